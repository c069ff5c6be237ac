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
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from mincam_render.core.labels import label_tasks
from mincam_render.core.seeds import stream_seed
from mincam_render.data.run_dispatch import check_executor, dispatch_runs
from mincam_render.learn.train import run_finished, train_run
from mincam_render.learn.train_config import TrainConfig
from mincam_render.studies.comparison.config import ComparisonConfig, Design

#: What a comparison keeps of the masks' training in supplement A's ablation.
_MASK_RUN_KEYS = ("steps", "best_step", "stopped_early", "train_wall_time_s", "episodes")
#: Where supplement A's ablation trains the tested camera, inside the masks' run.
_HEAD_RUN = "head-with-sensor"


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
    splits: Mapping[str, Any],
    runs_dir: Path,
    *,
    progress: bool = False,
    on_progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Train (or resume) one run into ``runs_dir/<task.name>``; its metrics (with episodes).

    ``splits``: ``{"train": TrainingData, "val": {name: TrainingData}, "tests": {name:
    TrainingData}}``; a task's run sees only its labels (:func:`task_splits`).
    A design without the detector model is supplement A's ablation: its masks
    are trained without the model, then frozen while a fresh head is trained
    with it (``<run>/head-with-sensor``); that camera is the one tested (with
    the model), and the masks' own training is kept as ``mask_run``.
    """
    design, run_dir = task.design, runs_dir / task.name
    splits = task_splits(splits, task.labels)
    common = {
        "config": task.config,
        "episodes": splits["tests"],
        "progress": progress,
        "on_progress": on_progress,
    }
    run = train_run(splits["train"], splits["val"], None, run_dir, **common,
                    **design.train_kwargs()).as_json()  # fmt: skip
    if not design.sensor_model:
        masks = {"run_dir": str(run_dir), **{k: run[k] for k in _MASK_RUN_KEYS}}
        run_dir = run_dir / _HEAD_RUN
        run = train_run(splits["train"], splits["val"], None, run_dir, **common,
                        frozen_masks_from=masks["run_dir"]).as_json()  # fmt: skip
        run["mask_run"] = masks
    return dict(run, run_dir=str(run_dir), seed_index=task.seed_index)


def task_splits(splits: Mapping[str, Any], labels: tuple[str, ...]) -> dict[str, Any]:
    """``splits`` with only ``labels`` (every split, every episode); all labels when empty."""
    if not labels:
        return dict(splits)
    return {
        "train": splits["train"].with_labels(labels),
        "val": {k: v.with_labels(labels) for k, v in splits["val"].items()},
        "tests": {k: v.with_labels(labels) for k, v in splits["tests"].items()},
    }


def train_runs(
    cfg: ComparisonConfig,
    splits: Mapping[str, Any],
    out: Path,
    *,
    train_workers: int = 1,
    ray_address: str | None = None,
    progress: bool = True,
) -> dict[str, dict[str, list[dict[str, Any]]]]:
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
    tasks, runs_dir = comparison_tasks(cfg, label_tasks(splits["train"].label_specs)), out / "runs"
    results: dict[str, dict[str, Any]] = {}
    bar = tqdm(total=len(tasks), desc="training runs", unit="run", disable=not progress)

    def done(task: RunTask, result: dict[str, Any]) -> None:
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
    by_task: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for t in tasks:
        by_task.setdefault(t.task, {}).setdefault(t.design.name, []).append(results[t.name])
    return by_task


def _finished(task: RunTask, runs_dir: Path) -> bool:
    """Whether the run's ``metrics.json`` (and its tested camera's, in the ablation) exists."""
    run_dir = runs_dir / task.name
    tested = run_dir if task.design.sensor_model else run_dir / _HEAD_RUN
    return run_finished(run_dir) and run_finished(tested)


def relocate_run(result: dict[str, Any], move: Callable[[str], str]) -> dict[str, Any]:
    """A run's metrics with its directories (and its masks' run's, in the ablation) moved."""
    result = dict(result, run_dir=move(result["run_dir"]))
    if "mask_run" in result:
        result["mask_run"] = dict(result["mask_run"], run_dir=move(result["mask_run"]["run_dir"]))
    return result
