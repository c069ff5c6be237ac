"""Differential rendering or not (``B + X - C``), with the spp of its frames and backgrounds.

Measured on the probe frames with common random numbers (``X`` and ``C`` with one
seed): the parallax of sharing ``X - C`` from the board centre, the noise of
``X - C`` from two seeds, the backgrounds' noise and their daylight
interpolation; the error budget then gives the spp of frames and backgrounds,
and the cost per frame of both estimators (paths traced, backgrounds amortized
over the dataset) decides. ``X - C`` is traced at the plain depth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.seeds import frame_seed, stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.render.capabilities import DifferentialBackground
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.render.fidelity.budget import split_noise_budget, spp_for
from mincam_render.render.fidelity.constants import (
    BACKGROUND_PILOT_SPP,
    DIFFERENCE_BASE_SPP,
    DIFFERENCE_PILOT_SPP,
    DIFFERENCE_SEEDS,
    INTERPOLATION_SPP,
    MAX_AUTO_SPP,
    MAX_BACKGROUND_SPP,
    PILOT_SPP,
    PLAN_ERROR_SHARE,
    SHARED_DIFFERENCE_SPP,
    SHARED_ERROR_SHARE,
)
from mincam_render.render.fidelity.probes import Probes
from mincam_render.render.fidelity.records import (
    Decision,
    DifferentialCost,
    Interpolation,
    Source,
)
from mincam_render.render.fidelity.signal import difference_pair

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera


def decide_differential(
    p: Probes, auto: bool, render_cam: FreeformCamera, max_depth: int, plain_spp: int
) -> Decision:
    """The decision of differential rendering (see the module doc).

    Raises:
        ValueError: ``--differential`` for a family without a static background.
    """
    from mincam_render.render.differential import background_parts

    record: JsonObject = {"background_interval_s": p.request.background_interval_s}
    settled = _settled_without_measuring(p, auto, record)
    if settled is not None:
        return settled
    parts = background_parts(p.background, p.family.num_frames, p.request.background_interval_s)
    components = {c for part in parts.values() for c in part}
    record["backgrounds"] = len(parts)
    record["converged_renders"] = len(components)
    record["difference_seeds"] = _difference_seeds(p).as_json()
    pilots = _pilots(p, render_cam, max_depth or None, record)
    cost = _settings_and_cost(p, pilots, len(parts), len(components), plain_spp)
    record.update(cost.as_json())
    if p.request.differential:
        value, source, reason = True, Source.FLAG, "set by --differential"
    else:
        value, source = cost.cost_per_frame < cost.plain_cost_per_frame, Source.AUTO
        reason = _reason(p, cost, pilots, len(parts), len(components), plain_spp)
    return Decision(value=value, source=source, reason=reason, measured=record)


def _settled_without_measuring(p: Probes, auto: bool, record: JsonObject) -> Decision | None:
    """The decision when a flag, full fidelity or the family settles it; else None."""
    family, request = p.family, p.request
    available = isinstance(family, DifferentialBackground)
    if request.differential is not None:
        if request.differential and not available:
            raise ValueError(
                f"family {family.name!r} has no static background: differential rendering "
                "is unavailable (drop --differential)"
            )
        if not request.differential:
            reason = "set by --no-differential"
            return Decision(value=False, source=Source.FLAG, reason=reason, measured=record)
    elif not auto:
        reason = "full fidelity renders frames whole"
        return Decision(value=False, source=Source.FULL, reason=reason, measured=record)
    elif not available:
        reason = f"family {family.name!r} has no static background"
        return Decision(value=False, source=Source.AUTO, reason=reason, measured=record)
    return None


def _difference_seeds(p: Probes) -> Decision:
    """Which frames share the seed of ``X - C``: the request's, else :data:`DIFFERENCE_SEEDS`."""
    if p.request.difference_seeds is not None:
        value = DifferenceSeeds(p.request.difference_seeds)
        return Decision(value=value.value, source=Source.FLAG, reason="set by --difference-seeds")
    reason = (
        "chosen by measurement: the task figures trained and tested on episodes with "
        "per-window and per-frame seeds (benchmarks/results/task_fidelity.json)"
    )
    return Decision(value=DIFFERENCE_SEEDS.value, source=Source.AUTO, reason=reason)


def _difference_pair(
    p: Probes, depth: int | None, seed_offset: int, spp: int, camera: FreeformCamera
) -> tuple[np.ndarray, np.ndarray]:
    """``(X, C)`` per probe with one seed each (common random numbers)."""

    def render(seed: int) -> np.ndarray:
        return p.family.render_transport(p.scene, camera, spp=spp, seed=seed, max_depth=depth)

    interval = p.request.background_interval_s
    pairs = [
        difference_pair(p.background, p.scene, render, i, p.seed(i, seed_offset + 11), interval)
        for i in p.indices
    ]
    return np.stack([x for x, _ in pairs]), np.stack([c for _, c in pairs])


@dataclass(frozen=True, kw_only=True)
class _Pilots:
    """What the differential estimator's pilots measured on the probes.

    Args:
        deep: path depth of ``X - C`` and the backgrounds (None: the scene's integrator).
        rendered_detectors: detectors rendered (1 when the plain render is shared).
        shared_difference: ``X - C`` is rendered once from the board centre.
        frame_paths: detectors ``X - C`` is rendered for.
        difference: relative noise of ``X - C`` at ``PILOT_SPP``.
        background: relative noise of a background at ``PILOT_SPP``.
        interpolation: the backgrounds' interpolation within a window.
        parallax: the relative error of sharing ``X - C`` (0 when not shared).
    """

    deep: int | None
    rendered_detectors: int
    shared_difference: bool
    frame_paths: int
    difference: float
    background: float
    interpolation: Interpolation
    parallax: float


def _pilots(p: Probes, render_cam: FreeformCamera, deep: int | None, record: JsonObject) -> _Pilots:
    """Noises and biases of the differential estimator on the probes (see the module doc).

    Adds ``record["shared_difference"]`` where there is more than one detector.
    """
    # X - C is traced as deep as the backgrounds: truncating it would bias the
    # movers' change and save little, since a path costs about the same at any
    # depth once Russian roulette and escapes through the window set in
    # (workspace, 12 spp: 12.7 ms per frame at depth 4, 16 at 6, 17.8 at 12).
    x_ref = _frames_in_window(p, render_cam, deep)
    shared_difference, parallax = _shared_difference(p, render_cam, deep, x_ref, record)
    diff_cam = render_cam.rendered_camera(shared_difference)
    x1, c1 = _difference_pair(p, deep, 1, DIFFERENCE_PILOT_SPP, diff_cam)
    x2, c2 = _difference_pair(p, deep, 2, DIFFERENCE_PILOT_SPP, diff_cam)
    # [N, 1, R, C] differences broadcast over the detectors when shared; the
    # noise is reported at PILOT_SPP like the others
    e_diff = (
        p.error(x_ref + x1 - c1, x_ref + x2 - c2)["rms"]
        / math.sqrt(2.0)
        * math.sqrt(DIFFERENCE_PILOT_SPP / PILOT_SPP)
    )
    return _Pilots(
        deep=deep,
        rendered_detectors=render_cam.num_detectors,
        shared_difference=shared_difference,
        frame_paths=diff_cam.num_detectors,
        difference=e_diff,
        background=_background_noise(p, render_cam, deep),
        interpolation=_interpolation_error(p, render_cam, deep),
        parallax=parallax if shared_difference else 0.0,
    )


def _frames_in_window(p: Probes, render_cam: FreeformCamera, deep: int | None) -> np.ndarray:
    """The probes' ``X`` that relative errors of ``X - C`` are taken against."""
    x_ref = []
    for i in p.indices:
        p.background.set_frame_in_window(p.scene, i, p.request.background_interval_s)
        x_ref.append(
            p.family.render_transport(
                p.scene,
                render_cam,
                spp=DIFFERENCE_BASE_SPP,
                seed=frame_seed(p.request.seed, i),
                max_depth=deep,
            )
        )
    return np.stack(x_ref)


def _shared_difference(
    p: Probes, render_cam: FreeformCamera, deep: int | None, x_ref: np.ndarray, record: JsonObject
) -> tuple[bool, float]:
    """One render of ``X - C`` from the board centre for all detectors? And its parallax error.

    Its parallax error ``p`` is measured against the noise of independent seeds:
    ``e_shared^2 ~ noise^2 + p^2`` and ``e_noise^2 ~ noise^2`` (same spp); 0 where
    it is not measured (a flag, or one detector). Records the choice in ``record``.
    """
    k = render_cam.num_detectors
    if k > 1 and p.request.shared_difference is not None:
        record["shared_difference"] = {"value": p.request.shared_difference, "source": "flag"}
        return p.request.shared_difference, 0.0
    if k <= 1:
        return False, 0.0
    xa, ca = _difference_pair(p, deep, 3, SHARED_DIFFERENCE_SPP, render_cam)
    xb, cb = _difference_pair(p, deep, 4, SHARED_DIFFERENCE_SPP, render_cam)
    centre_cam = render_cam.centre_camera()
    xc, cc = _difference_pair(p, deep, 5, SHARED_DIFFERENCE_SPP, centre_cam)
    e_shared = p.error(xa + (xc - cc) - (xa - ca), xa)["rms"]
    e_noise = p.error(xa + (xb - cb) - (xa - ca), xa)["rms"]
    parallax_error = math.sqrt(max(e_shared**2 - e_noise**2, 0.0))
    bound = SHARED_ERROR_SHARE * p.target_error
    record["shared_difference"] = {
        "value": parallax_error < bound,
        "source": "auto",
        "parallax_error_rms": parallax_error,
        "shared_vs_per_detector_rms": e_shared,
        "two_seeds_rms": e_noise,
        "probe_spp": SHARED_DIFFERENCE_SPP,
        "bound": bound,
    }
    return parallax_error < bound, parallax_error


def _background_noise(p: Probes, camera: FreeformCamera, depth: int | None) -> float:
    """Monte Carlo error of the probes' backgrounds, piloted at BACKGROUND_PILOT_SPP.

    Two seeds per probe; reported at PILOT_SPP (times sqrt(BACKGROUND_PILOT_SPP /
    PILOT_SPP)) like the other noises. Stratified samples converge faster than
    1/sqrt(spp) (:mod:`mincam_render.render.transport`), so extrapolating from a pilot
    nearer the backgrounds' spp wastes fewer samples than one at PILOT_SPP.
    A whole background is piloted: its components, rendered apart and summed,
    are no noisier (their weights' squares sum to at most 1 per light).
    """
    renders: dict[int, list[np.ndarray]] = {0: [], 1: []}
    for i in p.indices:
        p.background.set_background(p.scene, i, p.request.background_interval_s)
        for s in renders:
            renders[s].append(
                p.family.render_transport(
                    p.scene,
                    camera,
                    spp=BACKGROUND_PILOT_SPP,
                    seed=p.seed(i, s + 31),
                    max_depth=depth,
                )
            )
    a, b = (np.stack(r) for r in renders.values())
    error = p.error(a, b)["rms"] / math.sqrt(2.0)
    return error * math.sqrt(BACKGROUND_PILOT_SPP / PILOT_SPP)


def _interpolation_error(p: Probes, camera: FreeformCamera, depth: int | None) -> Interpolation:
    """Error of the background halfway through the probes' windows, interpolated from its ends.

    ``B`` at the start, the middle and the end of each probe frame's window with
    one seed (common random numbers, so the figure is the interpolation's, not
    noise), at ``INTERPOLATION_SPP``.
    """
    spp = INTERPOLATION_SPP
    ends, middles = [], []
    for i in p.indices:
        renders = []
        for at in (0.0, 0.5, 1.0):
            p.background.set_background(p.scene, i, p.request.background_interval_s, at=at)
            renders.append(
                p.family.render_transport(
                    p.scene,
                    camera,
                    spp=spp,
                    seed=stream_seed(p.request.seed, "fidelity/interpolation", i),
                    max_depth=depth,
                )
            )
        ends.append(0.5 * (renders[0] + renders[2]))
        middles.append(renders[1])
    return Interpolation(error=p.error(np.stack(ends), np.stack(middles)), probe_spp=spp, at=0.5)


def _settings_and_cost(
    p: Probes, pilots: _Pilots, backgrounds: int, components: int, plain_spp: int
) -> DifferentialCost:
    """Frame and background spp from the error budget, and both estimators' cost per frame.

    The biases measured on the probes are fixed; the two noises share what is
    left, split to minimize the cost per frame (:func:`split_noise_budget`). Cost
    is paths traced per frame (samples x detectors rendered, backgrounds
    amortized): a deterministic stand-in for time (wall-clock figures would make
    two plans of one request differ). Paths, not path segments: measured on the
    workspace, a path costs about the same at depth 4 as at depth 12 (Russian
    roulette, escapes through the window, per-path camera and light sampling).
    """
    # detectors rendered: 1 when the plain render is shared from the board centre
    request, k, frames = p.request, pilots.rendered_detectors, p.family.num_frames
    # per-frame seeds render C again with every frame: twice the frames' paths
    per_frame = DifferenceSeeds(p.request.difference_seeds or DIFFERENCE_SEEDS)
    seed_factor = 2 if per_frame is DifferenceSeeds.FRAME else 1
    biases = {
        "shared_difference_parallax": pilots.parallax,
        "daylight_interpolation": pilots.interpolation.error["rms"],
    }
    e_diff, e_bg = pilots.difference, pilots.background
    frame_paths = seed_factor * pilots.frame_paths
    background_paths = k * components / frames
    planned_error = PLAN_ERROR_SHARE * p.target_error
    budget = split_noise_budget(
        planned_error,
        biases,
        (e_diff, frame_paths, request.spp),
        (e_bg, background_paths, request.background_spp),
    )
    frame_spp = (
        request.spp
        if request.spp is not None
        else spp_for(e_diff, budget.difference_noise, MAX_AUTO_SPP, 4)
    )
    # the background takes what the frame's rounded-up spp left
    budget = split_noise_budget(
        planned_error,
        biases,
        (e_diff, frame_paths, frame_spp),
        (e_bg, background_paths, request.background_spp),
    )
    background_spp = (
        request.background_spp
        if request.background_spp is not None
        else spp_for(e_bg, budget.background_noise, MAX_BACKGROUND_SPP, 4)
    )
    frame_cost = frame_spp * frame_paths
    # every window's own C at the frames' samples (rendered with either seeds)
    background_cost = components * background_spp * k + backgrounds * frame_spp * pilots.frame_paths
    deep = pilots.deep
    return DifferentialCost(
        frame_max_depth=0 if deep is None else deep,
        frame_spp=frame_spp,
        background_spp=background_spp,
        difference_pilot_error_rms=e_diff,
        background_pilot_error_rms=e_bg,
        background_pilot_spp=BACKGROUND_PILOT_SPP,
        daylight_interpolation=pilots.interpolation,
        error_budget=budget,
        predicted_error_rms=math.hypot(
            e_diff * math.sqrt(PILOT_SPP / frame_spp),
            e_bg * math.sqrt(PILOT_SPP / background_spp),
            *biases.values(),
        ),
        cost_per_frame=frame_cost + background_cost / frames,
        plain_cost_per_frame=plain_spp * k,
    )


def _reason(
    p: Probes,
    cost: DifferentialCost,
    pilots: _Pilots,
    backgrounds: int,
    components: int,
    plain_spp: int,
) -> str:
    shared = " from the board centre" if pilots.shared_difference else ""
    interval = p.request.background_interval_s
    return (
        f"B + X - C: X at depth {cost.frame_max_depth} x {cost.frame_spp} spp"
        f"{shared} (difference noise {pilots.difference:.3g} at {PILOT_SPP} spp), "
        f"{backgrounds} background(s) from {components} converged "
        f"components at {cost.background_spp} spp, daylight interpolated within "
        f"{interval:g} s windows (error {pilots.interpolation.error['rms']:.3g} rms "
        f"halfway): cost {cost.cost_per_frame:.4g} vs plain {plain_spp} spp "
        f"{cost.plain_cost_per_frame:.4g} (paths per texel)"
    )
