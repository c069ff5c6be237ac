"""The planning episode's probe frames, rendered as the planner's knobs ask (numpy, W)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mincam_render.core.seeds import frame_seed, stream_seed
from mincam_render.render.fidelity.constants import (
    DEEP_REFERENCE_DEPTH,
    DEFAULT_SIGNAL_TARGET_ERROR,
    DEPTH_GRID,
    FINEST_BOX_TEXELS,
    PROBE_FRAMES,
    SIGNAL_FRAMES,
    SIGNAL_SPP,
)
from mincam_render.render.fidelity.records import DepthRange, ReferenceFigures, SignalRms
from mincam_render.render.fidelity.signal import SignalSource, render_label_signal
from mincam_render.render.precision import (
    ErrorScale,
    LabelSignal,
    StorageDtype,
    UnmeasurableSignalError,
    measurement_relative_error,
    measurements_of,
)

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.differential import BackgroundFamily, DifferenceSeeds
    from mincam_render.render.fidelity.signal import ProbedFamily

    # Structural types: ``render`` sits below ``scenes`` and ``data`` in the layers
    # and does not import them.
    class PlanRequest(Protocol):
        """What the planner reads of a render request (``RenderRequest`` has it)."""

        @property
        def seed(self) -> int:
            """Dataset seed, >= 0."""

        @property
        def spp(self) -> int | None:
            """Samples per texel, or None to decide."""

        @property
        def max_depth(self) -> int | None:
            """Path depth (2 = direct light), 0 = the scene's integrator, or None to decide."""

        @property
        def shared_render(self) -> bool | None:
            """One render for all detectors, or None to decide."""

        @property
        def mask_res(self) -> int | None:
            """Mask texels per side, or None for the family camera's."""

        @property
        def dtype(self) -> StorageDtype | None:
            """Storage type, or None to decide."""

        @property
        def target_error(self) -> float:
            """Target Monte Carlo measurement error relative to the total."""

        @property
        def error_scale(self) -> ErrorScale | None:
            """What the plan's target is relative to, or None: the family's planning scale."""

        @property
        def signal_target_error(self) -> float | None:
            """Target relative to the label signal, or None: the family's."""

        @property
        def dtype_error_bound(self) -> float:
            """Largest relative measurement error float16 may add."""

        @property
        def indirect_fraction(self) -> float:
            """Drop indirect light when it changes measurements less."""

        @property
        def parallax_fraction(self) -> float:
            """Share one render when parallax is below this many texels."""

        @property
        def differential(self) -> bool | None:
            """Render frames as background plus difference, or None to decide."""

        @property
        def background_interval_s(self) -> float:
            """Scene time (s) one background's daylight stands for."""

        @property
        def background_spp(self) -> int | None:
            """Samples per texel of backgrounds, or None to decide."""

        @property
        def shared_difference(self) -> bool | None:
            """Render ``X - C`` once from the board centre, or None to decide."""

        @property
        def difference_seeds(self) -> DifferenceSeeds | None:
            """Which frames share the seed of ``X - C``, or None: the planner's default."""


def planning_targets(
    family_scale: ErrorScale, family_signal_target: float | None, request: PlanRequest
) -> tuple[ErrorScale, float]:
    """``(scale, target)`` the Monte Carlo error is planned for.

    The request's scale, else the family's (``planning_error_scale``). Relative
    to the total (frame or mean) the target is ``request.target_error``;
    relative to the label signal it is ``request.signal_target_error``, else the
    family's (``signal_target_error``), else :data:`DEFAULT_SIGNAL_TARGET_ERROR`.
    """
    scale = ErrorScale(request.error_scale or family_scale)
    if scale is not ErrorScale.SIGNAL:
        return scale, float(request.target_error)
    for target in (request.signal_target_error, family_signal_target):
        if target is not None:
            return scale, float(target)
    return scale, DEFAULT_SIGNAL_TARGET_ERROR


def probe_indices(num_frames: int) -> list[int]:
    """``PROBE_FRAMES`` frame indices spread evenly over the sequence."""
    n = min(PROBE_FRAMES, num_frames)
    return sorted({int(round(x)) for x in np.linspace(0, num_frames - 1, n)})


class Probes:
    """A family's probe frames and renders of them at fixed seeds.

    Attributes:
        family: the scene family; ``scene`` its built Mitsuba scene.
        camera: the camera the plan is for; ``k`` its detectors.
        request: the render request (seed, bounds, explicit settings).
        indices: the probe frames.
        lo_hi: printable transmittance range of the masks errors are measured with.
        scale: what the Monte Carlo target is relative to (:func:`planning_targets`).
        target_error: the Monte Carlo target in ``scale``.
        total_scale: what the bounds of the biases (path depth, float16) are
            relative to: the family's total (frame or mean), whatever ``scale``.
    """

    def __init__(self, family: ProbedFamily, camera: FreeformCamera, request: PlanRequest) -> None:
        self.family, self.camera, self.request = family, camera, request
        self.scene = family.build_scene()
        self.indices = probe_indices(family.num_frames)
        self.k = camera.num_detectors
        self.lo_hi = camera.transmittance_range
        self.scale, self.target_error = planning_targets(
            family.planning_error_scale, family.signal_target_error, request
        )
        self.total_scale = ErrorScale(family.total_error_scale)
        self._renders: dict[tuple, np.ndarray] = {}
        self._signal: LabelSignal | None = None

    @property
    def background(self) -> BackgroundFamily:
        """The family as one with a differential background; ValueError if it has none."""
        from mincam_render.render.differential import background_family

        return background_family(self.family)

    def seed(self, index: int, offset: int) -> int:
        """Render seed of probe frame ``index`` for stream ``offset`` (0 = the frame's own).

        Stream 0 is the seed the dataset renders frame ``index`` with; any other
        stream is ``stream_seed(seed, "fidelity/probe/<offset>", index)``.
        """
        if offset == 0:
            return frame_seed(self.request.seed, index)
        return stream_seed(self.request.seed, f"fidelity/probe/{offset}", index)

    def render(
        self,
        cam: FreeformCamera,
        *,
        spp: int,
        seed_offset: int = 0,
        max_depth: int | None = None,
        shared: bool = False,
        parallax: bool = True,
    ) -> np.ndarray:
        """``T[probe, detector, row, col]`` (W); ``shared``: one render copied to every detector.

        Renders are kept: the same arguments (a render at the same seed, so the
        same samples) return the kept array instead of rendering again, e.g. the
        pilot at the depth the depth decision already rendered. Do not modify it.
        """
        key = (cam, spp, seed_offset, max_depth or None, shared, parallax)
        kept = self._renders.get(key)
        if kept is None:
            kept = self._renders[key] = self._render(
                cam, spp, seed_offset, max_depth, shared, parallax
            )
        return kept

    def _render(
        self,
        cam: FreeformCamera,
        spp: int,
        seed_offset: int,
        max_depth: int | None,
        shared: bool,
        parallax: bool,
    ) -> np.ndarray:
        out = []
        for i in self.indices:
            self.family.set_frame(self.scene, i)
            t = self.family.render_transport(
                self.scene,
                cam,
                spp=spp,
                seed=self.seed(i, seed_offset),
                max_depth=max_depth or None,
                parallax=parallax,
            )
            out.append(np.repeat(t, self.k, axis=0) if shared else t)
        return np.stack(out)

    def error(
        self,
        a: np.ndarray,
        b: np.ndarray,
        scale: ErrorScale | None = None,
        box_texels: int | None = None,
    ) -> dict[str, float]:
        """Relative measurement error of ``a`` against ``b`` for random printable masks.

        Relative to ``scale`` (default :attr:`scale`, the planning target's);
        with ``box_texels``, of box pixels of that size instead of random masks.

        Raises:
            UnmeasurableSignalError: relative to a label signal that is not measurable.
        """
        scale = self.scale if scale is None else scale
        signal = self.label_signal() if scale is ErrorScale.SIGNAL else None
        return measurement_relative_error(
            a, b, self.lo_hi, scale=scale, signal=signal, box_texels=box_texels
        )

    def signal_figure(
        self, a: np.ndarray, b: np.ndarray, box_texels: int | None = None
    ) -> dict[str, float] | None:
        """:meth:`error` relative to the label signal, for a figure the plan only reports.

        None where the signal is not measurable; a plan on the signal scale
        raises instead, since its target would be undefined.
        """
        try:
            return self.error(a, b, ErrorScale.SIGNAL, box_texels)
        except UnmeasurableSignalError:
            if self.scale is ErrorScale.SIGNAL:
                raise
            return None

    def figures(self, a: np.ndarray, b: np.ndarray) -> ReferenceFigures:
        """``a`` against ``b`` in every metric: relative to the total and to the label signal.

        Random printable masks and, for the finest box, single-texel pixels.
        """
        return ReferenceFigures(
            total_relative=self.error(a, b, self.total_scale),
            total_scale=self.total_scale.value,
            signal_relative=self.signal_figure(a, b),
            signal_relative_finest_box=self.signal_figure(a, b, box_texels=FINEST_BOX_TEXELS),
        )

    def label_signal(self) -> LabelSignal:
        """The label signal of the planning episode (rendered once, then kept).

        On ``SIGNAL_FRAMES`` frames spread over the episode, at ``SIGNAL_SPP``
        and the deep reference's path depth, every detector rendered.
        """
        if self._signal is None:
            n = min(SIGNAL_FRAMES, self.family.num_frames)
            frames = sorted({int(round(x)) for x in np.linspace(0, self.family.num_frames - 1, n)})
            if len(frames) < 2:
                raise ValueError(
                    f"a {self.family.num_frames}-frame episode has no spread over frames: "
                    "the label signal needs at least 2 frames"
                )
            self._signal = render_label_signal(
                self.family,
                self.scene,
                self.camera,
                frames,
                source=SignalSource(self.family.label_signal),
                spp=SIGNAL_SPP,
                seeds=lambda i, e: stream_seed(self.request.seed, f"fidelity/signal/{e}", i),
                interval_s=self.request.background_interval_s,
                max_depth=DEEP_REFERENCE_DEPTH,
            )
        return self._signal

    def signal_rms(self) -> SignalRms:
        """The label signal's RMS (W) for the random masks and the finest box pixels."""
        signal, shape = self.label_signal(), (self.k, *self.camera.mask_resolution)
        return SignalRms(
            random_masks_w=signal.rms(measurements_of(shape, self.lo_hi)),
            finest_box_w=signal.rms(
                measurements_of(shape, self.lo_hi, box_texels=FINEST_BOX_TEXELS)
            ),
        )

    def depth_range_m(self) -> DepthRange:
        """Nearest and farthest depth (m) seen from the board centre over the probe frames."""
        depths = []
        for i in self.indices:
            self.family.set_frame(self.scene, i)
            depths.append(nearest_depth_m(self.scene, self.camera))
        return DepthRange(min_m=min(d["min"] for d in depths), max_m=max(d["max"] for d in depths))


def nearest_depth_m(scene: mi.Scene, camera: FreeformCamera) -> dict[str, float]:
    """Nearest and farthest scene depth (m, along the board normal) seen from the board centre.

    Over a ``DEPTH_GRID^2`` grid of rays from the board centre through the
    mask's field of view (:func:`depth_map_m`). Misses count as infinitely far.
    """
    depth = depth_map_m(scene, camera, (DEPTH_GRID, DEPTH_GRID))
    depth = depth[np.isfinite(depth)]
    if depth.size == 0:
        return {"min": math.inf, "max": math.inf}
    return {"min": float(depth.min()), "max": float(depth.max())}


def depth_map_m(
    scene: mi.Scene, camera: FreeformCamera, shape: tuple[int, int] | None = None
) -> np.ndarray:
    """``depth[row, col]`` (m, along the board normal) seen from the board centre.

    One ray from the board centre through each cell centre of a ``shape`` grid
    over the mask (default: the mask's texels; row 0 up). Misses are ``inf``.
    """
    import mitsuba as mi

    right, up, fwd = camera.frame
    rows, cols = shape or camera.mask_resolution
    s = ((np.arange(cols) + 0.5) / cols - 0.5) * camera.mask_size_m
    t = (0.5 - (np.arange(rows) + 0.5) / rows) * camera.mask_size_m
    ss, tt = np.meshgrid(s, t)
    dirs = ss.reshape(-1, 1) * right + tt.reshape(-1, 1) * up + camera.mask_distance_m * fwd
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origin = np.broadcast_to(np.asarray(camera.position), dirs.shape)
    ray = mi.Ray3f(
        mi.Point3f(*[mi.Float(origin[:, i]) for i in range(3)]),
        mi.Vector3f(*[mi.Float(dirs[:, i]) for i in range(3)]),
    )
    si = scene.ray_intersect(ray)
    hit = np.asarray(si.t.numpy(), dtype=np.float64)
    depth = np.where(np.isfinite(hit) & (hit < 1e30), hit * (dirs @ fwd), np.inf)
    return depth.reshape(rows, cols)


class Stages:
    """A progress bar over the planner's measurements, naming the one under way."""

    def __init__(self, total: int, *, enabled: bool) -> None:
        from tqdm import tqdm

        self._bar = tqdm(
            total=total, desc="fidelity plan", unit="step", disable=not enabled, leave=False
        )
        self._started = False

    def start(self, what: str) -> None:
        """Count the previous step done and name this one."""
        if self._started:
            self._bar.update(1)
        self._started = True
        self._bar.set_postfix_str(f"measuring {what}")

    def close(self) -> None:
        """Count the last step done and remove the bar."""
        self._bar.update(1)
        self._bar.close()
