"""Where a job's shards render: in this process, a pool of worker processes, or Ray tasks.

Worker processes (:mod:`mincam_render.data.worker_pool`: ``spawn``; each
replaced after a few shards so Mitsuba/Dr.Jit memory cannot accumulate; each
limited to ``cores / workers`` Dr.Jit threads; a worker that dies or stalls
stops the render with an error naming its shard) and Ray tasks return arrays;
the ``finish`` callback of the parent writes them.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, cast

from mincam_render.data.render_job.shards import _worker_init, render_shard

if TYPE_CHECKING:
    import numpy as np
    from tqdm import tqdm

log = logging.getLogger(__name__)

#: Shards a local worker process renders before it is replaced by a fresh one.
DEFAULT_SHARDS_PER_WORKER = 4


class RenderError(RuntimeError):
    """A render could not run (worker crash, Ray unavailable)."""


#: A worker pool pays off when the shards left would take this process longer than
#: this (s). Measured on 2 cores (benchmarks/bench_workers.py, first run with 20 s):
#: a pool renders about 1.6x faster but costs 1.6 s (patches) to 3.5 s (workspace) to
#: start, so it wins beyond about 2.7x its start-up: 4 s (patches), 9 s (workspace).
POOL_BREAK_EVEN_S = 10.0


def _first_shard_then_choose(
    job: dict,
    todo: list[int],
    frames_of: dict[int, int],
    finish: Callable[[tuple, bool], None],
    bar: tqdm | None,
    backgrounds_of: Callable[[int], dict | None],
) -> tuple[int, list[int]]:
    """Render ``todo[0]`` here, then ``(workers, rest)``: a pool only for long remainders.

    The time per frame is taken from the shard's frames after its first (which
    pays for compiling the kernels) when it has more than one.
    """
    stamps = []

    def on_frame(n: int) -> None:
        stamps.append(time.perf_counter())
        if bar is not None:
            bar.update(n)

    first, rest = todo[0], list(todo[1:])
    t0 = time.perf_counter()
    finish(render_shard(job, first, backgrounds_of(first), on_frame), True)
    per_frame = (
        (stamps[-1] - stamps[0]) / (len(stamps) - 1)
        if len(stamps) > 1
        else time.perf_counter() - t0
    )
    left_s = per_frame * sum(frames_of[i] for i in rest)
    workers = (os.cpu_count() or 1) if left_s > POOL_BREAK_EVEN_S and len(rest) > 1 else 0
    log.info(
        "workers: %.3g s per frame, about %.0f s left in this process -> %s",
        per_frame,
        left_s,
        f"{workers} worker processes" if workers else "this process",
    )
    return workers, rest


def _run_processes(
    job: dict,
    todo: list[int],
    finish: Callable[[tuple, bool], None],
    workers: int,
    shards_per_worker: int,
    bar: tqdm | None,
    backgrounds_of: Callable[[int], dict | None],
) -> None:
    from mincam_render.data.worker_pool import PoolError, run_tasks, threads_per_worker
    from mincam_render.render import backend

    workers = min(workers, len(todo))  # and the cores go to the workers that run
    try:
        run_tasks(
            render_shard,
            todo,
            lambda shard: (job, shard, backgrounds_of(cast(int, shard))),
            lambda shard, result: finish(result, True),
            workers=workers,
            tasks_per_worker=shards_per_worker,
            initializer=_worker_init,
            initargs=(threads_per_worker(workers), os.getpid(), backend.chosen_variant()),
            on_progress=None if bar is None else lambda shard, n: bar.update(n),
        )
    except PoolError as err:
        raise RenderError(
            f"{err}: shard {', '.join(map(str, err.tasks))} did not finish; finished shards "
            "are kept: run the same command again to resume"
        ) from None


def _run_ray(
    address: str,
    job: dict,
    todo: list[int],
    finish: Callable[[tuple, bool], None],
    shards_per_worker: int,
    backgrounds_of: Callable[[int], dict | None],
) -> None:
    from mincam_render.data.ray_cluster import RayError, collect, ray_session
    from mincam_render.render import backend

    try:
        with ray_session(address) as ray:
            cpus = int(ray.cluster_resources().get("CPU", 1))
            # one Dr.Jit thread per task: Ray runs as many tasks as the cluster has CPUs
            task = ray.remote(num_cpus=1, max_calls=shards_per_worker)(_ray_render_shard)
            job_ref = ray.put(job)
            variant = backend.use_variant()  # the parent's: no shard of another variant
            shard_of = {task.remote(job_ref, i, 1, backgrounds_of(i), variant): i for i in todo}
            log.info("Ray: %d shard tasks on %d CPUs", len(shard_of), cpus)
            collect(ray, shard_of, lambda shard, result: finish(result, False), what="shard")
    except RayError as err:
        raise RenderError(str(err)) from None


def _ray_render_shard(
    job: dict, shard: int, threads: int, backgrounds: dict | None, variant: str | None = None
) -> tuple[int, np.ndarray, dict, float]:
    _worker_init(threads, None, variant)
    return render_shard(job, shard, backgrounds)
