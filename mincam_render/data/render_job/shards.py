"""One shard of a job rendered into arrays (in whatever process calls it, worker or parent).

Frame ``i`` is rendered with seed :func:`~mincam_render.core.seeds.frame_seed`
``(seed, i)`` (or its background's seed, differential jobs) and the family's
scene state ``i``, so a shard re-renders bit-identically in any process.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.seeds import frame_seed
from mincam_render.data import dataset as ds
from mincam_render.data.render_job.scene import _load_family, _render_camera
from mincam_render.render import precision
from mincam_render.render.differential import background_family

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.differential import Background
    from mincam_render.scenes.base import SceneFamily

#: Test hook: seconds to sleep after each frame (slows renders so a test can kill
#: one mid-way). Read by workers from the environment; unset in normal use.
FRAME_DELAY_ENV = "MINCAM_RENDER_TEST_FRAME_DELAY_S"


@dataclasses.dataclass
class _WorkerState:
    """This process's part of a render: the parent to watch, the scene built once.

    Attributes:
        parent: the process that started this worker (None: none to watch).
        cache: ``{job's request_sha256: (family, scene, camera, render camera)}``,
            one job at a time.
    """

    parent: int | None = None
    cache: dict[str, tuple] = dataclasses.field(default_factory=dict)


_WORKER = _WorkerState()


def _worker_init(threads: int, parent_pid: int | None, variant: str | None = None) -> None:
    """Initializer of a worker process: its variant, Dr.Jit threads, the parent.

    Args:
        threads: Dr.Jit threads of this worker.
        parent_pid: the process that started it (None: none to watch).
        variant: the job's Mitsuba variant (its parent's), so no shard of one job
            is rendered with another; None: this process's own choice.

    Raises:
        BackendUnavailableError: ``variant`` cannot run in this process.
    """
    import drjit as dr

    from mincam_render.render.backend import backend_of, use_variant

    if variant is None:
        use_variant()
    else:
        use_variant(backend_of(variant))
    dr.set_thread_count(max(1, int(threads)))
    _WORKER.parent = parent_pid


def render_shard(
    job: dict,
    shard: int,
    backgrounds: dict | None = None,
    on_progress: Callable[[int], None] | None = None,
) -> tuple[int, np.ndarray, dict, float]:
    """Render one shard of a job (in whatever process calls it).

    Args:
        job: the ``job`` section of a manifest (family, camera, render settings).
        shard: shard number.
        backgrounds: for differentially rendered jobs, ``{key: Background}``
            covering the shard's frames (see
            :func:`~mincam_render.data.render_job.backgrounds.load_backgrounds`).
        on_progress: called with 1 after each frame.

    Returns:
        ``(shard, stored T[frame, detector, row, col], shard metadata, seconds)``.

    Raises:
        ValueError: a differential job without the shard's backgrounds.
    """
    from mincam_render.render.backend import use_variant

    use_variant()
    t0 = time.perf_counter()
    start = shard * job["shard_frames"]
    stop = min(job["num_frames"], start + job["shard_frames"])
    images, frames, labels = _render_frames(job, start, stop, backgrounds, on_progress)
    stored, scales = precision.encode_transport(images, job["render"]["dtype"])
    for f, s in zip(frames, scales, strict=True):
        f["scale"] = float(s)
    meta = {
        "format": ds.FORMAT_NAME,
        "format_version": ds.FORMAT_VERSION,
        # ties the shard to its request: resume and `repair` keep only their request's
        "request_sha256": job["request_sha256"],
        "shard": shard,
        "start": start,
        "stop": stop,
        "dtype": job["render"]["dtype"],
        "shape": list(stored.shape),
        "frames": frames,
        "labels": labels,
    }
    # JSON round trip now, so the parent writes exactly what a reader will parse
    meta = json.loads(json.dumps(meta, default=ds._json_default))
    return shard, stored, meta, time.perf_counter() - t0


def _cached_scene(job: dict) -> tuple:
    """``(family, scene, camera, render camera)`` of ``job``, built once per process."""
    key = job["request_sha256"]
    cached = _WORKER.cache.get(key)
    if cached is None:
        _WORKER.cache.clear()  # one job per process: free the previous scene
        family = _load_family(job)
        cached = (family, family.build_scene(), *_render_camera(job))
        _WORKER.cache[key] = cached
    return cached


def _render_frames(
    job: dict,
    start: int,
    stop: int,
    backgrounds: dict | None,
    on_progress: Callable[[int], None] | None,
) -> tuple[np.ndarray, list[dict], dict[str, list]]:
    """Frames ``start``..``stop - 1`` of ``job``, rendered in order.

    Returns:
        ``(images, frame records, labels)``: ``images`` is the numpy
        ``T[frame, detector, row, col]`` (W) of the frames.
    """
    family, scene, camera, render_cam = _cached_scene(job)
    delay = float(os.environ.get(FRAME_DELAY_ENV, "0") or 0)
    frames, images = [], []
    labels: dict[str, list] = {s.name: [] for s in family.labels}
    for i in range(start, stop):
        if _WORKER.parent is not None and os.getppid() != _WORKER.parent:
            os._exit(1)  # the render was killed: do not linger as an orphan
        background = _frame_background(job, family, i, backgrounds)
        t, lab, seed = _render_frame(job, family, scene, render_cam, i, background)
        images.append(t)
        for name in labels:
            labels[name].append(np.asarray(lab[name], dtype=np.float32).reshape(-1).tolist())
        record = {"index": i, "time_s": family.time_s(i), "seed": seed}
        if background is not None:
            record["background"] = background.key
        frames.append(dict(record, state=family.frame_state(i)))
        if on_progress is not None:
            on_progress(1)
        if delay:
            time.sleep(delay)
    stacked = np.stack(images)
    if job["render"]["shared_render"]:  # one copy to every detector, once per shard
        stacked = np.repeat(stacked, camera.num_detectors, axis=1)
    return stacked, frames, labels


def _frame_background(
    job: dict, family: SceneFamily, i: int, backgrounds: dict | None
) -> Background | None:
    """The ``Background`` of frame ``i`` of a differential job, else None.

    Raises:
        ValueError: the frame's background is not in ``backgrounds``.
    """
    settings = job["render"].get("background")
    if settings is None:
        return None
    key = background_family(family).background_key(i, settings["interval_s"])
    background = (backgrounds or {}).get(key)
    if background is None:
        raise ValueError(f"frame {i}: background {key!r} was not given to render_shard")
    return background


def _render_frame(
    job: dict,
    family: SceneFamily,
    scene: mi.Scene,
    render_cam: FreeformCamera,
    i: int,
    background: Background | None,
) -> tuple:
    """``(T[detector, row, col] (W, numpy), labels, seed)`` of frame ``i``.

    Differentially with ``background`` (its seed), else the plain transport at
    :func:`frame_seed` ``(seed, i)``; a shared render has one detector.
    """
    from mincam_render.render.differential import render_frame

    r = job["render"]
    max_depth = r["max_depth"] or None
    if background is not None:
        t, lab = render_frame(
            background_family(family),
            scene,
            render_cam,
            i,
            background,
            spp=r["spp"],
            max_depth=max_depth,
        )
        return t, lab, background.frame_seed(i)
    lab = family.set_frame(scene, i)
    seed = frame_seed(job["seed"], i)
    t = family.render_transport(scene, render_cam, spp=r["spp"], seed=seed, max_depth=max_depth)
    return t, lab, seed
