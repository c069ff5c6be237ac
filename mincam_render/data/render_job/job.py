"""The one entry point that renders a dataset: :func:`render_dataset`, step by step.

Open or plan the directory (:mod:`.manifest`), render the backgrounds a
differential job lacks (:mod:`.backgrounds`), render the shards still to do on
an executor (:mod:`.executors`), and write each returned shard here, atomically,
then the manifest. Only this process writes files.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.checks import check_int
from mincam_render.data import dataset as ds
from mincam_render.data.render_job.backgrounds import _shard_backgrounds
from mincam_render.data.render_job.estimate import JobLimits
from mincam_render.data.render_job.executors import (
    DEFAULT_SHARDS_PER_WORKER,
    _first_shard_then_choose,
    _run_processes,
    _run_ray,
)
from mincam_render.data.render_job.manifest import (
    _append_log,
    _check_shards,
    _open_or_plan,
    warn_of_other_versions,
)
from mincam_render.data.render_job.request import RenderRequest
from mincam_render.data.render_job.rescale import resolved_request
from mincam_render.data.render_job.shards import render_shard
from mincam_render.data.writer_lock import exclusive_writer

if TYPE_CHECKING:
    from tqdm import tqdm

log = logging.getLogger(__name__)


@dataclass
class RenderSummary:
    """What a call of :func:`render_dataset` did."""

    path: Path
    num_frames: int
    shards_total: int
    shards_rendered: list[int]
    shards_kept: list[int]
    shards_repaired: list[int]
    seconds: float
    frames_per_s: float


def render_dataset(
    request: RenderRequest,
    out: str | os.PathLike,
    *,
    workers: int | None = 1,
    ray_address: str | None = None,
    progress: bool = False,
    shards_per_worker: int = DEFAULT_SHARDS_PER_WORKER,
    use_plan_cache: bool = True,
    limits: JobLimits | None = None,
) -> RenderSummary:
    """Render (or finish) the dataset of ``request`` into directory ``out``.

    Args:
        request: what to render (its ``samples_factor`` applied first:
            :func:`~.rescale.resolved_request`).
        out: dataset directory; created, or resumed if it holds the same request.
        workers: local worker processes (>= 1), 0 to render in this process, or None to
            choose by job size: the first shard renders in this process, and a pool of
            one worker per core takes the rest only if this process would need more than
            :data:`~.executors.POOL_BREAK_EVEN_S` for it (:func:`_first_shard_then_choose`).
        ray_address: run shards as Ray tasks on this cluster (``"local"`` starts a
            single-node cluster, ``"auto"`` joins the running one); needs the
            ``ray`` extra. ``workers`` is then ignored.
        progress: show a tqdm progress bar (frames/s, ETA) on stderr.
        shards_per_worker: shards a worker process renders before it is replaced.
        use_plan_cache: reuse a kept fidelity plan of the same description, camera,
            targets and frame count (:mod:`mincam_render.data.plan_cache`), and keep a
            new one; False measures the plan again.
        limits: estimate a new job's time and disk before anything is written, log
            it, and refuse it above these limits unless confirmed (:mod:`.estimate`);
            None: no estimate.

    Returns:
        A :class:`RenderSummary`.

    Raises:
        JobTooLarge: a new job above ``limits``, not confirmed (nothing is written).
        DatasetError: ``out`` holds another configuration or is not a dataset.
        RenderError: a worker died or Ray is unavailable.
        ValueError: invalid arguments.
    """
    _check_executor_args(workers, shards_per_worker)
    # a resumed render finds its base plan kept (else measured again: the same plan)
    started = (Path(out) / ds.MANIFEST_NAME).is_file()
    factor = request.samples_factor
    request = resolved_request(request, use_plan_cache=use_plan_cache or started, progress=progress)
    with exclusive_writer(out, "render") as out:
        t_start = time.perf_counter()
        manifest, kept, repaired, todo = _prepare(request, out, use_plan_cache, progress, limits)
        backgrounds_of = _shard_backgrounds(out, manifest, progress) if todo else (lambda i: None)
        _log_start(out, kept, repaired, todo, workers, ray_address, factor)
        finish = _ShardWriter(out, manifest, kept, progress and bool(todo))
        try:
            _run_shards(finish, todo, backgrounds_of, workers, ray_address, shards_per_worker)
        finally:
            finish.close()
        return _summary(finish, kept, repaired, t_start)


def _check_executor_args(workers: int | None, shards_per_worker: int) -> None:
    """Raise ``ValueError`` for a ``workers`` or ``shards_per_worker`` out of range."""
    if workers is not None:  # None: auto
        check_int("workers", workers, 0, 256)
    check_int("shards_per_worker", shards_per_worker, 1)


def _prepare(
    request: RenderRequest,
    out: Path,
    use_plan_cache: bool,
    progress: bool,
    limits: JobLimits | None,
) -> tuple[dict, list[int], list[int], list[int]]:
    """``(manifest, kept, repaired, todo)`` of ``out``, opened or planned, its shards checked.

    Temporary files a killed render left are removed first.
    """
    manifest = _open_or_plan(request, out, use_plan_cache, progress, limits)
    for tmp in ds.remove_stale_temporaries(out):
        log.info("removed %s, left by a killed render", tmp)
    (out / ds.SHARD_DIR).mkdir(parents=True, exist_ok=True)
    kept, repaired, todo = _check_shards(out, manifest)
    warn_of_other_versions(out, manifest, todo)
    return manifest, kept, repaired, todo


def _frames_of(job: dict, num_shards: int) -> dict[int, int]:
    """``{shard: number of frames}`` of a job (the last shard may be short)."""
    return {
        i: min(job["num_frames"], (i + 1) * job["shard_frames"]) - i * job["shard_frames"]
        for i in range(num_shards)
    }


def _progress_bar(out: Path, job: dict, done_frames: int) -> tqdm:
    """A tqdm bar over the job's frames on stderr, starting at ``done_frames``."""
    from tqdm import tqdm

    return tqdm(
        total=job["num_frames"],
        initial=done_frames,
        unit="frame",
        desc=f"render {out.name}",
        dynamic_ncols=True,
        smoothing=0.1,
    )


def _log_start(
    out: Path,
    kept: list[int],
    repaired: list[int],
    todo: list[int],
    workers: int | None,
    ray_address: str | None,
    samples_factor: float | None,
) -> None:
    """Log the start of the shard renders: what is kept, repaired and to do, and where.

    ``samples_factor``: the multiple of a plan's samples the request asked for
    (``render --samples-factor``), None if it gave its settings. It is not in
    the manifest, whose request holds the resolved settings: the same dataset
    either way.
    """
    _append_log(
        out,
        {
            "event": "start",
            "pid": os.getpid(),
            "time": time.time(),
            "kept": kept,
            "repaired": repaired,
            "todo": todo,
            "workers": workers,
            "ray": ray_address,
            "samples_factor": samples_factor,
        },
    )


class _ShardWriter:
    """``finish(result, per_frame_progress)``: write a rendered shard, update the manifest.

    Called in this process with each ``render_shard`` result, in the order they
    arrive; ``per_frame_progress`` says the progress bar already counted its
    frames. Holds what the executors share: the job, its shards' frame counts
    and the bar (tqdm on stderr, or None).
    """

    def __init__(self, out: Path, manifest: dict, kept: list[int], progress: bool) -> None:
        self.out, self.manifest, self.job = out, manifest, manifest["job"]
        self.frames_of = _frames_of(self.job, manifest["num_shards"])
        self.bar = None
        if progress:
            self.bar = _progress_bar(out, self.job, sum(self.frames_of[i] for i in kept))
        self.rendered: list[int] = []

    def __call__(
        self, result: tuple[int, np.ndarray, dict, float], per_frame_progress: bool
    ) -> None:
        shard, stored, meta, seconds = result
        record = ds.write_shard(self.out, shard, stored, meta)
        self.manifest["shards"][shard] = record
        self.manifest["complete"] = all(s is not None for s in self.manifest["shards"])
        ds.write_manifest(self.out, self.manifest)
        self.rendered.append(shard)
        _append_log(
            self.out,
            {
                "event": "shard",
                "shard": shard,
                "frames": [meta["start"], meta["stop"]],
                "seconds": seconds,
                "pid": os.getpid(),
                "time": time.time(),
            },
        )
        if self.bar is not None and not per_frame_progress:
            self.bar.update(meta["stop"] - meta["start"])

    def close(self) -> None:
        """Close the progress bar."""
        if self.bar is not None:
            self.bar.close()


def _run_shards(
    finish: _ShardWriter,
    todo: list[int],
    backgrounds_of: Callable[[int], dict | None],
    workers: int | None,
    ray_address: str | None,
    shards_per_worker: int,
) -> None:
    """Render the shards ``todo`` on Ray, a worker pool or here, as ``workers`` says."""
    job, bar = finish.job, finish.bar
    if not todo:
        return
    if ray_address is not None:
        _run_ray(ray_address, job, todo, finish, shards_per_worker, backgrounds_of)
        return
    if workers is None:
        workers, todo = _first_shard_then_choose(
            job, todo, finish.frames_of, finish, bar, backgrounds_of
        )
        _append_log(finish.out, {"event": "workers", "workers": workers, "time": time.time()})
    if workers == 0:
        on_frame = None if bar is None else bar.update
        for i in todo:
            shard = render_shard(job, i, backgrounds_of(i), on_frame)
            finish(shard, on_frame is not None)
    elif todo:
        _run_processes(job, todo, finish, workers, shards_per_worker, bar, backgrounds_of)


def _summary(
    finish: _ShardWriter, kept: list[int], repaired: list[int], t_start: float
) -> RenderSummary:
    """Log the end of a render and summarise it (``t_start``: its ``perf_counter``)."""
    seconds = time.perf_counter() - t_start
    rendered = finish.rendered
    n_rendered = sum(finish.frames_of[i] for i in rendered)
    _append_log(
        finish.out,
        {
            "event": "end",
            "pid": os.getpid(),
            "time": time.time(),
            "rendered": rendered,
            "seconds": seconds,
        },
    )
    return RenderSummary(
        path=finish.out,
        num_frames=finish.job["num_frames"],
        shards_total=finish.manifest["num_shards"],
        shards_rendered=sorted(rendered),
        shards_kept=kept,
        shards_repaired=repaired,
        seconds=seconds,
        frames_per_s=n_rendered / seconds if seconds > 0 else 0.0,
    )
