"""One decision per render knob, each from a measured error: sharing, path depth, spp, dtype.

Every decision is a :class:`~.records.Decision` (JSON ``{"value", "source",
"reason", **measured}``): ``source`` is ``flag`` (set by the request), ``full``
(full fidelity: no shortcut) or ``auto`` (measured on the probe frames), and the
measured figures are the errors the choice was made from.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.strict_json import JsonObject
from mincam_render.render.capabilities import history_frames
from mincam_render.render.fidelity.budget import spp_for
from mincam_render.render.fidelity.constants import (
    CANDIDATE_DEPTHS,
    DEEP_REFERENCE_DEPTH,
    FULL_SPP,
    MAX_AUTO_SPP,
    PILOT_SPP,
    SHARED_ERROR_SHARE,
)
from mincam_render.render.fidelity.probes import Probes
from mincam_render.render.fidelity.records import Decision, Parallax, SharingChange, Source
from mincam_render.render.precision import (
    StorageDtype,
    decode_transport,
    encode_transport,
)

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera


def decide_shared_render(p: Probes, auto: bool) -> Decision:
    """One render at the board centre for all detectors, or one per detector."""
    request = p.request
    parallax = _parallax(p)
    measured = parallax.as_json()
    change = None
    if p.k > 1 and request.shared_render is None and auto:
        change = _sharing_change(p)
        measured.update(change.as_json())
    if request.shared_render is not None:
        value, source = bool(request.shared_render), Source.FLAG
        reason = "set by --shared-render/--per-detector"
    elif not auto:
        value, source, reason = False, Source.FULL, "full fidelity renders every detector"
    elif p.k == 1:
        value, source, reason = False, Source.AUTO, "one detector: nothing to share"
    else:
        assert change is not None  # measured above for auto with several detectors
        value, reason = shared_render_choice(
            parallax.parallax_texels, request.parallax_fraction, change
        )
        depth = parallax.depth_range
        reason = f"{reason} (depths {depth.min_m:.3g}-{depth.max_m:.3g} m)"
        source = Source.AUTO
    return Decision(value=value, source=source, reason=reason, measured=measured)


def _parallax(p: Probes) -> Parallax:
    """The largest parallax on the mask plane (texels) from the nearest depth seen."""
    camera = p.camera
    rows, cols = camera.mask_resolution
    baseline = float(np.linalg.norm(np.asarray(camera.layout.positions_m), axis=1).max())
    texel_m = camera.mask_size_m / max(rows, cols)
    depth = p.depth_range_m()
    z_min = depth.min_m
    parallax = (
        0.0 if not math.isfinite(z_min) else baseline * camera.mask_distance_m / z_min / texel_m
    )
    return Parallax(
        parallax_texels=parallax,
        depth_range=depth,
        largest_detector_offset_m=baseline,
        bound_texels=p.request.parallax_fraction,
    )


def _sharing_change(p: Probes) -> SharingChange:
    """How much sharing changes measurements, against the noise of two seeds."""
    # common random numbers: the same samples with every detector moved to the
    # board centre, so the difference is the parallax alone, not noise
    per_det = p.render(p.camera, spp=PILOT_SPP)
    no_parallax = p.render(p.camera, spp=PILOT_SPP, parallax=False)
    other = p.render(p.camera, spp=PILOT_SPP, seed_offset=1)
    return SharingChange(
        error_shared_vs_per_detector=p.error(no_parallax, per_det),
        noise_floor_two_seeds=p.error(other, per_det),
        probe_spp=PILOT_SPP,
        error_bound=SHARED_ERROR_SHARE * p.target_error,
    )


def shared_render_choice(
    parallax: float, fraction: float, measured: SharingChange
) -> tuple[bool, str]:
    """Share one centre render? ``(choice, reason)`` from the measured change it makes.

    The change (common random numbers, so the parallax alone plus the noise of
    rays that land elsewhere) decides; only where it is within the noise of two
    independent renders does the geometric parallax estimate decide instead.
    """
    err = measured.error_shared_vs_per_detector["rms"]
    noise = measured.noise_floor_two_seeds["rms"]
    bound = measured.error_bound
    geometry = (
        f"parallax {parallax:.3g} texel ({'<' if parallax < fraction else '>='} {fraction:g})"
    )
    change = f"sharing changes measurements by {err:.3g} rms"
    if err < bound:
        return True, f"{change} < bound {bound:.3g} (a share of the target error); {geometry}"
    if parallax < fraction and err <= noise:
        return True, (
            f"{geometry}; {change} >= bound {bound:.3g} but within the noise of two seeds "
            f"({noise:.3g} rms at {measured.probe_spp} spp), so the geometry decides"
        )
    return False, f"{change} >= bound {bound:.3g} (a share of the target error); {geometry}"


def decide_max_depth(p: Probes, auto: bool, render_cam: FreeformCamera, shared: bool) -> Decision:
    """The shallowest path depth whose missing bounces change measurements < the bound.

    Relative to the total (``p.total_scale``): the bounces left out are light of
    the whole room, scaling with its lamps and daylight, not of the labels.
    """
    from mincam_render.render.transport import scene_max_depth

    request = p.request
    scene_depth = scene_max_depth(p.scene)
    measured: JsonObject = {
        "scene_integrator_max_depth": scene_depth,
        "bound": request.indirect_fraction,
    }
    if request.max_depth is not None:
        reason = "set by --max-depth"
        return Decision(
            value=request.max_depth, source=Source.FLAG, reason=reason, measured=measured
        )
    if not auto:
        reason = "full fidelity uses the scene's integrator"
        return Decision(value=0, source=Source.FULL, reason=reason, measured=measured)
    if scene_depth is not None and 1 <= scene_depth <= 2:
        reason = f"the scene's integrator is already direct-only (max_depth = {scene_depth})"
        measured["indirect_change"] = {"rms": 0.0, "max": 0.0}
        return Decision(value=0, source=Source.AUTO, reason=reason, measured=measured)
    max_depth, changes = _depth_changes(p, render_cam, shared, scene_depth)
    measured.update(
        {
            "change_vs_reference": {str(d): c for d, c in sorted(changes.items())},
            "indirect_change": changes[2],
            "reference_depth": DEEP_REFERENCE_DEPTH,
        }
    )
    kept = changes.get(max_depth, {"rms": 0.0})["rms"]
    reason = (
        f"depth {max_depth} changes measurements by {kept:.3g} (rms) vs depth "
        f"{DEEP_REFERENCE_DEPTH}, < bound {request.indirect_fraction:g}; direct light "
        f"only (depth 2) would change them by {changes[2]['rms']:.3g}"
    )
    if scene_depth is not None and scene_depth in changes:
        reason += f", the scene's own depth {scene_depth} by {changes[scene_depth]['rms']:.3g}"
    return Decision(value=max_depth, source=Source.AUTO, reason=reason, measured=measured)


def _depth_changes(
    p: Probes, render_cam: FreeformCamera, shared: bool, scene_depth: int | None
) -> tuple[int, dict[int, dict[str, float]]]:
    """``(chosen depth, {depth: change vs a deep reference})`` with common random numbers.

    Same seeds: paths agree up to the truncation, so each difference is the light
    of the bounces left out, not noise. The scene's own depth is an author's
    default, not the truth: it is measured like any other candidate.
    """
    bound = p.request.indirect_fraction
    deep = p.render(render_cam, spp=PILOT_SPP, max_depth=DEEP_REFERENCE_DEPTH, shared=shared)
    changes: dict[int, dict[str, float]] = {}
    max_depth = DEEP_REFERENCE_DEPTH
    for depth in CANDIDATE_DEPTHS:
        trial = p.render(render_cam, spp=PILOT_SPP, max_depth=depth, shared=shared)
        changes[depth] = p.error(trial, deep, p.total_scale)
        if changes[depth]["rms"] < bound:
            max_depth = depth
            break
    if scene_depth is not None and scene_depth > 0 and scene_depth not in changes:
        trial = p.render(render_cam, spp=PILOT_SPP, max_depth=scene_depth, shared=shared)
        changes[scene_depth] = p.error(trial, deep, p.total_scale)
    return max_depth, changes


def decide_spp(
    p: Probes, auto: bool, render_cam: FreeformCamera, max_depth: int, shared: bool
) -> tuple[Decision, float | None]:
    """Samples per texel for the target error (plain estimator); also the pilot error.

    Returns:
        ``(decision, pilot error)``: the pilot's relative error at ``PILOT_SPP``
        (None unless auto), from two renders with different seeds.
    """
    request = p.request
    target = p.target_error
    measured: JsonObject = {"target_error": target, "error_scale": p.scale.value}
    e_pilot = None
    if auto:
        a = p.render(render_cam, spp=PILOT_SPP, max_depth=max_depth, shared=shared)
        b = p.render(render_cam, spp=PILOT_SPP, seed_offset=1, max_depth=max_depth, shared=shared)
        # the difference of two independent renders has twice the variance of one
        e_pilot = p.error(a, b)["rms"] / math.sqrt(2.0)
        measured.update({"pilot_spp": PILOT_SPP, "pilot_error_rms": e_pilot})
    if request.spp is not None:
        value, source, reason = request.spp, Source.FLAG, "set by --spp"
    elif e_pilot is None:  # not auto
        value, source, reason = FULL_SPP, Source.FULL, f"full fidelity default {FULL_SPP} spp"
    else:
        spp = spp_for(e_pilot, target, MAX_AUTO_SPP)
        predicted = measured["predicted_error_rms"] = e_pilot * math.sqrt(PILOT_SPP / spp)
        verdict = (
            f"{spp} spp meets target {target:g}"
            if predicted <= target
            else f"capped at {spp} spp: predicted {predicted:.3g} > target {target:g}"
        )
        reason = (
            f"Monte Carlo error {e_pilot:.3g} at {PILOT_SPP} spp scales as 1/sqrt(spp); {verdict}"
        )
        value, source = spp, Source.AUTO
    return Decision(value=value, source=source, reason=reason, measured=measured), e_pilot


def decide_dtype(p: Probes, auto: bool, chosen: np.ndarray) -> Decision:
    """float16 storage when the error it adds to ``chosen``'s measurements stays < the bound.

    The bound is relative to the total (``p.total_scale``), like float16's own
    precision; the error relative to the label signal is recorded beside it.
    """
    request = p.request
    stored, scales = encode_transport(chosen, StorageDtype.FLOAT16)
    decoded = decode_transport(stored, scales)
    f16_err = p.error(decoded, chosen, p.total_scale)
    measured = {
        "float16_error": f16_err,
        "float16_error_signal_relative": p.signal_figure(decoded, chosen),
        "bound": request.dtype_error_bound,
    }
    if request.dtype is not None:
        dtype, source, reason = request.dtype, Source.FLAG, "set by --dtype"
    elif not auto:
        dtype, source, reason = StorageDtype.FLOAT32, Source.FULL, "full fidelity stores float32"
    else:
        small = f16_err["max"] < request.dtype_error_bound
        dtype = StorageDtype.FLOAT16 if small else StorageDtype.FLOAT32
        source = Source.AUTO
        reason = (
            f"float16 changes measurements by at most {f16_err['max']:.3g} "
            f"{'<' if small else '>='} bound {request.dtype_error_bound:g}"
        )
    return Decision(value=dtype.value, source=source, reason=reason, measured=measured)


def recorded_decisions(p: Probes) -> dict[str, Decision]:
    """Choices with nothing to measure: mask resolution, variant, temporal history."""
    from mincam_render.render import backend

    history = history_frames(p.family) > 1
    return {
        "mask_resolution": Decision(
            value=p.camera.mask_resolution[0],
            source=Source.FLAG if p.request.mask_res is not None else Source.CAMERA,
            reason="a coarser transport image is exact for masks of that resolution (block "
            "sums), so resolution is a mask design choice, not reduced automatically",
        ),
        "variant": Decision(
            value=backend.describe()["variant"],
            source=Source.AUTO,
            reason="photodiodes are single-channel: monochrome variant",
        ),
        "temporal_history": Decision(
            value=history,
            source=Source.AUTO,
            reason="the family's task needs a time history"
            if history
            else "static task: frames are used without history",
        ),
    }
