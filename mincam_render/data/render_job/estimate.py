"""What a new render will cost, measured before anything is written, and when to refuse it.

A new job's manifest is planned in memory; before it is written,
:func:`estimate_job` renders the job's first frames in this process (the
second is timed: the first pays for compiling the kernels, which the shards
rendered here reuse) and computes the bytes every shard, the backgrounds and
the manifest will take on disk. :func:`check_job` logs the estimate and refuses
a job above :class:`JobLimits` (a day of rendering in this process, or more
bytes than the disk has free) unless it was confirmed (``render --yes``): a
``--frames 1000000000`` typed by mistake is one line, not a 31 MB manifest
followed by weeks of work.

A differential job's frames render with the plan's cost per frame (paths per
texel, its backgrounds amortized) rather than the plain render timed here: the
time is scaled by the ratio of the two costs.
"""

from __future__ import annotations

import logging
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mincam_render.core.checks import check_number
from mincam_render.core.seeds import frame_seed
from mincam_render.data import dataset as ds
from mincam_render.data.render_job.shards import _cached_scene

log = logging.getLogger(__name__)

#: Bytes of a ``.npy`` header (version 1: 128 bytes for the shapes we write).
NPY_HEADER_BYTES = 128
#: Bytes of one shard's record in the manifest (its paths and checksums), about.
MANIFEST_RECORD_BYTES = 400


class JobTooLarge(ValueError):
    """A new render's estimate is above its limits and it was not confirmed."""


@dataclass(frozen=True, kw_only=True)
class JobLimits:
    """When a new render is refused before anything is written.

    Args:
        max_hours: the longest render (in this process) that needs no confirmation, h > 0.
        confirmed: the user confirmed the job (``render --yes``): the estimate is
            shown, nothing is refused.
    """

    max_hours: float = 24.0
    confirmed: bool = False

    def __post_init__(self) -> None:
        check_number("JobLimits.max_hours", self.max_hours, 0.0, lo_open=True, unit="h")


@dataclass(frozen=True, kw_only=True)
class JobEstimate:
    """A new render's cost: time in this process and bytes on disk.

    Args:
        frames: frames to render.
        seconds_per_frame: measured (s), including the amortized backgrounds.
        shards: shard files to write.
        bytes_per_shard: a full shard's ``.npy`` and ``.json`` (bytes).
        other_bytes: the manifest and a differential job's backgrounds (bytes).
        free_bytes: free space where the dataset goes (bytes).
    """

    frames: int
    seconds_per_frame: float
    shards: int
    bytes_per_shard: int
    other_bytes: int
    free_bytes: int

    @property
    def seconds(self) -> float:
        """Estimated render time in this process (s)."""
        return self.frames * self.seconds_per_frame

    @property
    def bytes(self) -> int:
        """Estimated size of the dataset on disk (bytes)."""
        return self.shards * self.bytes_per_shard + self.other_bytes

    def describe(self) -> str:
        """One line: frames x seconds per frame, shards x bytes per shard, free space."""
        return (
            f"{self.frames} frames x {self.seconds_per_frame:.3g} s (measured) = about "
            f"{_duration(self.seconds)} in one process; {self.shards} shards x "
            f"{_size(self.bytes_per_shard)} = about {_size(self.bytes)} on disk "
            f"({_size(self.free_bytes)} free)"
        )


def estimate_job(manifest: dict, out: Path) -> JobEstimate:
    """The cost of rendering ``manifest``'s job into ``out`` (frames rendered here, not kept).

    Args:
        manifest: a new job's manifest (:func:`~.planning.plan_render`).
        out: where the dataset goes (it need not exist).
    """
    job = manifest["job"]
    family, scene, camera, render_cam = _cached_scene(job)
    r = job["render"]
    probe_frames = range(min(2, job["num_frames"]))
    seconds, labels = [], {}
    for i in probe_frames:
        t0 = time.perf_counter()
        labels = family.set_frame(scene, i)
        family.render_transport(
            scene,
            render_cam,
            spp=r["spp"],
            seed=frame_seed(job["seed"], i),
            max_depth=r["max_depth"] or None,
        )
        seconds.append(time.perf_counter() - t0)
    texel_bytes = camera.num_detectors * int(np.prod(camera.mask_resolution))
    record = {"index": 0, "time_s": 0.0, "seed": 2**63 - 1, "state": family.frame_state(0)}
    frame_bytes = texel_bytes * np.dtype(r["dtype"]).itemsize + _json_size(record, labels)
    background_files = len(job.get("backgrounds", [])) + len(job.get("background_components", []))
    return JobEstimate(
        frames=job["num_frames"],
        seconds_per_frame=seconds[-1] * _cost_ratio(manifest, r["spp"], render_cam.num_detectors),
        shards=manifest["num_shards"],
        bytes_per_shard=job["shard_frames"] * frame_bytes + NPY_HEADER_BYTES,
        other_bytes=background_files * texel_bytes * 4
        + manifest["num_shards"] * MANIFEST_RECORD_BYTES,
        free_bytes=shutil.disk_usage(_existing(out)).free,
    )


def check_job(estimate: JobEstimate, limits: JobLimits, out: Path) -> None:
    """Log the estimate; refuse a job above ``limits`` unless it was confirmed.

    Raises:
        JobTooLarge: above the time limit or the free disk, not confirmed.
    """
    log.info("render estimate: %s", estimate.describe())
    over = []
    if estimate.seconds > limits.max_hours * 3600:
        over.append(f"more than {limits.max_hours:g} h")
    if estimate.bytes > estimate.free_bytes:
        over.append("more than the free disk")
    if over and not limits.confirmed:
        raise JobTooLarge(
            f"{out}: {estimate.describe()}: {' and '.join(over)}; pass --yes to render it "
            "anyway, or render fewer --frames"
        )


def _cost_ratio(manifest: dict, spp: int, detectors_rendered: int) -> float:
    """A frame's planned cost over the plain render timed (1 unless rendered differentially)."""
    differential = manifest["fidelity"].get("differential", {})
    if not (manifest["job"]["render"]["background"] and "cost_per_frame" in differential):
        return 1.0
    return float(differential["cost_per_frame"]) / (spp * detectors_rendered)


def _json_size(record: dict, labels: dict) -> int:
    """Bytes of a frame's record and labels in a shard's ``.json``."""
    return len(ds.json_bytes({"frame": record, "labels": labels}))


def _existing(path: Path) -> Path:
    """``path`` or its nearest existing ancestor (where its free space is counted)."""
    path = path.absolute()
    while not path.exists():
        path = path.parent
    return path


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.2g} s"


def _size(n: float) -> str:
    exponent = min(int(math.log10(n) // 3), 4) if n >= 1000 else 0
    return f"{n / 1000**exponent:.3g} {('B', 'kB', 'MB', 'GB', 'TB')[exponent]}"
