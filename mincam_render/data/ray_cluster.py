"""Ray: a session on a cluster (or one started here), this package shipped, results collected.

Rendering (:mod:`mincam_render.data.render_job.executors`) and a comparison's
training runs (:mod:`mincam_render.data.run_dispatch`) both run as Ray tasks
through these pieces: :func:`ray_session` connects (``"local"`` starts a cluster
in this process's machine) and ships the package (:func:`ray_runtime_env`), and
:func:`collect` hands each task's result to the caller as it arrives, naming a
task that failed and cancelling the others when one fails or nothing arrives
for too long. Nothing assumes a shared file system: tasks take their inputs as
arguments and return what the caller writes. Ray is an optional extra
(``mincam_render[ray]``); it is imported only here, when a session starts.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Hashable, Iterator, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any, TypedDict

from mincam_render.data.worker_pool import (
    DEFAULT_STALL_FLOOR_S,
    POLL_S,
    StallWatch,
    WorkerStalled,
)


class RayError(RuntimeError):
    """Ray is missing or unreachable, or one of its tasks failed or stalled."""


class RuntimeEnv(TypedDict):
    """The part of Ray's ``runtime_env`` we set (Ray's schema)."""

    py_modules: list[str]
    excludes: list[str]


def ray_runtime_env() -> RuntimeEnv:
    """Ray's ``runtime_env`` that ships this package to the workers.

    Other nodes may not have it installed. Ray makes a shipped directory
    importable as the module named after it, so the directory is the package
    root ``mincam_render/`` (it shipped ``mincam_render/data``, which made only a
    module named ``data`` importable there).
    """
    return {"py_modules": [str(Path(__file__).resolve().parents[1])], "excludes": ["__pycache__"]}


def _import_ray() -> ModuleType:
    try:
        import ray
    except ImportError:
        raise RayError(
            "--ray needs the optional dependency ray: pip install 'mincam_render[ray]'"
        ) from None
    return ray


@contextlib.contextmanager
def ray_session(address: str) -> Iterator[ModuleType]:
    """The ``ray`` module, connected to the cluster at ``address`` (``"local"`` starts one).

    A session opened inside another reuses it; the one that started Ray shuts it
    down when its ``with`` block ends.

    Raises:
        RayError: ray is not installed, or the cluster cannot be reached.
    """
    ray = _import_ray()
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(
                address=None if address == "local" else address,  # None: Ray's default
                ignore_reinit_error=True,
                log_to_driver=False,
                include_dashboard=False,
                runtime_env=dict(ray_runtime_env()),
            )
        except Exception as err:  # ray raises ConnectionError, RuntimeError, ValueError ...
            raise RayError(f"could not connect to Ray at {address!r}: {err}") from None
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()


def collect(
    ray: ModuleType,
    task_of: Mapping[Any, Hashable],
    on_result: Callable[[Hashable, Any], None],
    *,
    what: str,
    stall_floor_s: float = DEFAULT_STALL_FLOOR_S,
) -> None:
    """Call ``on_result(task, result)`` as each Ray task ends; stop all if one fails or stalls.

    Args:
        ray: the ``ray`` module of a :func:`ray_session`.
        task_of: ``{ObjectRef: task key}`` of the submitted tasks.
        on_result: called in this process with each task's key and result.
        what: what a task is (``"shard"``, ``"training run"``), for messages.
        stall_floor_s: a run stalls when no task ends for ``max(this, 10 x the
            longest wait between two results)`` seconds (Ray tasks report only
            their end; tasks wait for a CPU, so that wait stands for a task's time).

    Raises:
        RayError: a task failed (its key and first line of its error), or none
            ended within the stall bound; the unfinished tasks are cancelled.
    """
    pending = list(task_of)
    watch, last_s = StallWatch(floor_s=stall_floor_s), time.monotonic()
    while pending:
        done, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
        if not done:
            try:
                watch.check([task_of[r] for r in pending])
            except WorkerStalled as err:
                _cancel(ray, pending)
                raise RayError(f"Ray: {err}; finished {what}s are kept: run the same command "
                               "again to resume") from None  # fmt: skip
            continue
        try:
            result = ray.get(done[0])
        except Exception as err:
            _cancel(ray, pending)
            cause = getattr(err, "cause", None) or err  # a RayTaskError wraps the task's error
            first = (str(cause).strip().splitlines() or [""])[0]
            raise RayError(
                f"Ray {what} {task_of[done[0]]} failed: {type(cause).__name__}: {first}"
            ) from None
        watch.report(time.monotonic() - last_s)
        last_s = time.monotonic()
        on_result(task_of[done[0]], result)


def _cancel(ray: ModuleType, refs: list[Any]) -> None:
    for ref in refs:
        ray.cancel(ref, force=True)
