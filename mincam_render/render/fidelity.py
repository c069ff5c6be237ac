"""Leaving out what a scene does not need, each choice decided from a measured error.

:func:`decide_fidelity` renders a few probe frames of a family (spread over the
sequence, at fixed seeds) and decides:

- **shared render**: one render at the board centre replicated to all detectors,
  when the largest parallax between a detector and the board centre,
  ``|b| d / z_min`` on the mask plane, stays below ``parallax_fraction`` of a
  texel (``b`` the detector offset, ``d`` the mask distance, ``z_min`` the
  nearest scene depth from a grid of rays cast from the board centre), or when
  the parallax changes measurements by less than ``SHARED_ERROR_SHARE`` of the
  target error (measured with common random numbers: the same samples with every
  detector moved to the board centre, so noise cancels);
- **bounce depth**: the shallowest of ``CANDIDATE_DEPTHS`` (2 = direct light
  only) whose measurements differ from a depth-``DEEP_REFERENCE_DEPTH`` render
  by less than ``indirect_fraction``; probes use common random numbers, so the
  difference is the light of the bounces left out, not noise. The scene's own
  integrator depth is measured and recorded too, not trusted;
- **samples per texel** from the target measurement error: the Monte Carlo
  error of measurements, estimated from two renders with different seeds at a
  pilot sample count, falls as ``1/sqrt(spp)``; the choice is then checked
  against a reference at 8x the samples;
- **differential rendering** (families with a static background, see
  :mod:`mincam_render.render.differential`) when its cost per frame, counted in paths
  traced with the backgrounds amortized, is lower than the plain
  render's. Its settings come from an error budget of ``PLAN_ERROR_SHARE`` of
  the target: the biases are measured first (sharing ``X - C`` from the board
  centre, interpolating the daylight within a window), and the noises of
  ``X - C`` and of the backgrounds share what is left in the cheapest split
  (:func:`_split_noise_budget`); ``X - C`` is traced as deep as the
  backgrounds; the choice is checked against a plain reference whose predicted
  noise is ``REFERENCE_NOISE_SHARE`` of the target (subtracted in quadrature);
- **storage float16** when the relative measurement error it adds (per-frame
  power-of-two scaling, see :mod:`mincam_render.render.precision`) stays below
  ``dtype_error_bound`` for random printable masks, else float32;
- **mask resolution**: kept at the camera's. A transport image at a coarser
  resolution gives *exact* measurements for masks of that resolution (its
  texels are sums of the finer ones), so resolution is a design choice of the
  mask (swept in training), not an accuracy knob of the render;
- **monochrome variant** (photodiodes are single-channel) and **no temporal
  history** unless the family ``needs_history``: recorded, nothing to measure.

Errors are relative errors of measurements ``P = sum T M`` for random printable
masks (:func:`mincam_render.render.precision.measurement_relative_error`), RMS and max
over probe frames, detectors and masks. Every decision records its value, its
source (``flag``, ``auto`` or ``full``), the bound and the measured figures.
"""

from __future__ import annotations

import enum
import logging
import math
from typing import Any

import numpy as np

from mincam_render.core.seeds import frame_seed
from mincam_render.render.precision import (
    decode_transport,
    encode_transport,
    measurement_relative_error,
)

log = logging.getLogger(__name__)


class Fidelity(enum.Enum):
    """How render settings not given explicitly are chosen."""

    AUTO = "auto"  # measured from scene and camera (mincam_render.render.fidelity)
    FULL = "full"  # no shortcuts: per-detector renders, scene integrator, float32


#: Probe frames rendered for the measurements.
PROBE_FRAMES = 3
#: Samples per texel of the pilot renders.
PILOT_SPP = 4
#: spp chosen automatically stays in [1, MAX_AUTO_SPP].
MAX_AUTO_SPP = 1024
#: Reference renders for the spp check use this many times the chosen spp.
REFERENCE_SPP_FACTOR = 8
#: Cap on the reference's spp (keeps planning a noisy scene to minutes).
MAX_REFERENCE_SPP = 4096
#: The reference of a differential plan gets the spp whose predicted noise is this
#: share of the target error (its noise is subtracted in quadrature from the check).
REFERENCE_NOISE_SHARE = 0.2
#: Path depths tried, shallowest first, against the deep reference.
CANDIDATE_DEPTHS = (2, 3, 4, 6, 8, 12)
#: Path depth of the reference when the scene's integrator is unbounded (-1).
DEEP_REFERENCE_DEPTH = 16
#: A shared render is chosen when parallax changes measurements by less than this
#: share of the target error (or by less than ``parallax_fraction`` texels).
SHARED_ERROR_SHARE = 0.5
#: spp of FULL fidelity when --spp is not given.
FULL_SPP = 64
#: Rays per side of the grid cast to estimate scene depth.
DEPTH_GRID = 16
#: Cap on the background's spp.
MAX_BACKGROUND_SPP = 16384
#: spp of the two renders whose difference gives the noise of ``X - C``: more than
#: PILOT_SPP, because the rare paths that find the sunlit floor make its noise
#: heavy-tailed and a small pilot underestimates it.
DIFFERENCE_PILOT_SPP = 16
#: Times the differential spp are raised when the check against the reference
#: misses the target (each by the squared ratio of the error found to the planned).
MAX_SPP_RAISES = 2
#: spp of the two renders of each probe's background whose difference gives the
#: backgrounds' noise (see _background_noise).
BACKGROUND_PILOT_SPP = 64
#: spp of the frame render that relative errors of ``X - C`` are taken against.
DIFFERENCE_BASE_SPP = 32
#: Differential settings are planned for this share of the target error; the rest
#: covers the uncertainty of figures measured on a few probe frames.
PLAN_ERROR_SHARE = 0.9
#: spp of the renders that measure the parallax error of one ``X - C`` for all
#: detectors (a difference of noise levels: it needs noise well below the bound).
SHARED_DIFFERENCE_SPP = 128
#: spp cap of the renders that measure the daylight interpolation of backgrounds
#: (common random numbers: the drift's change, not noise, dominates).
INTERPOLATION_SPP = 256


def _probe_indices(num_frames: int) -> list[int]:
    n = min(PROBE_FRAMES, num_frames)
    return sorted({int(round(x)) for x in np.linspace(0, num_frames - 1, n)})


def nearest_depth_m(scene, camera) -> dict[str, float]:
    """Nearest and farthest scene depth (m, along the board normal) seen from the board centre.

    Casts a ``DEPTH_GRID^2`` grid of rays from the board centre through the mask's
    field of view. Misses count as infinitely far.
    """
    import mitsuba as mi

    right, up, fwd = camera.frame
    n = DEPTH_GRID
    s = ((np.arange(n) + 0.5) / n - 0.5) * camera.mask_size_m
    ss, tt = np.meshgrid(s, -s)
    dirs = ss.reshape(-1, 1) * right + tt.reshape(-1, 1) * up + camera.mask_distance_m * fwd
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origin = np.broadcast_to(np.asarray(camera.position), dirs.shape)
    ray = mi.Ray3f(
        mi.Point3f(*[mi.Float(origin[:, i]) for i in range(3)]),
        mi.Vector3f(*[mi.Float(dirs[:, i]) for i in range(3)]),
    )
    si = scene.ray_intersect(ray)
    t = np.asarray(si.t.numpy(), dtype=np.float64)
    valid = np.isfinite(t) & (t < 1e30)
    depth = t[valid] * (dirs[valid] @ fwd)
    if depth.size == 0:
        return {"min": math.inf, "max": math.inf}
    return {"min": float(depth.min()), "max": float(depth.max())}


def decide_fidelity(
    family, camera, request, *, progress: bool = False
) -> tuple[dict[str, Any], dict[str, dict]]:
    """Choose render settings for ``family`` seen by ``camera`` (see the module doc).

    Args:
        family: a :class:`~mincam_render.scenes.base.SceneFamily`.
        camera: the camera to render (mask resolution already final).
        request: a :class:`~mincam_render.data.render_job.RenderRequest`; its explicit
            settings win, its bounds drive the automatic choices.
        progress: show a progress bar naming what is being measured (stderr).

    Returns:
        ``(settings, decisions)``: settings ``{"spp", "max_depth" (0 = scene
        integrator), "shared_render", "mask_resolution", "dtype"}`` and per
        setting a decision record ``{"value", "source", "reason", ...measured}``.
    """
    from mincam_render.render import backend
    from mincam_render.render.transport import scene_max_depth

    auto = request.fidelity is Fidelity.AUTO
    scene = family.build_scene()
    probes = _probe_indices(family.num_frames)
    k = camera.num_detectors
    rows, cols = camera.mask_resolution
    lo_hi = camera.transmittance_range
    decisions: dict[str, dict] = {}
    stages = _Stages(_PLAN_STAGES, enabled=progress)

    def render(cam, *, spp, seed_offset=0, max_depth=None, shared=False, parallax=True):
        out = []
        for i in probes:
            family.set_frame(scene, i)
            seed = (frame_seed(request.seed, i) + 7919 * seed_offset) % 2**63
            t = family.render_transport(
                scene, cam, spp=spp, seed=seed, max_depth=max_depth or None, parallax=parallax
            )
            out.append(np.repeat(t, k, axis=0) if shared else t)
        return np.stack(out)

    centre_cam = camera.centre_camera()

    # ---- shared render ------------------------------------------------------------------
    stages.start("parallax: one shared render vs one per detector")
    offsets = np.asarray(camera.layout.positions_m)
    baseline = float(np.linalg.norm(offsets, axis=1).max())
    texel_m = camera.mask_size_m / max(rows, cols)
    depths = []
    for i in probes:
        family.set_frame(scene, i)
        depths.append(nearest_depth_m(scene, camera))
    z_min = min(d["min"] for d in depths)
    z_max = max(d["max"] for d in depths)
    parallax = (
        0.0 if not math.isfinite(z_min) else baseline * camera.mask_distance_m / z_min / texel_m
    )
    measured: dict[str, Any] = {
        "parallax_texels": parallax,
        "depth_range_m": [z_min, z_max],
        "largest_detector_offset_m": baseline,
        "bound_texels": request.parallax_fraction,
    }
    if k > 1 and request.shared_render is None and auto:
        # common random numbers: the same samples with every detector moved to the
        # board centre, so the difference is the parallax alone, not noise
        per_det = render(camera, spp=PILOT_SPP)
        no_parallax = render(camera, spp=PILOT_SPP, parallax=False)
        other = render(camera, spp=PILOT_SPP, seed_offset=1)
        measured["error_shared_vs_per_detector"] = measurement_relative_error(
            no_parallax, per_det, lo_hi
        )
        measured["noise_floor_two_seeds"] = measurement_relative_error(other, per_det, lo_hi)
        measured["probe_spp"] = PILOT_SPP
        measured["error_bound"] = SHARED_ERROR_SHARE * request.target_error
    if request.shared_render is not None:
        shared, source = bool(request.shared_render), "flag"
        reason = "set by --shared-render/--per-detector"
    elif not auto:
        shared, source, reason = False, "full", "full fidelity renders every detector"
    elif k == 1:
        shared, source, reason = False, "auto", "one detector: nothing to share"
    else:
        shared, reason = _shared_render_choice(parallax, request.parallax_fraction, measured)
        source = "auto"
        reason = f"{reason} (depths {z_min:.3g}-{z_max:.3g} m)"
    decisions["shared_render"] = {"value": shared, "source": source, "reason": reason, **measured}
    render_cam = centre_cam if shared else camera

    # ---- direct light only ---------------------------------------------------------------
    stages.start("path depth vs a deep reference")
    scene_depth = scene_max_depth(scene)
    measured = {"scene_integrator_max_depth": scene_depth, "bound": request.indirect_fraction}
    if request.max_depth is not None:
        max_depth, source, reason = request.max_depth, "flag", "set by --max-depth"
    elif not auto:
        max_depth, source, reason = 0, "full", "full fidelity uses the scene's integrator"
    elif scene_depth is not None and 1 <= scene_depth <= 2:
        max_depth, source = 0, "auto"
        reason = f"the scene's integrator is already direct-only (max_depth = {scene_depth})"
        measured["indirect_change"] = {"rms": 0.0, "max": 0.0}
    else:
        # same seeds (common random numbers): paths agree up to the truncation, so
        # each difference is the light of the bounces left out, not noise. The
        # scene's own depth is an author's default, not the truth: it is measured
        # like any other candidate.
        deep = render(render_cam, spp=PILOT_SPP, max_depth=DEEP_REFERENCE_DEPTH, shared=shared)
        changes = {}
        max_depth = DEEP_REFERENCE_DEPTH
        for depth in CANDIDATE_DEPTHS:
            trial = render(render_cam, spp=PILOT_SPP, max_depth=depth, shared=shared)
            changes[depth] = measurement_relative_error(trial, deep, lo_hi)
            if changes[depth]["rms"] < request.indirect_fraction:
                max_depth = depth
                break
        if scene_depth is not None and scene_depth > 0 and scene_depth not in changes:
            trial = render(render_cam, spp=PILOT_SPP, max_depth=scene_depth, shared=shared)
            changes[scene_depth] = measurement_relative_error(trial, deep, lo_hi)
        measured.update(
            {
                "change_vs_reference": {str(d): c for d, c in sorted(changes.items())},
                "indirect_change": changes[2],
                "reference_depth": DEEP_REFERENCE_DEPTH,
            }
        )
        source = "auto"
        kept = changes.get(max_depth, {"rms": 0.0})["rms"]
        reason = (
            f"depth {max_depth} changes measurements by {kept:.3g} (rms) vs depth "
            f"{DEEP_REFERENCE_DEPTH}, < bound {request.indirect_fraction:g}; direct light "
            f"only (depth 2) would change them by {changes[2]['rms']:.3g}"
        )
        if scene_depth is not None and scene_depth in changes:
            reason += f", the scene's own depth {scene_depth} by {changes[scene_depth]['rms']:.3g}"
    decisions["max_depth"] = {"value": max_depth, "source": source, "reason": reason, **measured}

    # ---- samples per texel (plain estimator) ------------------------------------------
    stages.start("Monte Carlo error at the pilot spp")
    measured = {"target_error": request.target_error}
    e_pilot = None
    if request.spp is not None:
        spp, source, reason = request.spp, "flag", "set by --spp"
    elif not auto:
        spp, source, reason = FULL_SPP, "full", f"full fidelity default {FULL_SPP} spp"
    else:
        source = "auto"
    if auto:
        a = render(render_cam, spp=PILOT_SPP, max_depth=max_depth, shared=shared)
        b = render(render_cam, spp=PILOT_SPP, seed_offset=1, max_depth=max_depth, shared=shared)
        # the difference of two independent renders has twice the variance of one
        e_pilot = measurement_relative_error(a, b, lo_hi)["rms"] / math.sqrt(2.0)
        measured.update(
            {
                "pilot_spp": PILOT_SPP,
                "pilot_error_rms": e_pilot,
            }
        )
    if source == "auto":
        spp = _spp_for(e_pilot, request.target_error, MAX_AUTO_SPP)
        measured["predicted_error_rms"] = e_pilot * math.sqrt(PILOT_SPP / spp)
        predicted = measured["predicted_error_rms"]
        verdict = (
            f"{spp} spp meets target {request.target_error:g}"
            if predicted <= request.target_error
            else f"capped at {spp} spp: predicted {predicted:.3g} > target {request.target_error:g}"
        )
        reason = (
            f"Monte Carlo error {e_pilot:.3g} at {PILOT_SPP} spp scales as 1/sqrt(spp); {verdict}"
        )
    decisions["spp"] = {"value": spp, "source": source, "reason": reason, **measured}

    # ---- differential rendering ----------------------------------------------------------
    stages.start("differential rendering: background and difference")
    background = None
    diff = _decide_differential(
        family,
        scene,
        request,
        render_cam,
        probes,
        lo_hi,
        max_depth,
        spp,
    )
    decisions["differential"] = diff
    if diff["value"]:
        background = {
            "interval_s": request.background_interval_s,
            "spp": diff["background_spp"],
            "max_depth": max_depth,
            "shared_difference": diff.get("shared_difference", {}).get("value", False),
        }
        for name, value, in_background in (
            ("spp", diff["frame_spp"], diff["background_spp"]),
            ("max_depth", diff["frame_max_depth"], max_depth),
        ):
            decisions[name]["plain_value"] = decisions[name]["value"]
            decisions[name]["value"] = value
            decisions[name]["reason"] += (
                f"; differential rendering renders frames with {name} {value} and backgrounds "
                f"with {in_background} (see 'differential')"
            )
        spp, max_depth = diff["frame_spp"], diff["frame_max_depth"]

    # ---- check against a reference -------------------------------------------------------
    stages.start("the plan against a high-spp reference")

    def differential_probes():
        return np.stack(
            [
                _differential_probe(
                    family, scene, render_cam, i, request, background, spp, max_depth, shared, k
                )
                for i in probes
            ]
        )

    if background is not None:
        chosen = differential_probes()
        # as many samples as keep the reference's own noise at a small share of
        # the target (it is subtracted in quadrature below): 4096 spp took 70 %
        # of planning the lighting family and bought nothing the figure uses
        ref_spp = (
            MAX_REFERENCE_SPP
            if e_pilot is None
            else _spp_for(e_pilot, REFERENCE_NOISE_SHARE * request.target_error, MAX_REFERENCE_SPP)
        )
        ref_depth = background["max_depth"]
    else:
        chosen = render(render_cam, spp=spp, seed_offset=2, max_depth=max_depth, shared=shared)
        ref_spp = min(spp * REFERENCE_SPP_FACTOR, MAX_REFERENCE_SPP)
        ref_depth = max_depth
    if auto:
        ref = render(render_cam, spp=ref_spp, seed_offset=3, max_depth=ref_depth, shared=shared)
        error = measurement_relative_error(chosen, ref, lo_hi)
        # the reference's own Monte Carlo error is part of the figure
        ref_noise = e_pilot * math.sqrt(PILOT_SPP / ref_spp) if e_pilot is not None else 0.0
        check = {"error_vs_reference": error, "reference_spp": ref_spp}
        if e_pilot is not None:
            check["reference_noise_rms"] = ref_noise
        if background is not None:
            raises = []
            own_spp = request.spp is None, request.background_spp is None
            for _ in range(MAX_SPP_RAISES if any(own_spp) else 0):
                found = math.sqrt(max(error["rms"] ** 2 - ref_noise**2, 0.0))
                if found <= request.target_error:
                    break
                factor = (found / (PLAN_ERROR_SHARE * request.target_error)) ** 2
                if own_spp[0]:
                    spp = _round_up_spp(spp * factor, MAX_AUTO_SPP)
                if own_spp[1]:
                    background["spp"] = _round_up_spp(
                        background["spp"] * factor, MAX_BACKGROUND_SPP
                    )
                raises.append(
                    {
                        "error_found_rms": found,
                        "frame_spp": spp,
                        "background_spp": background["spp"],
                    }
                )
                chosen = differential_probes()
                error = measurement_relative_error(chosen, ref, lo_hi)
            if raises:
                check["spp_raised"] = raises
                check["error_vs_reference"] = error
                diff["frame_spp"] = decisions["spp"]["value"] = spp
                diff["background_spp"] = background["spp"]
                diff["reason"] += (
                    f"; raised to {spp} spp (backgrounds {background['spp']}) after the check "
                    "against the reference missed the target"
                )
        (diff if background is not None else decisions["spp"]).update(check)
        decisions["achieved"] = _achieved(check, ref_noise, decisions, request, spp)
        decisions["achieved"]["per_detector_error_rms"] = _per_detector_error(
            chosen, ref, lo_hi, ref_noise
        )

    # ---- storage type ------------------------------------------------------------------
    stages.start("float16 storage error")
    stored, scales = encode_transport(chosen, "float16")
    f16_err = measurement_relative_error(decode_transport(stored, scales), chosen, lo_hi)
    measured = {"float16_error": f16_err, "bound": request.dtype_error_bound}
    if request.dtype is not None:
        dtype, source, reason = request.dtype, "flag", "set by --dtype"
    elif not auto:
        dtype, source, reason = "float32", "full", "full fidelity stores float32"
    else:
        dtype = "float16" if f16_err["max"] < request.dtype_error_bound else "float32"
        source = "auto"
        reason = (
            f"float16 changes measurements by at most {f16_err['max']:.3g} "
            f"{'<' if dtype == 'float16' else '>='} bound {request.dtype_error_bound:g}"
        )
    decisions["dtype"] = {"value": dtype, "source": source, "reason": reason, **measured}

    # ---- recorded, nothing to measure --------------------------------------------------
    decisions["mask_resolution"] = {
        "value": rows,
        "source": "flag" if request.mask_res is not None else "camera",
        "reason": "a coarser transport image is exact for masks of that resolution (block "
        "sums), so resolution is a mask design choice, not reduced automatically",
    }
    decisions["variant"] = {
        "value": backend.describe()["variant"],
        "source": "auto",
        "reason": "photodiodes are single-channel: monochrome variant",
    }
    decisions["temporal_history"] = {
        "value": bool(family.needs_history),
        "source": "auto",
        "reason": "the family's task needs a time history"
        if family.needs_history
        else "static task: frames are used without history",
    }
    decisions["probe_frames"] = probes
    settings = {
        "spp": spp,
        "max_depth": max_depth,
        "shared_render": shared,
        "mask_resolution": rows,
        "dtype": dtype,
        "background": background,
    }
    stages.close()
    log.info("fidelity: %s", {k_: v["value"] for k_, v in decisions.items() if "value" in v})
    return settings, decisions


#: Measurements of a plan (the progress bar's steps): sharing, depth, spp, differential,
#: the check against a reference, storage.
_PLAN_STAGES = 6


class _Stages:
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


def _per_detector_error(chosen, ref, lo_hi, ref_noise: float) -> list[float]:
    """Each detector's measurement error vs the reference (its noise out in quadrature)."""
    errors = []
    for k in range(chosen.shape[1]):
        rms = measurement_relative_error(chosen[:, k : k + 1], ref[:, k : k + 1], lo_hi)["rms"]
        errors.append(math.sqrt(max(rms**2 - ref_noise**2, 0.0)))
    worst = int(np.argmax(errors))
    log.info("fidelity: worst detector %d: %.3g rms against the reference", worst, errors[worst])
    return errors


def _achieved(check, ref_noise, decisions, request, spp) -> dict[str, Any]:
    """The plan's error against the reference vs the target; a warning naming the knob if missed.

    The reference's own Monte Carlo error is taken out in quadrature. The
    advice names every knob whose part of the error exceeds the target (else
    the largest): the measured biases of sharing and path depth, and the
    Monte Carlo rest with the spp that brings it to the target.
    """
    found = math.sqrt(max(check["error_vs_reference"]["rms"] ** 2 - ref_noise**2, 0.0))
    record = {"error_rms": found, "target_error": request.target_error}
    record["met"] = found <= request.target_error
    if record["met"]:
        return record
    shared = decisions["shared_render"]
    parts = {}
    if shared["value"] and "error_shared_vs_per_detector" in shared:
        parts["--per-detector"] = shared["error_shared_vs_per_detector"]["rms"]
    depth = decisions["max_depth"]
    kept = depth.get("change_vs_reference", {}).get(str(depth.get("plain_value", depth["value"])))
    if kept is not None:
        parts[f"--max-depth {int(depth['value']) + 1}"] = kept["rms"]
    noise = math.sqrt(max(found**2 - sum(b * b for b in parts.values()), 0.0))
    parts[f"--spp {_round_up_spp(spp * (noise / request.target_error) ** 2, 1 << 24)}"] = noise
    ranked = sorted(parts.items(), key=lambda kv: -kv[1])
    knobs = [kv for kv in ranked if kv[1] > request.target_error] or ranked[:1]
    record["advice"] = "pass " + " and ".join(f"{k} (now {v:.3g} rms of it)" for k, v in knobs)
    if request.spp is not None and any(k.startswith("--spp") for k, _ in knobs):
        record["advice"] += "; or drop --spp to let auto fidelity choose"
    log.warning(
        "fidelity: measurements are %.3g rms off the reference, target %g: %s",
        found,
        request.target_error,
        record["advice"],
    )
    return record


def _shared_render_choice(parallax: float, fraction: float, measured: dict) -> tuple[bool, str]:
    """Share one centre render? ``(choice, reason)`` from the measured change it makes.

    The change (common random numbers, so the parallax alone plus the noise of
    rays that land elsewhere) decides; only where it is within the noise of two
    independent renders does the geometric parallax estimate decide instead.
    """
    err = measured["error_shared_vs_per_detector"]["rms"]
    noise = measured["noise_floor_two_seeds"]["rms"]
    bound = measured["error_bound"]
    geometry = (
        f"parallax {parallax:.3g} texel ({'<' if parallax < fraction else '>='} {fraction:g})"
    )
    change = f"sharing changes measurements by {err:.3g} rms"
    if err < bound:
        return True, f"{change} < bound {bound:.3g} (a share of the target error); {geometry}"
    if parallax < fraction and err <= noise:
        return True, (
            f"{geometry}; {change} >= bound {bound:.3g} but within the noise of two seeds "
            f"({noise:.3g} rms at {measured['probe_spp']} spp), so the geometry decides"
        )
    return False, f"{change} >= bound {bound:.3g} (a share of the target error); {geometry}"


def _spp_for(error_at_pilot: float, target: float, cap: int, steps_per_octave: int = 1) -> int:
    """Smallest spp whose predicted error (1/sqrt(spp)) meets ``target`` (rounded up)."""
    return _round_up_spp(PILOT_SPP * (error_at_pilot / target) ** 2, cap, steps_per_octave)


def _round_up_spp(need: float, cap: int, steps_per_octave: int = 4) -> int:
    """``need`` rounded up on a grid of ``steps_per_octave`` steps per octave, in [1, cap].

    With ``steps_per_octave`` = 4: to ``m 2^e`` with ``m`` in 4..7 (at most 25 %
    above), then up to the next full stratification grid (a multiple of its
    integer square root, at most ``2 / sqrt(n)`` more), so that a frame's
    samples take one pass (:func:`mincam_render.render.transport.sample_passes`).
    """
    need = max(need, 1.0)
    octave = 2 ** math.floor(math.log2(need))
    step = max(octave // steps_per_octave, 1)
    n = int(step * math.ceil(need / step - 1e-9))
    while n % math.isqrt(n):
        n += 1
    return int(min(cap, n))


def _differential_probe(
    family, scene, camera, index, request, background, spp, max_depth, shared, k
):
    """``B + X - C`` of probe frame ``index`` (as a dataset would store it)."""
    from mincam_render.render.differential import (
        BackgroundSettings,
        render_background,
        render_frame,
    )

    settings = BackgroundSettings.from_dict(background)
    bg = render_background(
        family,
        scene,
        camera,
        index,
        settings,
        dataset_seed=request.seed,
        spp=spp,
        max_depth=max_depth or None,
    )
    t, _ = render_frame(family, scene, camera, index, bg, spp=spp, max_depth=max_depth or None)
    return np.repeat(t, k, axis=0) if shared else t


def _split_noise_budget(target, biases, difference, background) -> dict[str, Any]:
    """Share the error left by ``biases`` between the noises of ``X - C`` and of ``B``.

    Errors add in quadrature: ``target^2 = sum(bias^2) + x^2 + y^2`` with ``x``
    the noise of ``X - C`` and ``y`` that of the background. With ``x = a_x
    sqrt(PILOT_SPP / spp_x)`` and cost ``c_x spp_x`` per frame (likewise for
    ``y``), the cheapest split has ``x^2 / y^2 = a_x sqrt(c_x) / (a_y sqrt(c_y))``.
    A noise whose spp is set by a flag takes its share first.

    Args:
        target: target relative measurement error.
        biases: ``{name: rms}`` of the fixed (sample-independent) errors.
        difference: ``(noise at PILOT_SPP, cost per sample per frame, spp flag or None)``.
        background: the same for the background.

    Returns:
        ``{"target", **biases, "difference_noise", "background_noise",
        "biases_exceed_target"}``: the noise each may have.
    """
    fixed2 = sum(b * b for b in biases.values())
    # biases eating the budget leave each noise at least a tenth of the target
    left2 = max(target * target - fixed2, 0.1 * target * target)
    noises = {"difference_noise": difference, "background_noise": background}
    shares = {
        name: pilot * math.sqrt(PILOT_SPP / flag)
        for name, (pilot, _, flag) in noises.items()
        if flag is not None
    }
    free = [(name, pilot, cost) for name, (pilot, cost, flag) in noises.items() if flag is None]
    rest2 = max(left2 - sum(v * v for v in shares.values()), 0.05 * left2)
    weights = {name: pilot * math.sqrt(max(cost, 1e-12)) for name, pilot, cost in free}
    total = sum(weights.values()) or 1.0
    for name, w in weights.items():
        shares[name] = math.sqrt(rest2 * w / total)
    return {
        "target": target,
        **biases,
        **shares,
        "biases_exceed_target": fixed2 > 0.9 * target * target,
    }


def _background_noise(family, scene, camera, probes, interval, depth, lo_hi, request) -> float:
    """Monte Carlo error of the probes' backgrounds, piloted at BACKGROUND_PILOT_SPP.

    Two seeds per probe; reported at PILOT_SPP (times sqrt(BACKGROUND_PILOT_SPP /
    PILOT_SPP)) like the other noises. Stratified samples converge faster than
    1/sqrt(spp) (:mod:`mincam_render.render.transport`), so extrapolating from a pilot
    nearer the backgrounds' spp wastes fewer samples than one at PILOT_SPP.
    A whole background is piloted: its components, rendered apart and summed,
    are no noisier (their weights' squares sum to at most 1 per light).
    """
    renders = {0: [], 1: []}
    for i in probes:
        family.set_background(scene, i, interval)
        for s in renders:
            seed = (frame_seed(request.seed, i) + 7919 * (s + 31)) % 2**63
            renders[s].append(
                family.render_transport(
                    scene, camera, spp=BACKGROUND_PILOT_SPP, seed=seed, max_depth=depth
                )
            )
    a, b = (np.stack(r) for r in renders.values())
    error = measurement_relative_error(a, b, lo_hi)["rms"] / math.sqrt(2.0)
    return error * math.sqrt(BACKGROUND_PILOT_SPP / PILOT_SPP)


def _interpolation_error(family, scene, camera, probes, interval, depth, lo_hi):
    """Error of the background halfway through the probes' windows, interpolated from its ends.

    ``B`` at the start, the middle and the end of each probe frame's window with
    one seed (common random numbers, so the figure is the interpolation's, not
    noise), at ``INTERPOLATION_SPP``.
    """
    spp = INTERPOLATION_SPP
    ends, middles = [], []
    for i in probes:
        renders = []
        for at in (0.0, 0.5, 1.0):
            family.set_background(scene, i, interval, at=at)
            renders.append(
                family.render_transport(
                    scene, camera, spp=spp, seed=frame_seed(i, 17), max_depth=depth
                )
            )
        ends.append(0.5 * (renders[0] + renders[2]))
        middles.append(renders[1])
    return {
        "error": measurement_relative_error(np.stack(ends), np.stack(middles), lo_hi),
        "probe_spp": spp,
        "at": 0.5,
    }


def _decide_differential(
    family,
    scene,
    request,
    render_cam,
    probes,
    lo_hi,
    max_depth,
    plain_spp,
) -> dict[str, Any]:
    """Differential rendering or not, with its frame spp and background spp.

    Measured on the probe frames with common random numbers (``X`` and ``C`` with
    one seed): the parallax of sharing ``X - C`` from the board centre, the
    noise of ``X - C`` from two seeds, the daylight interpolation of the
    backgrounds; then the error budget gives the spp of frames and backgrounds,
    and the cost per frame of both estimators (paths traced, backgrounds
    amortized over the dataset) decides. ``X - C`` is traced at the plain depth.
    """
    from mincam_render.render.differential import background_parts, difference_camera

    available = bool(getattr(family, "has_background", False))
    interval = request.background_interval_s
    record: dict[str, Any] = {"background_interval_s": interval}
    if request.differential is not None:
        if request.differential and not available:
            raise ValueError(
                f"family {family.name!r} has no static background: differential rendering "
                "is unavailable (drop --differential)"
            )
        if not request.differential:
            return {
                "value": False,
                "source": "flag",
                "reason": "set by --no-differential",
                **record,
            }
    elif request.fidelity is not Fidelity.AUTO:
        return {
            "value": False,
            "source": "full",
            "reason": "full fidelity renders frames whole",
            **record,
        }
    elif not available:
        return {
            "value": False,
            "source": "auto",
            "reason": f"family {family.name!r} has no static background",
            **record,
        }

    parts = background_parts(family, family.num_frames, interval)
    components = {c for p in parts.values() for c in p}
    record["backgrounds"] = len(parts)
    record["converged_renders"] = len(components)
    deep = max_depth or None

    def pair(depth, seed_offset, spp, camera=render_cam):
        """(X, C) per probe with one seed each (common random numbers)."""
        xs, cs = [], []
        for i in probes:
            seed = (frame_seed(request.seed, i) + 7919 * (seed_offset + 11)) % 2**63
            family.set_frame_in_window(scene, i, interval)
            xs.append(family.render_transport(scene, camera, spp=spp, seed=seed, max_depth=depth))
            family.set_background(scene, i, interval)
            cs.append(family.render_transport(scene, camera, spp=spp, seed=seed, max_depth=depth))
        return np.stack(xs), np.stack(cs)

    # X - C is traced as deep as the backgrounds: truncating it would bias the
    # movers' change and save little, since a path costs about the same at any
    # depth once Russian roulette and escapes through the window set in
    # (workspace, 12 spp: 12.7 ms per frame at depth 4, 16 at 6, 17.8 at 12).
    # Relative errors of X - C are taken against the probes' X:
    x_ref = []
    for i in probes:
        family.set_frame_in_window(scene, i, interval)
        seed = frame_seed(request.seed, i)
        x_ref.append(
            family.render_transport(
                scene, render_cam, spp=DIFFERENCE_BASE_SPP, seed=seed, max_depth=deep
            )
        )
    x_ref = np.stack(x_ref)
    # one render of X - C from the board centre for all detectors? Its parallax
    # error p is measured against the noise of independent seeds:
    # e_shared^2 ~ noise^2 + p^2 and e_noise^2 ~ noise^2 (same spp, independent seeds)
    k = render_cam.num_detectors
    centre_cam = difference_camera(render_cam, True)
    shared_difference = False
    if k > 1 and request.shared_difference is not None:
        shared_difference = request.shared_difference
        record["shared_difference"] = {"value": shared_difference, "source": "flag"}
    elif k > 1:
        xa, ca = pair(deep, 3, SHARED_DIFFERENCE_SPP)
        xb, cb = pair(deep, 4, SHARED_DIFFERENCE_SPP)
        xc, cc = pair(deep, 5, SHARED_DIFFERENCE_SPP, centre_cam)
        e_shared = measurement_relative_error(xa + (xc - cc) - (xa - ca), xa, lo_hi)["rms"]
        e_noise = measurement_relative_error(xa + (xb - cb) - (xa - ca), xa, lo_hi)["rms"]
        parallax_error = math.sqrt(max(e_shared**2 - e_noise**2, 0.0))
        bound = SHARED_ERROR_SHARE * request.target_error
        shared_difference = parallax_error < bound
        record["shared_difference"] = {
            "value": shared_difference,
            "source": "auto",
            "parallax_error_rms": parallax_error,
            "shared_vs_per_detector_rms": e_shared,
            "two_seeds_rms": e_noise,
            "probe_spp": SHARED_DIFFERENCE_SPP,
            "bound": bound,
        }
    diff_cam = centre_cam if shared_difference else render_cam
    x1, c1 = pair(deep, 1, DIFFERENCE_PILOT_SPP, diff_cam)
    x2, c2 = pair(deep, 2, DIFFERENCE_PILOT_SPP, diff_cam)
    # [N, 1, R, C] differences broadcast over the detectors when shared; the
    # noise is reported at PILOT_SPP like the others
    e_diff = (
        measurement_relative_error(x_ref + x1 - c1, x_ref + x2 - c2, lo_hi)["rms"]
        / math.sqrt(2.0)
        * math.sqrt(DIFFERENCE_PILOT_SPP / PILOT_SPP)
    )
    e_bg = _background_noise(family, scene, render_cam, probes, interval, deep, lo_hi, request)
    interpolation = _interpolation_error(family, scene, render_cam, probes, interval, deep, lo_hi)
    # the error budget: the biases measured above are fixed; the two noises share
    # what is left, split to minimize the cost per frame (see _split_noise_budget)
    parallax = record.get("shared_difference", {}).get("parallax_error_rms", 0.0)
    biases = {
        "shared_difference_parallax": parallax if shared_difference else 0.0,
        "daylight_interpolation": interpolation["error"]["rms"],
    }
    # cost in paths traced per frame (samples x detectors rendered, backgrounds
    # amortized): a deterministic stand-in for time (wall-clock figures would make
    # two plans of one request differ). Paths, not path segments: measured on the
    # workspace, a path costs about the same at depth 4 as at depth 12 (Russian
    # roulette, escapes through the window, per-path camera and light sampling)
    frame_paths = diff_cam.num_detectors
    background_paths = k * len(components) / family.num_frames
    planned_error = PLAN_ERROR_SHARE * request.target_error
    budget = _split_noise_budget(
        planned_error,
        biases,
        (e_diff, frame_paths, request.spp),
        (e_bg, background_paths, request.background_spp),
    )
    frame_spp = (
        request.spp
        if request.spp is not None
        else _spp_for(e_diff, budget["difference_noise"], MAX_AUTO_SPP, 4)
    )
    # the background takes what the frame's rounded-up spp left
    budget = _split_noise_budget(
        planned_error,
        biases,
        (e_diff, frame_paths, frame_spp),
        (e_bg, background_paths, request.background_spp),
    )
    background_spp = (
        request.background_spp
        if request.background_spp is not None
        else _spp_for(e_bg, budget["background_noise"], MAX_BACKGROUND_SPP, 4)
    )
    frame_cost = frame_spp * frame_paths
    background_cost = len(components) * background_spp * k + len(parts) * frame_cost
    cost_diff = frame_cost + background_cost / family.num_frames
    cost_plain = plain_spp * k
    record.update(
        {
            "frame_max_depth": 0 if deep is None else deep,
            "frame_spp": frame_spp,
            "background_spp": background_spp,
            "difference_pilot_error_rms": e_diff,
            "background_pilot_error_rms": e_bg,
            "background_pilot_spp": BACKGROUND_PILOT_SPP,
            "daylight_interpolation": interpolation,
            "error_budget": budget,
            "predicted_error_rms": math.hypot(
                e_diff * math.sqrt(PILOT_SPP / frame_spp),
                e_bg * math.sqrt(PILOT_SPP / background_spp),
                *biases.values(),
            ),
            "cost_per_frame": cost_diff,
            "plain_cost_per_frame": cost_plain,
            "cost_unit": "paths per texel (samples x detectors rendered), backgrounds amortized",
        }
    )
    if request.differential:
        value, source, reason = True, "flag", "set by --differential"
    else:
        value, source = cost_diff < cost_plain, "auto"
        reason = (
            f"B + X - C: X at depth {record['frame_max_depth']} x {frame_spp} spp"
            f"{' from the board centre' if shared_difference else ''} (difference noise "
            f"{e_diff:.3g} at {PILOT_SPP} spp), {len(parts)} background(s) from "
            f"{len(components)} converged components at {background_spp} spp, daylight "
            f"interpolated within {interval:g} s windows (error "
            f"{interpolation['error']['rms']:.3g} rms halfway): cost {cost_diff:.4g} vs plain "
            f"{plain_spp} spp {cost_plain:.4g} (paths per texel)"
        )
    return {"value": value, "source": source, "reason": reason, **record}
