"""Error against run time for every fidelity knob of a scene family.

For one family at its default camera, :func:`bench_fidelity` renders a few
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
import logging
import math
import platform
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from mincam_render.core.checks import check_int
from mincam_render.core.seeds import stream_seed
from mincam_render.render.precision import printable_masks, smooth_masks

if TYPE_CHECKING:
    import os
    from pathlib import Path

    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.precision import LabelSignal
    from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)

#: Path depth of the converged reference (as the fidelity decisions' deep reference).
REFERENCE_DEPTH = 16
#: Side of the "point" detector (m); its transport is rescaled by the area ratio.
POINT_DETECTOR_SIZE_M = 1e-6
#: Knobs in the order rows are produced.
KNOBS = ("spp", "mask_res", "max_depth", "render", "detector", "storage", "paper", "auto")
#: Background window (s) of the label signal of differential families (a render
#: request's default).
SIGNAL_INTERVAL_S = 60.0
#: An effect whose estimated systematic error stays below this can be left out.
NEGLIGIBLE_EFFECT = 0.01


@dataclasses.dataclass(frozen=True, kw_only=True)
class FidelityBenchConfig:
    """Sizes of one fidelity benchmark (defaults run a family in a few minutes on 2 cores).

    Args:
        num_frames: frames rendered per setting, spread over the sequence, >= 1.
        sequence_frames: length of the family's sequence the frames are taken from.
        reference_spp: samples per texel of the reference (split in two halves).
        base_spp: samples per texel of the base setting the other knobs start from.
        spp_levels: levels of the ``spp`` knob.
        mask_res_levels: coarser mask resolutions (texels per side) to try; levels
            that do not divide the camera's resolution are skipped.
        depth_levels: path depths to try (the scene's own depth is added).
        num_masks: masks of each kind per detector.
        repeats: timed runs per setting (median reported).
        mask_resolution: override of the camera's mask resolution, or None.
        include_auto: run the automatic fidelity decision and bench its choice.
        seed: family seed (trajectories) and render seeds.
        signal_seconds: scene time (s) the label signal's frames are spread over
            (at the family's frame rate): the bench's short sequence holds too few
            changes of the labels' state to show their spread.
    """

    num_frames: int = 2
    sequence_frames: int = 60
    reference_spp: int = 256
    base_spp: int = 16
    spp_levels: tuple[int, ...] = (1, 4, 16, 64)
    mask_res_levels: tuple[int, ...] = (16, 8)
    depth_levels: tuple[int, ...] = (1, 2, 5)
    num_masks: int = 8
    repeats: int = 1
    mask_resolution: int | None = None
    include_auto: bool = True
    seed: int = 0
    signal_seconds: float = 600.0

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ValueError:
            return ValueError(
                f"FidelityBenchConfig.{name} = {getattr(self, name)!r} is invalid: "
                f"allowed {allowed}"
            )

        for name, lo, hi in (
            ("num_frames", 1, 1000),
            ("sequence_frames", 1, 10**6),
            ("reference_spp", 2, 1 << 20),
            ("base_spp", 1, 1 << 20),
            ("num_masks", 2, 1000),
            ("repeats", 1, 100),
        ):
            check_int(f"FidelityBenchConfig.{name}", getattr(self, name), lo, hi)
        if self.num_frames > self.sequence_frames:
            raise bad("num_frames", f"at most sequence_frames = {self.sequence_frames}")
        for name, hi in (("spp_levels", 1 << 20), ("mask_res_levels", 4096), ("depth_levels", 64)):
            v = tuple(getattr(self, name))
            if not all(isinstance(x, int) and 1 <= x <= hi for x in v):
                raise bad(name, f"integers in [1, {hi}]")
            object.__setattr__(self, name, v)
        if self.mask_resolution is not None and not 1 <= self.mask_resolution <= 4096:
            raise bad("mask_resolution", "None or an integer in [1, 4096]")
        if not 1e-3 <= self.signal_seconds <= 1e6:
            raise bad("signal_seconds", "a number of seconds in [1e-3, 1e6]")


# ---- masks and errors (numpy, float64) ---------------------------------------------------


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


# ---- the benchmark -----------------------------------------------------------------------


def _median_time(fn: Callable[..., np.ndarray], repeats: int) -> tuple[Any, float, float]:
    """``(result, median s, spread s)`` of ``fn()`` after an untimed ``fn(warm_up=True)``."""
    fn(warm_up=True)
    result = None
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return result, float(np.median(times)), float(np.max(times) - np.min(times))


def bench_fidelity(family_name: str, config: FidelityBenchConfig | None = None) -> dict[str, Any]:
    """Measure error against run time of every fidelity knob for one family.

    Args:
        family_name: a shipped family name or a scene TOML path.
        config: sizes; defaults run in a few minutes on 2 CPU cores.

    Returns:
        ``{"family", "rows": [{"family", "knob", "level", "error", "effect",
        "error_random", "error_trained", "error_signal_random", "error_signal_finest_box",
        "seconds", "seconds_spread", "settings"}],
        "reference": {...}, "auto": {"settings", "decisions"} or None,
        "statements": [str], "machine": {...}}``. Seconds are per frame.

    Raises:
        ConfigError: unknown family.
    """
    from mincam_render.render import backend

    cfg = config or FidelityBenchConfig()
    backend.use_variant()
    bench = _Bench.of(family_name, cfg)
    reference = bench.measure_reference()
    base_error = _bench_spp(bench)
    _bench_knobs(bench)
    auto = _bench_auto(bench, family_name) if cfg.include_auto else None
    return _result(bench, reference, base_error, auto)


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
    base_settings: dict[str, Any]
    #: reference measurements of the random and trained-like masks (set by the reference)
    p_ref: tuple[np.ndarray, np.ndarray] | None = None
    #: the reference itself and the label signal (set by the reference)
    t_ref: np.ndarray | None = None
    signal: LabelSignal | None = None
    rows: list[dict[str, Any]] = dataclasses.field(default_factory=list)

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
            base_settings={
                "spp": cfg.base_spp,
                "mask_res": camera.mask_resolution[0],
                # full depth: each knob's effect is then measured alone, not on top of the
                # scene integrator's truncation (which is a level of the max_depth knob)
                "max_depth": REFERENCE_DEPTH,
                "render": "per_detector",
                "detector": "area",
                "storage": "float32",
            },
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

    def measure_reference(self) -> dict[str, Any]:
        """Render the reference in two independent halves; its settings, time and own noise."""
        half = self.cfg.reference_spp // 2
        t0 = time.perf_counter()
        ref_a = self.render(self.camera, spp=half, max_depth=REFERENCE_DEPTH, seed_offset=101)
        ref_b = self.render(self.camera, spp=half, max_depth=REFERENCE_DEPTH, seed_offset=102)
        ref_seconds = (time.perf_counter() - t0) / len(self.frames)
        ref = 0.5 * (ref_a.astype(np.float64) + ref_b.astype(np.float64))
        self.p_ref = (measurements(ref, self.masks_random), measurements(ref, self.masks_trained))
        self.t_ref, self.signal = ref, _label_signal(self)
        # halves differ by twice the variance of their mean
        half_r = relative_rms(
            measurements(ref_a, self.masks_random), measurements(ref_b, self.masks_random)
        )
        half_t = relative_rms(
            measurements(ref_a, self.masks_trained), measurements(ref_b, self.masks_trained)
        )
        return {
            "spp": self.cfg.reference_spp,
            "max_depth": REFERENCE_DEPTH,
            "render": "per_detector",
            "detector": "area",
            "storage": "float32",
            "seconds": ref_seconds,
            "reference_noise": max(half_r, half_t) / 2.0,
        }

    def errors(self, t: np.ndarray) -> dict[str, float | None]:
        """Relative RMS errors of ``T`` against the reference, per mask kind and the larger."""
        if self.p_ref is None:
            raise RuntimeError("render the reference first")
        p_ref_r, p_ref_t = self.p_ref
        p = measurements(t, self.masks_random)
        er = relative_rms(p, p_ref_r)
        et = relative_rms(measurements(t, self.masks_trained), p_ref_t)
        return {
            "error_random": er,
            "error_trained": et,
            "error": max(er, et),
            **self.signal_errors(t, p),
        }

    def signal_errors(self, t: np.ndarray, p: np.ndarray) -> dict[str, float | None]:
        """``t``'s errors relative to the label signal: random masks, single-texel pixels.

        The single texel's is None for a transport at a coarser resolution.
        """
        from mincam_render.render.precision import ErrorScale, measurement_relative_error

        assert self.signal is not None and self.p_ref is not None and self.t_ref is not None
        signal_rms = self.signal.rms(lambda x: measurements(x, self.masks_random))
        random = float(np.sqrt(np.mean((p - self.p_ref[0]) ** 2))) / signal_rms
        box = None
        if t.shape == self.t_ref.shape:
            lo_hi = self.camera.transmittance_range
            box = measurement_relative_error(
                t, self.t_ref, lo_hi, scale=ErrorScale.SIGNAL, signal=self.signal, box_texels=1
            )["rms"]
        return {"error_signal_random": random, "error_signal_finest_box": box}

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
        max_depth = self.base_settings["max_depth"] if max_depth is None else max_depth

        def run(warm_up: bool = False) -> np.ndarray:
            t = self.render(
                cam, spp=spp, max_depth=max_depth, shared=shared, point=point, warm_up=warm_up
            )
            return decode_transport(*encode_transport(t, "float16")) if float16 else t

        return run

    def add(
        self, knob: str, level: Any, fn: Callable[..., np.ndarray], **changed: Any
    ) -> np.ndarray:
        """Time ``fn`` (a :meth:`setting`), add its row; returns its transport."""
        t, sec, spread = _median_time(fn, self.cfg.repeats)
        e = self.errors(t)
        name, n = self.family.name, len(self.frames)
        self.rows.append(
            {
                "family": name,
                "knob": knob,
                "level": level,
                **e,
                "seconds": sec / n,
                "seconds_spread": spread / n,
                "settings": {**self.base_settings, **changed},
            }
        )
        log.info(
            "fidelity bench %s %s=%s: error %.3g, %.3g s/frame",
            name,
            knob,
            level,
            e["error"],
            sec / n,
        )
        return t


def _label_signal(bench: _Bench) -> LabelSignal:
    """The family's label signal over ``signal_seconds`` (two estimates, full depth)."""
    from mincam_render.render.fidelity.constants import SIGNAL_FRAMES, SIGNAL_SPP
    from mincam_render.render.fidelity.signal import render_label_signal
    from mincam_render.scenes import load_family

    cfg, fps = bench.cfg, float(bench.family.fps)
    n = max(2, int(round(cfg.signal_seconds * fps)))
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
    return cast(float, bench.errors(base_t)["error"])  # total-relative: always a number


def _bench_knobs(bench: _Bench) -> None:
    """Rows of the knobs mask_res, max_depth, render, detector, storage and paper."""
    cfg, camera, scene_depth = bench.cfg, bench.camera, bench.scene_depth
    rows, cols = camera.mask_resolution
    for res in cfg.mask_res_levels:
        if res >= rows or rows % res or cols % res or rows != cols:
            continue
        cam_lo = dataclasses.replace(camera, mask_resolution=(res, res))
        bench.add("mask_res", res, bench.setting(cam_lo), mask_res=res)
    base_depth = bench.base_settings["max_depth"]
    scene_levels = {scene_depth} if scene_depth and 0 < scene_depth < base_depth else set()
    for depth in sorted({*cfg.depth_levels, *scene_levels} - {base_depth}):
        bench.add("max_depth", depth, bench.setting(camera, max_depth=depth), max_depth=depth)
    centre_cam = camera.centre_camera()
    point_cam = dataclasses.replace(camera, detector_size_m=POINT_DETECTOR_SIZE_M)
    paper_cam = dataclasses.replace(centre_cam, detector_size_m=POINT_DETECTOR_SIZE_M)
    bench.add("render", "shared", bench.setting(centre_cam, shared=True), render="shared")
    bench.add("detector", "point", bench.setting(point_cam, point=True), detector="point")
    bench.add("storage", "float16", bench.setting(camera, float16=True), storage="float16")
    bench.add(
        "paper",
        "centre pinhole",
        bench.setting(paper_cam, shared=True, point=True),
        render="shared",
        detector="point",
    )


def _bench_auto(bench: _Bench, family_name: str) -> dict[str, Any]:
    """The row of the automatic fidelity decision; ``{"settings", "decisions"}``."""
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
    settings = plan.settings()
    # 0 = the scene's integrator
    scene_depth = bench.scene_depth
    depth = settings["max_depth"] or (
        scene_depth if scene_depth and scene_depth > 0 else bench.base_settings["max_depth"]
    )
    shared = settings["shared_render"]
    auto_render = bench.setting(
        bench.camera.rendered_camera(shared),
        spp=settings["spp"],
        max_depth=depth,
        shared=shared,
        float16=settings["dtype"] == "float16",
    )
    bench.add(
        "auto",
        f"{settings['spp']} spp, depth {depth}, "
        f"{'shared' if shared else 'per-detector'}, {settings['dtype']}",
        auto_render,
        spp=settings["spp"],
        max_depth=depth,
        render="shared" if shared else "per_detector",
        storage=settings["dtype"],
    )
    return {"settings": settings, "decisions": plan.decisions}


def _result(bench: _Bench, reference: dict, base_error: float, auto: dict | None) -> dict[str, Any]:
    """The JSON-ready result: rows with their ``effect``, base, reference, statements, machine."""
    from mincam_render.data.render_job import source_revision
    from mincam_render.render import backend

    rows_out, camera = bench.rows, bench.camera
    for r in rows_out:
        r["effect"] = math.sqrt(max(r["error"] ** 2 - base_error**2, 0.0))
    base_row = next(
        (r for r in rows_out if r["knob"] == "spp" and r["level"] == bench.cfg.base_spp), None
    )
    base_seconds = base_row["seconds"] if base_row else None
    name = bench.family.name
    return {
        "family": name,
        "frames": bench.frames,
        "camera": {
            "detectors": camera.num_detectors,
            "mask_resolution": list(camera.mask_resolution),
            "detector_size_m": camera.detector_size_m,
        },
        "config": dataclasses.asdict(bench.cfg),
        "scene_max_depth": bench.scene_depth,
        "base": {**bench.base_settings, "error": base_error, "seconds": base_seconds},
        "reference": reference,
        "rows": rows_out,
        "auto": auto,
        "statements": fidelity_statements(name, rows_out, base_error, base_seconds, reference),
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor() or platform.machine(),
            "variant": backend.describe()["variant"],
            "git_revision": source_revision() or "not a git checkout",
        },
    }


# ---- summaries ---------------------------------------------------------------------------

_EFFECTS = {
    ("max_depth", 2): "indirect light (direct light only, depth 2)",
    ("max_depth", 3): "light after more than one bounce (depth 3)",
    ("render", "shared"): "parallax between detectors (one shared render)",
    ("detector", "point"): "the diode's area (point detector: no detector blur)",
    ("storage", "float16"): "float32 storage (float16 instead)",
    ("paper", "centre pinhole"): "what the paper's training camera approximates "
    "(centre pinhole image)",
    ("auto", None): "the automatic fidelity choice",
}


def fidelity_statements(
    family: str, rows: list[dict], base_error: float, base_s: float | None, reference: dict
) -> list[str]:
    """One sentence per effect: can it be left out, and at what error (plain text)."""
    out = []
    floor = reference["reference_noise"]
    for r in rows:
        what = _EFFECTS.get((r["knob"], None if r["knob"] == "auto" else r["level"]))
        if r["knob"] == "mask_res":
            what = f"mask detail finer than {r['level']}x{r['level']} texels"
        if what is None:
            continue
        what = what[0].upper() + what[1:]
        # float16 re-encodes the base's own samples, so its difference is not noise
        resolved = base_error < NEGLIGIBLE_EFFECT or r["knob"] == "storage"
        if r["knob"] == "auto":
            decision = (
                "within the bound"
                if r["effect"] < NEGLIGIBLE_EFFECT
                else "adds more than the bound against the full-depth reference"
            )
        elif r["effect"] >= NEGLIGIBLE_EFFECT:
            decision = "can NOT be left out"
        elif resolved:
            decision = "CAN be left out"
        else:
            decision = (
                "UNRESOLVED (its effect is below the base's own Monte Carlo error; "
                "rerun with a higher --base-spp)"
            )
        speed = (
            f", {r['seconds'] / base_s:.2g}x the base render time"
            if base_s and r["seconds"]
            else ""
        )
        out.append(
            f"{family}: {what}: {decision}; estimated effect {r['effect']:.2%} "
            f"(total error {r['error']:.2%} vs base {base_error:.2%}, reference noise "
            f"{floor:.2%}, bound {NEGLIGIBLE_EFFECT:.0%}){speed}."
        )
    return out


def pareto_front(rows: list[dict]) -> list[dict]:
    """Rows not dominated in (seconds, error): nothing else is both faster and more accurate."""
    front: list[dict] = []
    for r in sorted(rows, key=lambda r: (r["seconds"], r["error"])):
        if not front or r["error"] < front[-1]["error"]:
            front.append(r)
    return front


def plot_pareto(result: dict[str, Any], path: str | os.PathLike) -> Path:
    """Save the error-vs-seconds plot (log axes) of one family; returns the path."""
    from pathlib import Path

    from mincam_render.analysis.plots import plt

    rows = result["rows"]
    fig, ax = plt.subplots(figsize=(7.5, 5.2), constrained_layout=True)
    markers = dict(zip(KNOBS, "o s D ^ v P X *".split(), strict=True))
    cmap = plt.get_cmap("tab10")
    for i, knob in enumerate(KNOBS):
        sel = [r for r in rows if r["knob"] == knob]
        if not sel:
            continue
        ax.scatter(
            [r["seconds"] for r in sel],
            [max(r["error"], 1e-7) for r in sel],
            marker=markers[knob],
            s=240 if knob == "auto" else 50,
            color="gold" if knob == "auto" else cmap(i),
            edgecolor="black" if knob == "auto" else "none",
            zorder=4 if knob == "auto" else 3,
            label="auto-fidelity choice" if knob == "auto" else knob,
        )
        for r in sel:
            ax.annotate(
                str(r["level"]) if knob != "auto" else "auto",
                (r["seconds"], max(r["error"], 1e-7)),
                textcoords="offset points",
                xytext=(4, 3),
                fontsize=7,
            )
    front = pareto_front(rows)
    ax.plot(
        [r["seconds"] for r in front],
        [max(r["error"], 1e-7) for r in front],
        color="grey",
        lw=1,
        ls="--",
        zorder=2,
        label="Pareto front",
    )
    ax.axhline(
        result["reference"]["reference_noise"],
        color="black",
        lw=0.8,
        ls=":",
        label="reference noise",
    )
    ax.axhline(NEGLIGIBLE_EFFECT, color="red", lw=0.8, ls="-.", label="1 % error")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("render time per frame (s)")
    ax.set_ylabel("relative measurement error vs reference (RMS)")
    ax.set_title(f"{result['family']}: measurement error against run time per fidelity knob")
    ax.legend(fontsize=7, loc="best")
    ax.grid(True, which="both", alpha=0.3)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def pareto_table(result: dict) -> str:
    """The rows as a plain-text table (knob, level, error, effect, vs signal, seconds)."""
    lines = [
        f"{'knob':<10} {'level':<40} {'error':>9} {'effect':>9} {'/signal':>8} "
        f"{'/texel':>8} {'s/frame':>9}"
    ]
    for r in result["rows"]:
        box = r.get("error_signal_finest_box")
        lines.append(
            f"{r['knob']:<10} {str(r['level']):<40} {r['error']:>9.3%} {r['effect']:>9.3%} "
            f"{r['error_signal_random']:>8.3f} {'' if box is None else f'{box:.3f}':>8} "
            f"{r['seconds']:>9.3f}"
        )
    return "\n".join(lines)


def _optional(value: float | None) -> str:
    return "" if value is None else f"{value:.3f}"


def write_fidelity_report(
    results: list[dict[str, Any]], out_dir: str | os.PathLike
) -> dict[str, Any]:
    """Write ``fidelity.json``, ``pareto_<family>.png`` and ``fidelity.html`` to ``out_dir``."""
    from pathlib import Path

    from mincam_render.analysis.report import Report
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    page = Report("Fidelity: measurement error against run time")
    page.paragraph(
        "Each point changes one fidelity knob away from the base setting and compares "
        "detector measurements (P = sum T M, random printable and trained-like masks) with "
        "a converged reference: per-detector, area-sampled diode, path depth "
        f"{REFERENCE_DEPTH}. 'effect' removes the base setting's Monte Carlo error in "
        "quadrature. The gold star is the automatic fidelity choice."
    )
    pngs = []
    for res in results:
        png = plot_pareto(res, out / f"pareto_{res['family']}.png")
        pngs.append(str(png))
        page.heading(res["family"])
        page.figure_file(png, f"{res['family']}: error against run time")
        page.table(
            [
                "knob",
                "level",
                "error (RMS)",
                "random masks",
                "trained-like masks",
                "effect",
                "vs label signal (random masks)",
                "vs label signal (1 texel)",
                "s / frame",
            ],
            [
                [
                    r["knob"],
                    str(r["level"]),
                    f"{r['error']:.3%}",
                    f"{r['error_random']:.3%}",
                    f"{r['error_trained']:.3%}",
                    f"{r['effect']:.3%}",
                    f"{r['error_signal_random']:.3f}",
                    _optional(r["error_signal_finest_box"]),
                    f"{r['seconds']:.3f}",
                ]
                for r in res["rows"]
            ],
        )
        ref = res["reference"]
        page.paragraph(
            f"Reference: {ref['spp']} spp, depth {ref['max_depth']}, {ref['seconds']:.2f} "
            f"s/frame, its own noise {ref['reference_noise']:.3%}. Base: "
            f"{res['base']['spp']} spp, depth {res['base']['max_depth']} (scene integrator "
            f"depth {res['scene_max_depth']} is a level of max_depth), "
            f"error {res['base']['error']:.3%}."
        )
        page.bullets(res["statements"])
    json_path = atomic_write_bytes(out / "fidelity.json", json_bytes({"families": results}))
    html_path = page.write(out / "fidelity.html")
    return {"json": str(json_path), "html": str(html_path), "png": pngs}
