"""Where training runs run: local worker processes or Ray tasks.

A study trains its *runs* (each a job with a ``name``, trained into
``runs_dir/<name>/`` by a module-level function of the study, pickled by
reference) in this process or hands them to :func:`dispatch_runs`:

- in ``train_workers`` local worker processes
  (:func:`mincam_render.data.worker_pool.run_tasks`, ``spawn``): each receives
  the splits once, uses ``cores / train_workers`` torch threads outside the
  training loop, trains into the run's directory and returns the run's figures;
  it reports after every evaluation, so a worker that dies or goes quiet for the
  pool's stall bound stops the study with an error naming its run;
- as Ray tasks (``ray_address``, :mod:`mincam_render.data.ray_cluster`),
  assuming no shared file system: the splits go once into Ray's object store;
  each task receives the files of its run directory (a killed run's
  checkpoint), trains in a temporary directory and returns the run's figures
  and its directory's files, which this process writes into
  ``runs_dir/<run>/`` (``metrics.json`` last: it marks a finished run).

The comparison's runs are :mod:`mincam_render.studies.comparison.runs`.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from mincam_render.core.checks import check_int

#: Ray tasks report only their end and a training run's length is unknown until
#: the first ends: a Ray run stalls after this long (s) without any result (or 10 x
#: the longest wait between two results, if longer).
RAY_STALL_FLOOR_S = 6 * 3600.0


class TrainingError(RuntimeError):
    """A training run could not finish because of its worker (died, stalled, Ray failed)."""


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


class RunJob(Protocol):
    """One training run: its ``name`` is its directory below the runs directory."""

    @property
    def name(self) -> str:
        """The run directory's name (may hold a ``/``)."""
        ...


#: A run's figures, whatever type the study gives them (picklable).
R = TypeVar("R")
#: Trains one run: ``(job, splits, runs_dir, *, on_progress=None) -> its figures``;
#: a module-level function (a worker receives it pickled by reference). The
#: splits are the study's, passed through (picklable).
TrainRun = Callable[..., R]
#: A run's figures with its paths moved out of a Ray task's temporary directory:
#: ``(figures, move) -> figures``, ``move`` maps a path below it to one below ``runs_dir``.
Relocate = Callable[[R, Callable[[str], str]], R]
#: Called in this process with each finished run and its figures.
Done = Callable[[Any, R], None]


@dataclass(frozen=True)
class RayRun(Generic[R]):
    """What a Ray task sends back: the run's figures and its directory's files.

    Attributes:
        figures: what the train function returned.
        files: ``{relative path: bytes}`` of the run's directory.
        worker_runs: the task's temporary runs directory, which the figures'
            and files' paths point into.
    """

    figures: R
    files: dict[str, bytes]
    worker_runs: str


def dispatch_runs(
    train: TrainRun[R],
    jobs: Sequence[RunJob],
    splits: object,
    runs_dir: Path,
    done: Done[R],
    *,
    train_workers: int,
    ray_address: str | None,
    relocate: Relocate[R],
) -> None:
    """Train ``jobs`` as Ray tasks (``ray_address``) or in ``train_workers`` local workers.

    Raises:
        TrainingError: a worker died or stalled, or a Ray task failed; finished
            runs are kept.
    """
    if ray_address is not None:
        _on_ray(ray_address, train, jobs, splits, runs_dir, done, relocate)
    else:
        _on_pool(train_workers, train, jobs, splits, runs_dir, done)


# ---- local worker processes ------------------------------------------------------------------

#: A pool worker's splits, received once when it starts (:func:`_pool_init`).
_WORKER_SPLITS: list[object] = []


def _pool_init(threads: int, splits: object) -> None:
    import torch

    torch.set_num_threads(threads)
    _WORKER_SPLITS[:] = [splits]


def _pool_train(
    train: TrainRun[R], task: RunJob, runs_dir: str, on_progress: Callable[[int], None]
) -> R:
    """A pool worker's task: one run; its error names the run (a ValueError stays one)."""
    try:
        return train(task, _WORKER_SPLITS[0], Path(runs_dir), on_progress=on_progress)
    except ValueError as err:
        raise ValueError(f"training run {task.name}: {err}") from None
    except Exception as err:
        raise TrainingError(
            f"training run {task.name} failed: {type(err).__name__}: {err}"
        ) from None


def _on_pool(
    workers: int,
    train: TrainRun[R],
    tasks: Sequence[RunJob],
    splits: object,
    runs_dir: Path,
    done: Done[R],
) -> None:
    from mincam_render.data.worker_pool import PoolError, run_tasks, threads_per_worker

    workers = min(workers, len(tasks))  # and the cores go to the workers that run
    by_name = {t.name: t for t in tasks}
    try:
        run_tasks(
            _pool_train,
            list(by_name),
            lambda name: (train, by_name[str(name)], str(runs_dir)),
            lambda name, result: done(by_name[str(name)], result),
            workers=workers,
            tasks_per_worker=len(tasks),  # the splits are sent once per worker
            initializer=_pool_init,
            initargs=(threads_per_worker(workers), splits),
        )
    except PoolError as err:
        raise TrainingError(
            f"{err}: training run {', '.join(map(str, err.tasks))} did not finish; finished "
            f"runs are kept in {runs_dir}: run the same command again to resume"
        ) from None


# ---- Ray tasks ---------------------------------------------------------------------------------


def _on_ray(
    address: str,
    train: TrainRun[R],
    tasks: Sequence[RunJob],
    splits: object,
    runs_dir: Path,
    done: Done[R],
    relocate: Relocate[R],
) -> None:
    from mincam_render.data.ray_cluster import RayError, collect, ray_session

    by_name = {t.name: t for t in tasks}

    def write(name: Any, returned: RayRun[R]) -> None:
        task = by_name[name]
        done(task, _write_run(runs_dir, task, returned, relocate=relocate))

    try:
        with ray_session(address) as ray:
            remote = ray.remote(num_cpus=1)(_ray_train)  # a run trains on one thread
            splits_ref = ray.put(splits)
            run_of = {
                remote.remote(train, splits_ref, t, run_files(runs_dir / t.name)): t.name
                for t in tasks
            }
            collect(ray, run_of, write, what="training run", stall_floor_s=RAY_STALL_FLOOR_S)
    except RayError as err:
        raise TrainingError(str(err)) from None


def _ray_train(
    train: TrainRun[R], splits: object, task: RunJob, files: Mapping[str, bytes]
) -> RayRun[R]:
    """A Ray task: the run resumed from ``files`` in a temporary directory; what it sends back."""
    import torch

    torch.set_num_threads(1)  # the task holds one CPU
    with tempfile.TemporaryDirectory(prefix="mincam-run-") as tmp:
        runs = Path(tmp)
        _write_files(runs / task.name, files)
        result = train(task, splits, runs)
        return RayRun(result, run_files(runs / task.name), str(runs))


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
    task: RunJob,
    returned: RayRun[R],
    *,
    relocate: Relocate[R],
) -> R:
    """Write a Ray run's files into ``runs_dir/<run>``; its metrics with the paths moved there.

    The run's JSON files (``run.json``'s ``frozen_masks_from`` in the ablation)
    and the metrics' paths (``relocate``) named the task's temporary directory.
    """
    from mincam_render.data.writer_lock import exclusive_writer

    new, worker_runs = str(runs_dir), returned.worker_runs
    old_json, new_json = json.dumps(worker_runs)[1:-1].encode(), json.dumps(new)[1:-1].encode()
    moved = {
        rel: data.replace(old_json, new_json) if rel.endswith((".json", ".jsonl")) else data
        for rel, data in returned.files.items()
    }
    with exclusive_writer(runs_dir / task.name, "training") as run_dir:
        _write_files(run_dir, moved)

    def move(path: str) -> str:
        return new + path[len(worker_runs) :] if path.startswith(worker_runs) else path

    return relocate(returned.figures, move)
