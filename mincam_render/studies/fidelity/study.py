"""Error against run time for every fidelity knob of a scene family.

For one family at its default camera, :func:`run` renders a few
frames (spread over the sequence) with a **converged reference** -- every
detector rendered from its own position, area sampling of the diode, path depth
``REFERENCE_DEPTH``, ``reference_spp`` samples per texel, float32 -- and then
changes one knob at a time away from a **base** setting (per-detector, area
detector, the scene's own integrator, ``base_spp``, full mask resolution,
float32):

============  ==========================================================
knob          levels
============  ==========================================================
spp           samples per texel (``spp_levels``)
mask_res      transport at a coarser resolution; measured with the same
              mask block-averaged to that resolution
max_depth     path depth (1 = emitters only, 2 = direct light, ...)
render        ``per_detector`` or ``shared`` (one render at the board
              centre replicated to every detector: no parallax)
detector      ``area`` or ``point`` (a 1 um diode, rescaled by area: no
              detector blur)
storage       ``float32`` or ``float16`` (per-frame power-of-two scale)
paper         the paper's training-camera approximation: one pinhole image
              from the board centre (shared render, point detector), masks
              applied to it
auto          the settings :func:`mincam_render.render.fidelity.decide_fidelity`
              chooses for the family
============  ==========================================================

Errors are relative errors of measurements ``P_k = sum_uv T_k M_k`` against the
reference, for masks of two kinds: *random* printable masks (half i.i.d.
uniform, half sparse binary, as in
:func:`mincam_render.render.precision.measurement_relative_error`) and *trained-like*
masks (smooth random fields in the printable range, the look of trained masks).
Each row reports both RMS errors and ``error`` = the larger, all relative to the
total light; beside them the error relative to the *label signal* (the spread
over frames of what the labels' state changes, :mod:`mincam_render.render.fidelity.signal`)
for the random masks and for single-texel box pixels (the finest pixel):
``error_signal_random`` and ``error_signal_finest_box``. ``effect`` removes
the base setting's Monte Carlo error in quadrature, ``sqrt(max(e^2 - e_base^2,
0))``: an estimate of the systematic error the knob itself adds. The reference's
own Monte Carlo error (from its two independent halves) is reported as
``reference_noise``; errors below it are not resolved.

Traced kernels come from Dr.Jit's cache after the warm-up, so timings exclude
compilation.

Seconds are render seconds per frame (median over ``repeats`` timed runs after
one untimed warm-up run that compiles the kernels); storage adds its encode and
decode time to the base render.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.core.seeds import stream_seed
from mincam_render.render.precision import StorageDtype, printable_masks, smooth_masks
from mincam_render.studies.fidelity.config import (
    KNOBS,
    POINT_DETECTOR_SIZE_M,
    REFERENCE_DEPTH,
    SIGNAL_INTERVAL_S,
    FidelityBenchConfig,
)
from mincam_render.studies.fidelity.report import fidelity_statements
from mincam_render.studies.fidelity.result import (
    BaseRun,
    BenchCamera,
    DetectorModel,
    FamilyFidelity,
    FidelityBenchResult,
    FidelityRow,
    KnobErrors,
    KnobSettings,
    Machine,
    ReferenceRun,
    RenderSharing,
    SignalErrors,
    effect,
)

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.fidelity import FidelityPlan
    from mincam_render.render.precision import LabelSignal
    from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)

__all__ = ["KNOBS", "block_mean", "measure_family", "measurements", "relative_rms", "run"]


def block_mean(masks: np.ndarray, res: int) -> np.ndarray:
    """Block-average ``M[..., rows, cols]`` to ``res x res`` (rows, cols multiples of res)."""
    rows, cols = masks.shape[-2:]
    fr, fc = rows // res, cols // res
    lead = masks.shape[:-2]
    return masks.reshape(*lead, res, fr, res, fc).mean(axis=(-3, -1))


def measurements(transport_w: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """Measurements ``P[frame, mask, detector] = sum_uv T[frame, k] M[mask, k]`` (W).

    Masks are block-averaged to the transport's resolution when it is coarser.
    """
    t = np.asarray(transport_w, np.float64)
    if t.shape[-1] != masks.shape[-1]:
        masks = block_mean(masks, t.shape[-1])
    return np.einsum("nkrc,mkrc->nmk", t, masks)


def relative_rms(p: np.ndarray, p_ref: np.ndarray) -> float:
    """RMS over all entries of ``|p - p_ref| / |p_ref|`` (entries with p_ref = 0 skipped)."""
    ok = np.abs(p_ref) > 0
    if not np.any(ok):
        return 0.0
    return float(np.sqrt(np.mean(((p - p_ref)[ok] / p_ref[ok]) ** 2)))


def _median_time(fn: Callable[..., np.ndarray], repeats: int) -> tuple[np.ndarray, float, float]:
    """``(result, median s, spread s)`` of ``fn()`` after an untimed ``fn(warm_up=True)``."""
    fn(warm_up=True)
    result = None
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    assert result is not None  # repeats >= 1
    return result, float(np.median(times)), float(np.max(times) - np.min(times))


def run(config: FidelityBenchConfig, out: str | os.PathLike) -> FidelityBenchResult:
    """Measure error against run time of every fidelity knob, for every family of ``config``.

    The families are measured one after the other, each in a few minutes on 2
    CPU cores at the default sizes; each family's result is kept in
    ``out/families/<family>.json`` as soon as it is measured, so a killed
    benchmark run again with the same sizes measures only the families it
    had not finished (a kept family of other sizes is measured again). The
    report is :func:`~.report.write_report`'s.

    Raises:
        ConfigError: an unknown family.
    """
    kept_dir = Path(out) / "families"
    return FidelityBenchResult(
        config=config,
        families=tuple(_kept_or_measured(name, config, kept_dir) for name in config.families),
    )


def _kept_or_measured(
    family_name: str, config: FidelityBenchConfig, kept_dir: Path
) -> FamilyFidelity:
    """The family's result kept in ``kept_dir`` for these sizes, or measured and kept there."""
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    path = kept_dir / f"{Path(family_name).stem}.json"
    if path.is_file():
        record = json.loads(path.read_text())
        if record.get("family") == family_name and record.get("config") == config.sizes_json():
            log.info("fidelity bench: %s read back from %s", family_name, path)
            return FamilyFidelity.from_json(record, config)
        log.info("fidelity bench: %s kept at other sizes in %s; measuring again", family_name, path)
    family = measure_family(family_name, config)
    kept_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, json_bytes(family.as_json()))
    return family


def measure_family(family_name: str, config: FidelityBenchConfig) -> FamilyFidelity:
    """Measure error against run time of every fidelity knob for one family.

    Args:
        family_name: a shipped family name or a scene TOML path.
        config: sizes (its ``families`` are not read).

    Returns:
        The family's rows (seconds are per frame), reference, base, automatic
        choice (None unless ``config.include_auto``), statements and machine.

    Raises:
        ConfigError: unknown family.
    """
    from mincam_render.render import backend

    backend.use_variant()
    bench = _Bench.of(family_name, config)
    reference = bench.measure_reference()
    base_error = _bench_spp(bench)
    _bench_knobs(bench)
    auto = _bench_auto(bench, family_name) if config.include_auto else None
    return _family_result(bench, reference, base_error, auto)


@dataclasses.dataclass(frozen=True)
class _Timed:
    """A knob level as measured, before the base's error gives its effect."""

    knob: str
    level: int | str
    errors: KnobErrors
    seconds: float
    seconds_spread: float
    settings: KnobSettings


@dataclasses.dataclass
class _Bench:
    """One family's benchmark: its scene and frames, the masks, the reference, the rows.

    Transport images are numpy ``T[frame, detector, row, col]`` (W); measurements are
    compared as ``P[frame, mask, detector]`` (:func:`measurements`).
    """

    cfg: FidelityBenchConfig
    family_name: str
    family: SceneFamily
    camera: FreeformCamera
    scene: mi.Scene
    frames: list[int]
    scene_depth: int | None
    masks_random: np.ndarray
    masks_trained: np.ndarray
    base_settings: KnobSettings
    #: reference measurements of the random and trained-like masks (set by the reference)
    p_ref: tuple[np.ndarray, np.ndarray] | None = None
    #: the reference itself and the label signal (set by the reference)
    t_ref: np.ndarray | None = None
    signal: LabelSignal | None = None
    rows: list[_Timed] = dataclasses.field(default_factory=list)

    @classmethod
    def of(cls, family_name: str, cfg: FidelityBenchConfig) -> _Bench:
        """The family at its default camera (or ``cfg.mask_resolution``), bench frames, masks."""
        from mincam_render.render.transport import scene_max_depth
        from mincam_render.scenes import load_family

        family = load_family(family_name, seed=cfg.seed, num_frames=cfg.sequence_frames)
        camera = family.camera()
        if cfg.mask_resolution is not None:
            camera = dataclasses.replace(
                camera, mask_resolution=(cfg.mask_resolution, cfg.mask_resolution)
            )
        scene = family.build_scene()
        frames = np.linspace(0, family.num_frames - 1, cfg.num_frames)
        shape = (camera.num_detectors, *camera.mask_resolution)
        lo_hi = camera.transmittance_range
        return cls(
            cfg=cfg,
            family_name=family_name,
            family=family,
            camera=camera,
            scene=scene,
            frames=sorted({int(round(x)) for x in frames}),
            scene_depth=scene_max_depth(scene),
            masks_random=printable_masks(
                cfg.num_masks, shape, lo_hi, stream_seed(cfg.seed, "fidelity_bench/random_masks")
            ),
            masks_trained=smooth_masks(
                cfg.num_masks, shape, lo_hi, stream_seed(cfg.seed, "fidelity_bench/smooth_masks")
            ),
            # full depth: each knob's effect is then measured alone, not on top of the
            # scene integrator's truncation (which is a level of the max_depth knob)
            base_settings=KnobSettings(
                spp=cfg.base_spp, mask_res=camera.mask_resolution[0], max_depth=REFERENCE_DEPTH
            ),
        )

    def render(
        self,
        cam: FreeformCamera,
        *,
        spp: int,
        max_depth: int | None = None,
        shared: bool = False,
        seed_offset: int = 0,
        point: bool = False,
        warm_up: bool = False,
    ) -> np.ndarray:
        """``T[frame, detector, row, col]`` (float32, W) of the bench frames through ``cam``.

        Args:
            cam: the camera rendered (its centre camera when ``shared``).
            spp: samples per texel.
            max_depth: path depth, None = the scene's integrator.
            shared: replicate the one render to every detector of the bench's camera.
            seed_offset: render seed stream.
            point: ``cam`` has a point detector: rescale to the real diode's area.
            warm_up: render one frame only (enough to compile the kernels).
        """
        k = self.camera.num_detectors
        out = []
        for i in self.frames[:1] if warm_up else self.frames:
            self.family.set_frame(self.scene, i)
            seed = stream_seed(self.cfg.seed, f"fidelity_bench/{seed_offset}", i)
            # the family's estimator (sun-patch sampling indoors), as datasets render
            t = self.family.render_transport(
                self.scene, cam, spp=spp, seed=seed, max_depth=max_depth
            )
            if point:
                # power scales with detector area: rescale to the real diode's
                t = t * np.float32((self.camera.detector_size_m / POINT_DETECTOR_SIZE_M) ** 2)
            out.append(np.repeat(t, k, axis=0) if shared else t)
        return np.stack(out)

    def measure_reference(self) -> ReferenceRun:
        """Render the reference in two independent halves; its settings, time and own noise."""
        half = self.cfg.reference_spp // 2
        t0 = time.perf_counter()
        ref_a = self.render(self.camera, spp=half, max_depth=REFERENCE_DEPTH, seed_offset=101)
        ref_b = self.render(self.camera, spp=half, max_depth=REFERENCE_DEPTH, seed_offset=102)
        ref_seconds = (time.perf_counter() - t0) / len(self.frames)
        ref = 0.5 * (ref_a.astype(np.float64) + ref_b.astype(np.float64))
        self.p_ref = (measurements(ref, self.masks_random), measurements(ref, self.masks_trained))
        self.t_ref = ref
        if self.cfg.signal_seconds is not None:
            self.signal = _label_signal(self, self.cfg.signal_seconds)
        # halves differ by twice the variance of their mean
        half_r = relative_rms(
            measurements(ref_a, self.masks_random), measurements(ref_b, self.masks_random)
        )
        half_t = relative_rms(
            measurements(ref_a, self.masks_trained), measurements(ref_b, self.masks_trained)
        )
        return ReferenceRun(
            spp=self.cfg.reference_spp,
            seconds=ref_seconds,
            reference_noise=max(half_r, half_t) / 2.0,
        )

    def errors(self, t: np.ndarray) -> KnobErrors:
        """Relative RMS errors of ``T`` against the reference, per mask kind."""
        if self.p_ref is None:
            raise RuntimeError("render the reference first")
        p_ref_r, p_ref_t = self.p_ref
        p = measurements(t, self.masks_random)
        return KnobErrors(
            error_random=relative_rms(p, p_ref_r),
            error_trained=relative_rms(measurements(t, self.masks_trained), p_ref_t),
            signal=None if self.signal is None else self.signal_errors(t, p, self.signal),
        )

    def signal_errors(self, t: np.ndarray, p: np.ndarray, signal: LabelSignal) -> SignalErrors:
        """``t``'s errors relative to the label signal: random masks, single-texel pixels.

        The single texel's is None for a transport at a coarser resolution.
        """
        from mincam_render.render.precision import ErrorScale, measurement_relative_error

        assert self.p_ref is not None and self.t_ref is not None
        error = float(np.sqrt(np.mean((p - self.p_ref[0]) ** 2)))
        random = error / signal.error_scale_w(lambda x: measurements(x, self.masks_random))
        box = None
        if t.shape == self.t_ref.shape:
            lo_hi = self.camera.transmittance_range
            box = measurement_relative_error(
                t, self.t_ref, lo_hi, scale=ErrorScale.SIGNAL, signal=signal, box_texels=1
            )["rms"]
        return SignalErrors(random=random, finest_box=box)

    def setting(
        self,
        cam: FreeformCamera,
        *,
        spp: int | None = None,
        max_depth: int | None = None,
        shared: bool = False,
        point: bool = False,
        float16: bool = False,
    ) -> Callable[..., np.ndarray]:
        """A render of all bench frames under one setting; ``warm_up`` renders one frame.

        ``spp`` and ``max_depth`` default (None) to the base setting's.
        """
        from mincam_render.render.precision import decode_transport, encode_transport

        spp = self.cfg.base_spp if spp is None else spp
        max_depth = self.base_settings.max_depth if max_depth is None else max_depth

        def render(warm_up: bool = False) -> np.ndarray:
            t = self.render(
                cam, spp=spp, max_depth=max_depth, shared=shared, point=point, warm_up=warm_up
            )
            return decode_transport(*encode_transport(t, "float16")) if float16 else t

        return render

    def add(
        self, knob: str, level: int | str, fn: Callable[..., np.ndarray], **changed: Any
    ) -> np.ndarray:
        """Time ``fn`` (a :meth:`setting`), add its row; returns its transport.

        ``changed``: the :class:`KnobSettings` fields this setting changes from the base.
        """
        t, sec, spread = _median_time(fn, self.cfg.repeats)
        e = self.errors(t)
        n = len(self.frames)
        settings = dataclasses.replace(self.base_settings, **changed)
        self.rows.append(_Timed(knob, level, e, sec / n, spread / n, settings))
        log.info(
            "fidelity bench %s %s=%s: error %.3g, %.3g s/frame",
            self.family.name,
            knob,
            level,
            e.error,
            sec / n,
        )
        return t


def _label_signal(bench: _Bench, seconds: float) -> LabelSignal:
    """The family's label signal over ``seconds`` of scene time (two estimates, full depth)."""
    from mincam_render.render.fidelity.constants import SIGNAL_FRAMES, SIGNAL_SPP
    from mincam_render.render.fidelity.signal import render_label_signal
    from mincam_render.scenes import load_family

    cfg, fps = bench.cfg, float(bench.family.fps)
    n = max(2, int(round(seconds * fps)))
    family = load_family(bench.family_name, seed=cfg.seed, num_frames=n)
    frames = sorted({int(round(x)) for x in np.linspace(0, n - 1, min(SIGNAL_FRAMES, n))})
    return render_label_signal(
        family,
        family.build_scene(),
        bench.camera,
        frames,
        source=family.label_signal,
        spp=SIGNAL_SPP,
        seeds=lambda i, e: stream_seed(cfg.seed, f"fidelity_bench/signal/{e}", i),
        interval_s=SIGNAL_INTERVAL_S,
        max_depth=REFERENCE_DEPTH,
    )


def _bench_spp(bench: _Bench) -> float:
    """Rows of the ``spp`` knob; returns the base setting's error."""
    cfg = bench.cfg
    for spp in cfg.spp_levels:
        t = bench.add("spp", spp, bench.setting(bench.camera, spp=spp), spp=spp)
        if spp == cfg.base_spp:
            base_t = t
    if cfg.base_spp not in cfg.spp_levels:
        base_t = bench.setting(bench.camera)()
    return bench.errors(base_t).error


def _bench_knobs(bench: _Bench) -> None:
    """Rows of the knobs mask_res, max_depth, render, detector, storage and paper."""
    cfg, camera, scene_depth = bench.cfg, bench.camera, bench.scene_depth
    rows, cols = camera.mask_resolution
    for res in cfg.mask_res_levels:
        if res >= rows or rows % res or cols % res or rows != cols:
            continue
        cam_lo = dataclasses.replace(camera, mask_resolution=(res, res))
        bench.add("mask_res", res, bench.setting(cam_lo), mask_res=res)
    base_depth = bench.base_settings.max_depth
    scene_levels = {scene_depth} if scene_depth and 0 < scene_depth < base_depth else set()
    for depth in sorted({*cfg.depth_levels, *scene_levels} - {base_depth}):
        bench.add("max_depth", depth, bench.setting(camera, max_depth=depth), max_depth=depth)
    centre_cam = camera.centre_camera()
    point_cam = dataclasses.replace(camera, detector_size_m=POINT_DETECTOR_SIZE_M)
    paper_cam = dataclasses.replace(centre_cam, detector_size_m=POINT_DETECTOR_SIZE_M)
    shared, point = RenderSharing.SHARED, DetectorModel.POINT
    bench.add("render", "shared", bench.setting(centre_cam, shared=True), render=shared)
    bench.add("detector", "point", bench.setting(point_cam, point=True), detector=point)
    float16 = bench.setting(camera, float16=True)
    bench.add("storage", "float16", float16, storage=StorageDtype.FLOAT16)
    paper = bench.setting(paper_cam, shared=True, point=True)
    bench.add("paper", "centre pinhole", paper, render=shared, detector=point)


def _bench_auto(bench: _Bench, family_name: str) -> FidelityPlan:
    """The row of the automatic fidelity decision; returns its plan."""
    from mincam_render.data.render_job import RenderRequest
    from mincam_render.render.fidelity import decide_fidelity

    # the knobs here are those of plain renders; differential rendering
    # (backgrounds + frames) is measured by benchmarks/bench_render.py
    request = RenderRequest(
        family=family_name,
        num_frames=bench.family.num_frames,
        seed=bench.cfg.seed,
        differential=False,
    )
    plan = decide_fidelity(bench.family, bench.camera, request)
    # 0 = the scene's integrator
    scene_depth = bench.scene_depth
    depth = plan.max_depth or (
        scene_depth if scene_depth and scene_depth > 0 else bench.base_settings.max_depth
    )
    shared = plan.shared_render
    auto_render = bench.setting(
        bench.camera.rendered_camera(shared),
        spp=plan.spp,
        max_depth=depth,
        shared=shared,
        float16=plan.dtype is StorageDtype.FLOAT16,
    )
    bench.add(
        "auto",
        f"{plan.spp} spp, depth {depth}, "
        f"{'shared' if shared else 'per-detector'}, {plan.dtype.value}",
        auto_render,
        spp=plan.spp,
        max_depth=depth,
        render=RenderSharing.SHARED if shared else RenderSharing.PER_DETECTOR,
        storage=plan.dtype,
    )
    return plan


def _family_result(
    bench: _Bench, reference: ReferenceRun, base_error: float, auto: FidelityPlan | None
) -> FamilyFidelity:
    """The family's result: rows with their ``effect``, base, reference, statements, machine."""
    from mincam_render.data.render_job import source_revision
    from mincam_render.render import backend

    rows = tuple(
        FidelityRow(
            family=bench.family.name,
            knob=r.knob,
            level=r.level,
            errors=r.errors,
            effect=effect(r.errors.error, base_error),
            seconds=r.seconds,
            seconds_spread=r.seconds_spread,
            settings=r.settings,
        )
        for r in bench.rows
    )
    base_row = next((r for r in rows if r.knob == "spp" and r.level == bench.cfg.base_spp), None)
    base = BaseRun(
        settings=bench.base_settings,
        error=base_error,
        seconds=base_row.seconds if base_row else None,
    )
    camera = bench.camera
    return FamilyFidelity(
        family=bench.family.name,
        frames=tuple(bench.frames),
        camera=BenchCamera(
            detectors=camera.num_detectors,
            mask_resolution=camera.mask_resolution,
            detector_size_m=camera.detector_size_m,
        ),
        config=bench.cfg,
        scene_max_depth=bench.scene_depth,
        base=base,
        reference=reference,
        rows=rows,
        auto=auto,
        statements=tuple(fidelity_statements(bench.family.name, rows, base, reference)),
        machine=Machine(
            platform=platform.platform(),
            processor=platform.processor() or platform.machine(),
            variant=backend.describe()["variant"],
            git_revision=source_revision() or "not a git checkout",
        ),
    )
