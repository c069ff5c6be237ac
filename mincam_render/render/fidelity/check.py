"""The plan against a high-spp reference: the error it achieves, raised spp where it missed.

The reference's own Monte Carlo error is part of the figure and is taken out in
quadrature. A plan that misses its target logs a warning naming the knobs
(flags) whose part of the error exceeds it.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.render.fidelity.budget import round_up_spp, spp_for
from mincam_render.render.fidelity.constants import (
    MAX_AUTO_SPP,
    MAX_BACKGROUND_SPP,
    MAX_REFERENCE_SPP,
    MAX_SPP_RAISES,
    PILOT_SPP,
    PLAN_ERROR_SHARE,
    REFERENCE_NOISE_SHARE,
    REFERENCE_SPP_FACTOR,
)
from mincam_render.render.fidelity.probes import Probes
from mincam_render.render.fidelity.records import Achieved, Decision, ReferenceCheck, SppRaise

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.differential import BackgroundSettings

log = logging.getLogger(__name__)


@dataclass
class Draft:
    """The plan while it is decided (mutable, inside :func:`decide_fidelity` only).

    Attributes:
        shared: one render from the board centre for all detectors.
        render_cam: the camera probes are rendered with (the centre camera when shared).
        max_depth: path depth of frames (0 = the scene's integrator).
        spp: samples per texel of frames.
        e_pilot: relative error at ``PILOT_SPP`` (None unless auto).
        background: the differential background settings, or None (plain renders).
    """

    shared: bool
    render_cam: FreeformCamera
    max_depth: int = 0
    spp: int = 1
    e_pilot: float | None = None
    background: BackgroundSettings | None = None


def render_plan(p: Probes, draft: Draft, seed_offset: int = 2) -> np.ndarray:
    """The probes as the plan renders them: ``T[probe, detector, row, col]`` (W)."""
    if draft.background is None:
        return p.render(
            draft.render_cam,
            spp=draft.spp,
            seed_offset=seed_offset,
            max_depth=draft.max_depth,
            shared=draft.shared,
        )
    return np.stack([_differential_probe(p, draft, draft.background, i) for i in p.indices])


def _differential_probe(
    p: Probes, draft: Draft, background: BackgroundSettings, index: int
) -> np.ndarray:
    """``B + X - C`` of probe frame ``index`` (as a dataset would store it)."""
    from mincam_render.render.differential import render_background, render_frame

    depth = draft.max_depth or None
    bg = render_background(
        p.background,
        p.scene,
        draft.render_cam,
        index,
        background,
        dataset_seed=p.request.seed,
        spp=draft.spp,
        max_depth=depth,
    )
    t, _ = render_frame(
        p.background, p.scene, draft.render_cam, index, bg, spp=draft.spp, max_depth=depth
    )
    return np.repeat(t, p.k, axis=0) if draft.shared else t


def check_against_reference(
    p: Probes, auto: bool, decisions: dict[str, Decision], draft: Draft
) -> tuple[np.ndarray, Achieved | None]:
    """Render the plan and, when auto, measure it against a reference.

    Records the check in the spp (plain) or differential decision; a
    differential plan that misses its target has its spp raised (at most
    ``MAX_SPP_RAISES`` times), in ``draft`` and the decisions.

    Returns:
        ``(the plan's probes, the error it achieves)``: None unless auto.
    """
    chosen = render_plan(p, draft)
    if not auto:
        return chosen, None
    ref_spp, ref_depth = _reference_settings(p, draft)
    ref = p.render(
        draft.render_cam, spp=ref_spp, seed_offset=3, max_depth=ref_depth, shared=draft.shared
    )
    error = p.error(chosen, ref)
    # the reference's own Monte Carlo error is part of the figure
    ref_noise = draft.e_pilot * math.sqrt(PILOT_SPP / ref_spp) if draft.e_pilot is not None else 0.0
    check = ReferenceCheck(
        error_vs_reference=error,
        reference_spp=ref_spp,
        reference_noise_rms=ref_noise if draft.e_pilot is not None else None,
    )
    if draft.background is not None:
        chosen, check = _raise_differential_spp(p, decisions, draft, ref, ref_noise, check, chosen)
    checked = "differential" if draft.background is not None else "spp"
    decisions[checked] = decisions[checked].with_measured(**check.as_json())
    found, advice = achieved(check, ref_noise, decisions, p, draft.spp)
    return chosen, Achieved(
        error_rms=found,
        target_error=p.target_error,
        error_scale=p.scale.value,
        advice=advice,
        per_detector_error_rms=_per_detector_error(p, chosen, ref, ref_noise),
        against_reference=p.figures(chosen, ref),
        label_signal_rms=p.signal_rms(),
    )


def _reference_settings(p: Probes, draft: Draft) -> tuple[int, int]:
    """``(spp, depth)`` of the reference the plan is checked against."""
    if draft.background is None:
        return min(draft.spp * REFERENCE_SPP_FACTOR, MAX_REFERENCE_SPP), draft.max_depth
    # as many samples as keep the reference's own noise at a small share of
    # the target (it is subtracted in quadrature): 4096 spp took 70 % of
    # planning the lighting family and bought nothing the figure uses
    ref_spp = (
        MAX_REFERENCE_SPP
        if draft.e_pilot is None
        else spp_for(draft.e_pilot, REFERENCE_NOISE_SHARE * p.target_error, MAX_REFERENCE_SPP)
    )
    return ref_spp, draft.background.max_depth or 0


def _raise_differential_spp(
    p: Probes,
    decisions: dict[str, Decision],
    draft: Draft,
    ref: np.ndarray,
    ref_noise: float,
    check: ReferenceCheck,
    chosen: np.ndarray,
) -> tuple[np.ndarray, ReferenceCheck]:
    """Raise the differential spp the request left to us while the check misses the target.

    Returns:
        ``(the plan's probes, the check)``: both after the last raise.
    """
    assert draft.background is not None  # called only with differential rendering
    request, background = p.request, draft.background
    raises: list[SppRaise] = []
    own_spp = request.spp is None, request.background_spp is None
    error = check.error_vs_reference
    for _ in range(MAX_SPP_RAISES if any(own_spp) else 0):
        found = math.sqrt(max(error["rms"] ** 2 - ref_noise**2, 0.0))
        if found <= p.target_error:
            break
        factor = (found / (PLAN_ERROR_SHARE * p.target_error)) ** 2
        if own_spp[0]:
            draft.spp = round_up_spp(draft.spp * factor, MAX_AUTO_SPP)
        if own_spp[1]:
            bg_spp = round_up_spp(background.spp * factor, MAX_BACKGROUND_SPP)
            background = draft.background = replace(background, spp=bg_spp)
        raises.append(
            SppRaise(error_found_rms=found, frame_spp=draft.spp, background_spp=background.spp)
        )
        chosen = render_plan(p, draft)
        error = p.error(chosen, ref)
    if raises:
        check = replace(check, spp_raised=tuple(raises), error_vs_reference=error)
        decisions["spp"] = replace(decisions["spp"], value=draft.spp)
        diff = decisions["differential"].with_measured(
            frame_spp=draft.spp, background_spp=background.spp
        )
        decisions["differential"] = replace(
            diff,
            reason=f"{diff.reason}; raised to {draft.spp} spp (backgrounds {background.spp}) "
            "after the check against the reference missed the target",
        )
    return chosen, check


def _per_detector_error(
    p: Probes, chosen: np.ndarray, ref: np.ndarray, ref_noise: float
) -> list[float]:
    """Each detector's measurement error vs the reference (its noise out in quadrature)."""
    errors = []
    for k in range(chosen.shape[1]):
        rms = p.error(chosen[:, k : k + 1], ref[:, k : k + 1])["rms"]
        errors.append(math.sqrt(max(rms**2 - ref_noise**2, 0.0)))
    worst = int(np.argmax(errors))
    log.info("fidelity: worst detector %d: %.3g rms against the reference", worst, errors[worst])
    return errors


def achieved(
    check: ReferenceCheck, ref_noise: float, decisions: dict[str, Decision], p: Probes, spp: int
) -> tuple[float, str | None]:
    """The plan's error against the reference vs the target; a warning naming the knob if missed.

    In the planning scale (``p.scale``). The reference's own Monte Carlo error
    is taken out in quadrature. The advice names every knob whose part of the
    error exceeds the target (else the largest): the measured biases of sharing
    and (in the same scale) path depth, and the Monte Carlo rest with the spp
    that brings it to the target.

    Returns:
        ``(error, advice)``: the error (reference noise out), and the flags to
        pass when it misses the target (else None).
    """
    found = math.sqrt(max(check.error_vs_reference["rms"] ** 2 - ref_noise**2, 0.0))
    target, request = p.target_error, p.request
    if found <= target:
        return found, None
    knobs = _knobs_to_turn(found, decisions, target, spp, depth_in_scale=p.scale is p.total_scale)
    advice = "pass " + " and ".join(f"{k} (now {v:.3g} rms of it)" for k, v in knobs)
    if request.spp is not None and any(k.startswith("--spp") for k, _ in knobs):
        advice += "; or drop --spp to let auto fidelity choose"
    log.warning(
        "fidelity: measurements are %.3g rms off the reference, target %g (%s-relative): %s",
        found,
        target,
        p.scale.value,
        advice,
    )
    return found, advice


def _knobs_to_turn(
    found: float, decisions: dict[str, Decision], target: float, spp: int, *, depth_in_scale: bool
) -> list[tuple[str, float]]:
    """``[(flag, its part of the error)]``: those above the target, else the largest.

    Sharing's part is its measured change less, in quadrature, the noise of two
    seeds it was measured with (the change of two renders holds both: only the
    rest is a bias). The path depth's change is measured relative to the total;
    it is a part of the error only when the target is too (``depth_in_scale``).
    """
    shared = decisions["shared_render"]
    parts = {}
    if shared.value and "error_shared_vs_per_detector" in shared.measured:
        change = shared.measured["error_shared_vs_per_detector"]["rms"]
        floor = shared.measured["noise_floor_two_seeds"]["rms"]
        parts["--per-detector"] = math.sqrt(max(change**2 - floor**2, 0.0))
    depth = decisions["max_depth"]
    changes = depth.measured.get("change_vs_reference", {})
    kept = changes.get(str(depth.measured.get("plain_value", depth.value)))
    if kept is not None and depth_in_scale:
        parts[f"--max-depth {int(depth.value) + 1}"] = kept["rms"]
    noise = math.sqrt(max(found**2 - sum(b * b for b in parts.values()), 0.0))
    parts[f"--spp {round_up_spp(spp * (noise / target) ** 2, 1 << 24)}"] = noise
    ranked = sorted(parts.items(), key=lambda kv: -kv[1])
    return [kv for kv in ranked if kv[1] > target] or ranked[:1]
