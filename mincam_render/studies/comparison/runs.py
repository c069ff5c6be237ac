"""A comparison's training runs: one per design, training seed and task.

A comparison trains every design with every training seed; each such *run*
trains into ``out/runs/<design>-seed<i>/`` (:func:`train_design_run`).
:func:`train_runs` trains them in this process (``train_workers=1``, the
default) or hands them to :func:`mincam_render.data.run_dispatch.dispatch_runs`
(local worker processes or Ray tasks).

A run's seed is ``stream_seed(cfg.seed, "train/<design>", i)`` whichever way it
runs, and the training loop runs on ``TrainConfig.torch_threads`` threads, so
every way gives each run the same figures (tests/studies/test_run_dispatch.py).
A run whose ``metrics.json`` is on disk is finished: it is not trained again but
read back in this process (:func:`~mincam_render.learn.train.train_run` resumes
it at its end and tests it again), as the in-process way always did. A failed
run stops the comparison; finished runs stay on disk for the next attempt.
"""

from __future__ import annotations

import dataclasses
import shutil
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

from mincam_render.core.labels import label_tasks
from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.data.run_dispatch import check_executor, dispatch_runs
from mincam_render.learn.evaluation import Evaluation
from mincam_render.learn.runs import RunMetrics
from mincam_render.learn.train import TrainingData, run_finished, train_run
from mincam_render.learn.train_config import TrainConfig
from mincam_render.studies.comparison.config import ComparisonConfig, Design

#: Where supplement A's ablation trains the tested camera, inside the masks' run.
_HEAD_RUN = "head-with-sensor"


@dataclasses.dataclass(frozen=True)
class Splits:
    """A comparison's data: the training episodes joined, and the named evaluation episodes.

    Args:
        train: every training episode, joined into one split.
        val: ``{name: validation episode}``, pooled for early stopping.
        tests: ``{name: test episode}``.
    """

    train: TrainingData
    val: Mapping[str, TrainingData]
    tests: Mapping[str, TrainingData]


def _evaluations(d: Mapping[str, Any]) -> dict[str, Evaluation]:
    return {k: Evaluation.from_json(e) for k, e in d.items()}


@dataclasses.dataclass(frozen=True, kw_only=True)
class MaskRun:
    """Supplement A's ablation: the training of the masks a tested camera froze.

    Args:
        run_dir: the masks' run directory.
        steps: its steps.
        best_step: the step of its kept state.
        stopped_early: whether early stopping ended it.
        train_wall_time_s: its training wall time (s).
        episodes: its (sensorless) camera's metrics on each test episode.
    """

    run_dir: str
    steps: int
    best_step: int
    stopped_early: bool
    train_wall_time_s: float
    episodes: Mapping[str, Evaluation]

    @classmethod
    def of(cls, run_dir: str, m: RunMetrics) -> MaskRun:
        """The masks' run in ``run_dir`` and its metrics."""
        return cls(run_dir=run_dir, steps=m.steps, best_step=m.best_step,
                   stopped_early=m.stopped_early, train_wall_time_s=m.train_wall_time_s,
                   episodes=m.episodes)  # fmt: skip

    def as_json(self) -> JsonObject:
        """The fields, in their order, the episodes' metrics as JSON."""
        return {"run_dir": self.run_dir, "steps": self.steps, "best_step": self.best_step,
                "stopped_early": self.stopped_early, "train_wall_time_s": self.train_wall_time_s,
                "episodes": {k: e.as_json() for k, e in self.episodes.items()}}  # fmt: skip

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MaskRun:
        """Inverse of :meth:`as_json`."""
        return cls(run_dir=d["run_dir"], steps=d["steps"], best_step=d["best_step"],
                   stopped_early=d["stopped_early"], train_wall_time_s=d["train_wall_time_s"],
                   episodes=_evaluations(d["episodes"]))  # fmt: skip


@dataclasses.dataclass(frozen=True, kw_only=True)
class ComparisonRun:
    """One finished run of a comparison (:func:`train_design_run`).

    Args:
        metrics: the tested camera's metrics (its ``metrics.json``), with every
            test and validation episode's.
        run_dir: the tested camera's run directory.
        seed_index: which of the comparison's training seeds.
        mask_run: supplement A's ablation: the masks' own training (None otherwise).
    """

    metrics: RunMetrics
    run_dir: str
    seed_index: int
    mask_run: MaskRun | None = None

    @property
    def episodes(self) -> Mapping[str, Evaluation]:
        """The camera's metrics on each test episode."""
        return self.metrics.episodes

    @property
    def validation_episodes(self) -> Mapping[str, Evaluation] | None:
        """Its metrics on each validation episode (None when not named)."""
        return self.metrics.validation_episodes

    def kept_val_error(self) -> float | None:
        """The pooled validation error at the kept (best) step; None if not recorded."""
        m = self.metrics
        best = [h for h in m.history if h["step"] == m.best_step]
        return best[0].get("val_error") if best else None

    def as_json(self) -> JsonObject:
        """The run's ``metrics.json`` with ``run_dir``, ``seed_index`` (and ``mask_run``)."""
        out = self.metrics.as_json()
        if self.mask_run is not None:
            out["mask_run"] = self.mask_run.as_json()
        return out | {"run_dir": self.run_dir, "seed_index": self.seed_index}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ComparisonRun:
        """Inverse of :meth:`as_json`."""
        mask_run = d.get("mask_run")
        metrics = RunMetrics.from_json(d)
        return cls(metrics=metrics, run_dir=d["run_dir"], seed_index=d["seed_index"],
                   mask_run=None if mask_run is None else MaskRun.from_json(mask_run))  # fmt: skip


#: ``{task: {design: [its runs, seed by seed]}}``.
RunsByTask = Mapping[str, Mapping[str, Sequence[ComparisonRun]]]


@dataclasses.dataclass(frozen=True)
class RunTask:
    """One training run of a comparison: a design, a seed index, its recipe and task.

    Args:
        design: the camera design.
        seed_index: which of the comparison's training seeds.
        config: the recipe (its seed is the run's).
        task: the task the camera is trained for (``"joint"``: every label).
        labels: the task's labels; empty when they are every label of the
            data (a joint camera, or the one task of a single-task family).
    """

    design: Design
    seed_index: int
    config: TrainConfig
    task: str = "joint"
    labels: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """The run directory's name: ``<design>-seed<i>`` (``<task>/`` before it for a task)."""
        run = f"{self.design.name}-seed{self.seed_index}"
        return f"{self.task}/{run}" if self.labels else run


def comparison_tasks(
    cfg: ComparisonConfig, family_tasks: Mapping[str, tuple[str, ...]] | None = None
) -> list[RunTask]:
    """Every run of ``cfg``, task by task, design by design, seed by seed.

    ``family_tasks``: the data's tasks (:func:`~mincam_render.core.labels.label_tasks`),
    of which ``cfg`` trains :meth:`ComparisonConfig.task_labels`; None: one joint
    camera per design. Each seed derives from ``cfg.seed``, the design and, for
    a camera of only some of the labels, the task.
    """
    family_tasks = dict(family_tasks or {"joint": ()})
    every = {label for names in family_tasks.values() for label in names}
    runs = []
    for task, names in cfg.task_labels(family_tasks).items():
        own = tuple(names) if set(names) != every else ()
        stream = f"train/{task}/" if own else "train/"
        runs += [
            RunTask(
                design=d,
                seed_index=i,
                config=dataclasses.replace(
                    cfg.train,
                    seed=stream_seed(cfg.seed, f"{stream}{d.name}", i),
                    head=d.head,
                    privacy_weight=d.privacy_weight,
                ),
                task=task,
                labels=own,
            )
            for d in cfg.designs
            for i in range(cfg.seeds)
        ]
    return runs


def train_design_run(
    task: RunTask,
    splits: Splits,
    runs_dir: Path,
    *,
    progress: bool = False,
    on_progress: Callable[[int], None] | None = None,
) -> ComparisonRun:
    """Train (or resume) one run into ``runs_dir/<task.name>``; its metrics (with episodes).

    A task's run sees only its labels (:func:`task_splits`). A design without
    the detector model is supplement A's ablation: its masks are trained
    without the model, then frozen while a fresh head is trained with it
    (``<run>/head-with-sensor``); that camera is the one tested (with the
    model), and the masks' own training is kept as ``mask_run``.
    """
    design, run_dir = task.design, runs_dir / task.name
    splits = task_splits(splits, task.labels)
    train = partial(train_run, splits.train, splits.val, None, config=task.config,
                    episodes=splits.tests, progress=progress, on_progress=on_progress)  # fmt: skip
    if design.grid is not None:
        run = train(run_dir, baseline_grid=design.grid)
    else:
        run = train(run_dir, pixels=design.pixels, sensor_model=design.sensor_model,
                    reference=design.reference, tune_reference=design.tuned)  # fmt: skip
    if design.sensor_model:
        return ComparisonRun(metrics=run, run_dir=str(run_dir), seed_index=task.seed_index)
    masks = MaskRun.of(str(run_dir), run)
    run_dir = run_dir / _HEAD_RUN
    run = train(run_dir, frozen_masks_from=masks.run_dir)
    return ComparisonRun(metrics=run, run_dir=str(run_dir), seed_index=task.seed_index,
                         mask_run=masks)  # fmt: skip


def task_splits(splits: Splits, labels: tuple[str, ...]) -> Splits:
    """``splits`` with only ``labels`` (every split, every episode); all labels when empty."""
    if not labels:
        return splits
    return Splits(
        train=splits.train.with_labels(labels),
        val={k: v.with_labels(labels) for k, v in splits.val.items()},
        tests={k: v.with_labels(labels) for k, v in splits.tests.items()},
    )


def train_runs(
    cfg: ComparisonConfig,
    splits: Splits,
    out: Path,
    *,
    train_workers: int = 1,
    ray_address: str | None = None,
    progress: bool = True,
) -> dict[str, dict[str, list[ComparisonRun]]]:
    """Every run of ``cfg`` trained (module docstring): ``{task: {design: [metrics per seed]}}``.

    The tasks are :meth:`ComparisonConfig.task_labels` of the training split's
    labels (``"joint"`` for a joint camera).

    Raises:
        ValueError: invalid ``train_workers`` or ``ray_address`` (:func:`check_executor`).
        TrainingError: a worker died or stalled, or a Ray task failed; finished
            runs are kept.
    """
    from tqdm import tqdm

    check_executor(train_workers, ray_address)
    tasks, runs_dir = comparison_tasks(cfg, label_tasks(splits.train.label_specs)), out / "runs"
    results: dict[str, ComparisonRun] = {}
    bar = tqdm(total=len(tasks), desc="training runs", unit="run", disable=not progress)

    def done(task: RunTask, result: ComparisonRun) -> None:
        results[task.name] = result
        bar.update(1)

    here = train_workers == 1 and ray_address is None
    try:
        for t in tasks:
            if here or _finished(t, runs_dir):
                done(t, train_design_run(t, splits, runs_dir, progress=progress))
        rest = [t for t in tasks if t.name not in results]
        if rest:
            dispatch_runs(
                train_design_run,
                rest,
                splits,
                runs_dir,
                done,
                train_workers=train_workers,
                ray_address=ray_address,
                relocate=relocate_run,
            )
    finally:
        bar.close()
    by_task: dict[str, dict[str, list[ComparisonRun]]] = {}
    for t in tasks:
        by_task.setdefault(t.task, {}).setdefault(t.design.name, []).append(results[t.name])
    return by_task


def _finished(task: RunTask, runs_dir: Path) -> bool:
    return design_run_finished(runs_dir / task.name, task.design)


def design_run_finished(run_dir: Path, design: Design) -> bool:
    """Whether ``design``'s run in ``run_dir`` (and its tested camera, in the ablation) ended."""
    tested = run_dir if design.sensor_model else run_dir / _HEAD_RUN
    return run_finished(run_dir) and run_finished(tested)


def relocate_run(result: ComparisonRun, move: Callable[[str], str]) -> ComparisonRun:
    """A run's metrics with its directories (and its masks' run's, in the ablation) moved."""
    masks = result.mask_run
    if masks is not None:
        masks = dataclasses.replace(masks, run_dir=move(masks.run_dir))
    return dataclasses.replace(result, run_dir=move(result.run_dir), mask_run=masks)


def copy_runs_afresh(runs: Path, to: Path) -> None:
    """Copy a comparison's ``runs`` directory to ``to``, replacing whatever is there.

    For testing kept runs on other episodes without touching them: a copy a
    kill cut short, or one of runs trained again since, is replaced whole.
    """
    shutil.rmtree(to, ignore_errors=True)
    shutil.copytree(runs, to)
