"""Where a comparison's training runs run: in this process, local worker processes, or Ray.

A comparison trains every design with every training seed; each such *run*
trains into ``out/runs/<design>-seed<i>/`` (:func:`train_design_run`).
:func:`train_runs` runs them

- in this process, one after the other (``train_workers=1``, the default);
- in ``train_workers`` local worker processes
  (:func:`mincam_render.data.worker_pool.run_tasks`, ``spawn``): each receives
  the splits once, uses ``cores / train_workers`` torch threads outside the
  training loop, trains into the run's directory and returns the run's figures;
  it reports after every evaluation, so a worker that dies or goes quiet for the
  pool's stall bound stops the comparison with an error naming its run;
- as Ray tasks (``ray_address``, :mod:`mincam_render.data.ray_cluster`),
  assuming no shared file system: the splits go once into Ray's object store;
  each task receives the files of its run directory (a killed run's
  checkpoint), trains in a temporary directory and returns the run's figures
  and its directory's files, which this process writes into
  ``out/runs/<run>/`` (``metrics.json`` last: it marks a finished run).

A run's seed is ``stream_seed(cfg.seed, "train/<design>", i)`` whichever way it
runs, and the training loop runs on ``TrainConfig.torch_threads`` threads, so
every way gives each run the same figures (tests/analysis/test_run_dispatch.py).
A run whose ``metrics.json`` is on disk is finished: it is not trained again but
read back in this process (:func:`~mincam_render.learn.train.train_run` resumes
it at its end and tests it again), as the in-process way always did. A failed
run stops the comparison; finished runs stay on disk for the next attempt.
"""

from __future__ import annotations

import dataclasses
import json
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from mincam_render.analysis.comparison_config import ComparisonConfig, Design
from mincam_render.core.checks import check_int
from mincam_render.core.labels import label_tasks
from mincam_render.core.seeds import stream_seed
from mincam_render.learn.train import run_finished, train_run
from mincam_render.learn.train_config import TrainConfig

#: What a comparison keeps of the masks' training in supplement A's ablation.
_MASK_RUN_KEYS = ("steps", "best_step", "stopped_early", "train_wall_time_s", "episodes")
#: Where supplement A's ablation trains the tested camera, inside the masks' run.
_HEAD_RUN = "head-with-sensor"
#: Ray tasks report only their end and a training run's length is unknown until
#: the first ends: a Ray run stalls after this long (s) without any result (or 10 x
#: the longest wait between two results, if longer).
RAY_STALL_FLOOR_S = 6 * 3600.0


class TrainingError(RuntimeError):
    """A training run could not finish because of its worker (died, stalled, Ray failed)."""


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


def check_executor(train_workers: int, ray_address: str | None) -> None:
    """Raise ValueError unless ``train_workers`` >= 1, or ``ray_address`` alone, is given."""
    check_int("train_workers", train_workers, 1)
    if ray_address is not None and not ray_address.strip():
        raise ValueError("--ray: give an address (host:port, ray://host:port) or 'local'")
    if ray_address is not None and train_workers > 1:
        raise ValueError(
            f"--train-workers {train_workers} and --ray {ray_address}: Ray decides where runs "
            "train; give one of them"
        )


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
        if rest and ray_address is not None:
            _on_ray(ray_address, rest, splits, runs_dir, done)
        elif rest:
            _on_pool(train_workers, rest, splits, runs_dir, done)
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


# ---- local worker processes ------------------------------------------------------------------

#: A pool worker's splits, received once when it starts (:func:`_pool_init`).
_WORKER_SPLITS: dict[str, Any] = {}


def _pool_init(threads: int, splits: Mapping[str, Any]) -> None:
    import torch

    torch.set_num_threads(threads)
    _WORKER_SPLITS.update(splits)


def _pool_train(task: RunTask, runs_dir: str, on_progress: Callable[[int], None]) -> dict:
    """A pool worker's task: one run; its error names the run (a ValueError stays one)."""
    try:
        return train_design_run(task, _WORKER_SPLITS, Path(runs_dir), on_progress=on_progress)
    except ValueError as err:
        raise ValueError(f"training run {task.name}: {err}") from None
    except Exception as err:
        raise TrainingError(
            f"training run {task.name} failed: {type(err).__name__}: {err}"
        ) from None


def _on_pool(
    workers: int,
    tasks: list[RunTask],
    splits: Mapping[str, Any],
    runs_dir: Path,
    done: Callable[[RunTask, dict[str, Any]], None],
) -> None:
    from mincam_render.data.worker_pool import PoolError, run_tasks, threads_per_worker

    workers = min(workers, len(tasks))  # and the cores go to the workers that run
    by_name = {t.name: t for t in tasks}
    try:
        run_tasks(
            _pool_train,
            list(by_name),
            lambda name: (by_name[str(name)], str(runs_dir)),
            lambda name, result: done(by_name[str(name)], result),
            workers=workers,
            tasks_per_worker=len(tasks),  # the splits are sent once per worker
            initializer=_pool_init,
            initargs=(threads_per_worker(workers), dict(splits)),
        )
    except PoolError as err:
        raise TrainingError(
            f"{err}: training run {', '.join(map(str, err.tasks))} did not finish; finished "
            f"runs are kept in {runs_dir}: run the same command again to resume"
        ) from None


# ---- Ray tasks ---------------------------------------------------------------------------------


def _on_ray(
    address: str,
    tasks: list[RunTask],
    splits: Mapping[str, Any],
    runs_dir: Path,
    done: Callable[[RunTask, dict[str, Any]], None],
) -> None:
    from mincam_render.data.ray_cluster import RayError, collect, ray_session

    by_name = {t.name: t for t in tasks}

    def write(name: Any, returned: tuple[dict[str, Any], dict[str, bytes], str]) -> None:
        task = by_name[name]
        done(task, _write_run(runs_dir, task, *returned))

    try:
        with ray_session(address) as ray:
            train = ray.remote(num_cpus=1)(_ray_train)  # a run trains on one thread
            splits_ref = ray.put(dict(splits))
            run_of = {
                train.remote(splits_ref, t, run_files(runs_dir / t.name)): t.name for t in tasks
            }
            collect(ray, run_of, write, what="training run", stall_floor_s=RAY_STALL_FLOOR_S)
    except RayError as err:
        raise TrainingError(str(err)) from None


def _ray_train(
    splits: Mapping[str, Any], task: RunTask, files: Mapping[str, bytes]
) -> tuple[dict[str, Any], dict[str, bytes], str]:
    """A Ray task: the run resumed from ``files`` in a temporary directory.

    Returns:
        ``(run metrics, {relative path: bytes} of the run directory, the
        temporary runs directory the metrics' and files' paths point into)``.
    """
    import torch

    torch.set_num_threads(1)  # the task holds one CPU
    with tempfile.TemporaryDirectory(prefix="mincam-run-") as tmp:
        runs = Path(tmp)
        _write_files(runs / task.name, files)
        result = train_design_run(task, splits, runs)
        return result, run_files(runs / task.name), str(runs)


def run_files(run_dir: Path) -> dict[str, bytes]:
    """``{relative path: bytes}`` of every file below ``run_dir`` but its own writer lock.

    (The lock of ``run_dir`` is held by whoever writes the files there; a nested
    run's, empty, is a file like the others.)
    """
    from mincam_render.data.writer_lock import LOCK_NAME

    if not run_dir.is_dir():
        return {}
    return {
        p.relative_to(run_dir).as_posix(): p.read_bytes()
        for p in sorted(run_dir.rglob("*"))
        if p.is_file() and p != run_dir / LOCK_NAME
    }


def _write_files(run_dir: Path, files: Mapping[str, bytes]) -> None:
    """Write ``files`` below ``run_dir`` atomically, every ``metrics.json`` last."""
    from mincam_render.data.dataset import atomic_write_bytes

    for rel in sorted(files, key=lambda r: (Path(r).name == "metrics.json", r.count("/"), r)):
        (run_dir / rel).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_bytes(run_dir / rel, files[rel])


def _write_run(
    runs_dir: Path,
    task: RunTask,
    result: dict[str, Any],
    files: dict[str, bytes],
    worker_runs: str,
) -> dict[str, Any]:
    """Write a Ray run's files into ``runs_dir/<run>``; its metrics with the paths moved there.

    The run's JSON files (``run.json``'s ``frozen_masks_from`` in the ablation)
    and the metrics' ``run_dir`` named the task's temporary directory.
    """
    from mincam_render.data.writer_lock import exclusive_writer

    new = str(runs_dir)
    old_json, new_json = json.dumps(worker_runs)[1:-1].encode(), json.dumps(new)[1:-1].encode()
    moved = {
        rel: data.replace(old_json, new_json) if rel.endswith((".json", ".jsonl")) else data
        for rel, data in files.items()
    }
    with exclusive_writer(runs_dir / task.name, "training") as run_dir:
        _write_files(run_dir, moved)

    def move(path: str) -> str:
        return new + path[len(worker_runs) :] if path.startswith(worker_runs) else path

    result = dict(result, run_dir=move(result["run_dir"]))
    if "mask_run" in result:
        result["mask_run"] = dict(result["mask_run"], run_dir=move(result["mask_run"]["run_dir"]))
    return result
