"""SURROGATE-real recordings: a family rendered through a camera perturbed like hardware.

:func:`make_surrogate` (for tests and demos; no prototype data exist here)
renders a family through a perturbed camera the way hardware deviates from its
design and records every injected value in ``injected.json``. The camera as
built is drawn from :class:`~mincam_render.optics.perturbation.PerturbationModel`,
the model robust training and the robustness report use (mask misalignment and
rotation, printer tone curve, dot gain, printable range and blur, detector gain
and offset mismatch, board pose error), printed by the same mask plane
(:func:`~mincam_render.optics.fabrication.printed_transmittance`), the board's
pose rendered exactly; stray light, dark current, read noise and ADC
quantization are the SURROGATE's own. Its output is labelled SURROGATE in the files and in every
report made from it.

Arrays are numpy float64 unless a docstring says torch; lengths in metres, angles
in radians (degrees where the name says so), powers in watts, voltages in volts.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.checks import check_number
from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import MM
from mincam_render.optics.perturbation import DEG, MAGNITUDES, PerturbationDraw, PerturbationModel
from mincam_render.studies.sim2real.recording import (
    FORMAT_NAME,
    FORMAT_VERSION,
    SURROGATE_BANNER,
    write_recording,
)
from mincam_render.studies.sim2real.simulation import simulate_volts

if TYPE_CHECKING:
    from mincam_render.optics.camera import DetectorElectronics, FreeformCamera
    from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)


#: Half-range of a uniform draw per standard deviation: the former SURROGATE drew
#: normal errors of standard deviation sigma; the shared model draws uniformly in
#: ``[-a, a]``, and ``a = sqrt(3) sigma`` keeps the spread.
UNIFORM_HALF_RANGE_PER_SIGMA = math.sqrt(3.0)

#: The SURROGATE's built camera: the former ``SurrogatePerturbations`` defaults
#: mapped onto the shared model (:mod:`mincam_render.optics.perturbation` lists
#: the mapping): sigma 0.15 mm shift, 1 deg rotation, 10 % gain, 10 mV offset,
#: 5 mm and 0.5 deg board pose; printer gamma 1.15; dot gain 0.05 (its darkening
#: 5 % of the prototype's printable range 0.01-0.67, its blur 0.5 texel of the
#: prototype's 0.5-mm texels).
SURROGATE_PERTURBATION = PerturbationModel(
    mask_shift_m=UNIFORM_HALF_RANGE_PER_SIGMA * 0.15 * MM,
    mask_rotation_rad=UNIFORM_HALF_RANGE_PER_SIGMA * 1.0 * DEG,
    gamma_deviation=0.15,
    dot_gain_deviation=0.05,
    min_transmittance_error=0.05 * 0.01,
    max_transmittance_error=0.05 * 0.67,
    mask_blur_m=0.25 * MM,
    gain_mismatch_fraction=UNIFORM_HALF_RANGE_PER_SIGMA * 0.1,
    dark_offset_v=UNIFORM_HALF_RANGE_PER_SIGMA * 0.01,
    pose_orientation_rad=UNIFORM_HALF_RANGE_PER_SIGMA * 0.5 * DEG,
    pose_position_m=UNIFORM_HALF_RANGE_PER_SIGMA * 5.0 * MM,
)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SurrogatePerturbations:
    """How the SURROGATE deviates from the design.

    Args:
        perturbation: the built camera's deviations from its design (mask
            shift and rotation, print tone, dot gain, printable range and blur,
            detector gain and offset, board pose), the model robust training and
            the robustness report draw from; one camera is drawn per recording.
            :meth:`PerturbationModel.zero` switches them all off.
        stray_light_fraction: constant stray power per pixel, uniform in
            ``[0, fraction] x`` the pixel's mean designed power (W).
        dark_current_a: per-pixel dark current, uniform in ``[0, value]`` (A).
        read_noise: add the electronics' read noise and ADC quantization.
        common_random_numbers: render with the analysis's seeds, so that without
            geometric perturbations the rendered power is identical and only the
            injected electronics differ (for exact recovery tests).

    Raises:
        ValueError: ``perturbation`` is no :class:`PerturbationModel`, or a
            number is negative or not finite (the message names the field).
    """

    perturbation: PerturbationModel = SURROGATE_PERTURBATION
    stray_light_fraction: float = 0.05
    dark_current_a: float = 2e-10
    read_noise: bool = True
    common_random_numbers: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.perturbation, PerturbationModel):
            raise ValueError(
                f"SurrogatePerturbations.perturbation = {self.perturbation!r}: allowed a "
                "mincam_render.optics.perturbation.PerturbationModel"
            )
        for name in ("stray_light_fraction", "dark_current_a"):
            check_number(f"SurrogatePerturbations.{name}", getattr(self, name), 0)

    @property
    def geometric(self) -> bool:
        """True when masks, print or board differ from the design (fits are then approximate)."""
        electronic = ("gain_mismatch_fraction", "dark_offset_v")
        return any(getattr(self.perturbation, n) for n in MAGNITUDES if n not in electronic)

    def to_record(self) -> JsonObject:
        """``injected.json``'s ``perturbations``, the model in its record's units (mm, deg, %)."""
        return {**dataclasses.asdict(self), "perturbation": self.perturbation.to_record()}


def print_masks(masks: np.ndarray, camera: FreeformCamera, draw: PerturbationDraw) -> np.ndarray:
    """What a printer and a slightly misplaced mask make of designs ``M[pixel, row, col]``.

    The shared fabricated mask plane
    (:func:`mincam_render.optics.fabrication.printed_transmittance`): tone
    curve and dot gain, printed range, blur, then each mask's shift and
    rotation, the printed border entering; the board's pose is left to the
    render of the moved camera.

    Args:
        masks: designs ``M[pixel, row, col]``, transmittance in ``camera``'s printable range.
        camera: the designed camera (printable range, texel size).
        draw: the built camera.

    Returns:
        The printed transmittance ``M[pixel, row, col]`` (numpy float64).
    """
    import torch

    from mincam_render.optics.fabrication import printed_transmittance

    lo, hi = camera.transmittance_range
    fraction = torch.from_numpy(np.clip((masks - lo) / (hi - lo), 0.0, 1.0))
    printed = printed_transmittance(
        fraction, camera.transmittance_range, draw.without_pose(), camera.texel_size_m
    )
    return printed.numpy()


def _mount_masks(
    design: np.ndarray, camera: FreeformCamera, draw: PerturbationDraw
) -> tuple[np.ndarray, JsonObject]:
    """Designs ``M[pixel, row, col]`` as printed and mounted by ``draw``.

    Returns:
        ``(printed M[pixel, row, col], {"mask_shift_m": [pixel][row, col] (m),
        "mask_rotation_deg": [pixel], "print": {...}})``: the masks and what was injected.
    """
    printed = print_masks(design, camera, draw)
    return printed, {
        "mask_shift_m": draw.shift_m.tolist(),
        "mask_rotation_deg": np.degrees(draw.rotation_rad).tolist(),
        "print": {
            "gamma": draw.gamma,
            "dot_gain": draw.dot_gain,
            "min_transmittance_error": draw.min_transmittance_error,
            "max_transmittance_error": draw.max_transmittance_error,
            "blur_sigma_m": draw.blur_sigma_m,
        },
    }


def _misplace_board(
    camera: FreeformCamera, draw: PerturbationDraw
) -> tuple[FreeformCamera, dict[str, list[float]]]:
    """The camera as mounted, and ``injected.json``'s ``board`` (pose error in m and deg).

    The designed camera turned by the draw's ``(pan, tilt, roll)`` and moved by
    its ``(right, up, forward)`` (:func:`mincam_render.optics.pose.posed_camera`).
    """
    from mincam_render.optics.pose import posed_camera

    real_cam = posed_camera(camera, draw.pose_rotation_rad, draw.pose_offset_m)
    board = {
        "position_error_m": draw.pose_offset_m.tolist(),
        "rotation_error_deg": np.degrees(draw.pose_rotation_rad).tolist(),
        "real_position_m": list(real_cam.position),
        "real_look_at_m": list(real_cam.look_at),
    }
    return real_cam, board


def _measure(
    power: np.ndarray,
    power_design: np.ndarray,
    e: DetectorElectronics,
    pert: SurrogatePerturbations,
    draw: PerturbationDraw,
    rng: np.random.Generator,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Voltages ``V[N, P]`` the perturbed electronics make of powers ``P[N, P]`` (W).

    Args:
        power: ``[N, P]`` power reaching each detector through its printed mask (W).
        power_design: ``[n, P]`` power of the design, whose mean scales the stray light (W).
        e: the designed electronics.
        pert: the perturbations.
        draw: the built camera: its gain acts on each detector's power, its
            offset on the output voltage (as in training).
        rng: draws stray light, dark current, then read noise, in that order.

    Returns:
        ``(volts[N, P] (V), {"gain", "offset_v", "stray_light_w", "dark_current_a"}: [P]
        each)``.
    """
    k = power.shape[1]
    gain, offset = draw.gain, draw.offset_v
    stray_w = rng.uniform(0.0, pert.stray_light_fraction, size=k) * power_design.mean(axis=0)
    dark_a = rng.uniform(0.0, pert.dark_current_a, size=k)
    # power (stray light included) -> photocurrent -> transimpedance, then the offset
    clean = e.gain_v_per_a * (e.responsivity_a_per_w * gain * (power + stray_w) + dark_a)
    volts = clean + offset
    if pert.read_noise:
        volts = volts + rng.normal(0.0, e.read_noise_v, size=volts.shape)
        volts = np.floor(volts / e.lsb_v) * e.lsb_v + 0.5 * e.lsb_v  # ADC quantization
    volts = _saturate(volts, e)
    injected = {
        "gain": gain,
        "offset_v": offset,
        "stray_light_w": stray_w,
        "dark_current_a": dark_a,
    }
    return volts, injected


def _saturate(volts: np.ndarray, e: DetectorElectronics) -> np.ndarray:
    """The electronics' leaky saturation of ``volts`` (any shape, V)."""
    import torch

    from mincam_render.optics.sensor import leaky_saturation

    return leaky_saturation(torch.from_numpy(volts), e.full_scale_v, e.saturation_slope).numpy()


def make_surrogate(
    family_name: str,
    out_dir: str | Path,
    *,
    num_frames: int = 300,
    spp: int = 4,
    seed: int = 0,
    perturbations: SurrogatePerturbations | None = None,
    mask_resolution: int | None = None,
    progress: bool = False,
) -> Path:
    """Write a SURROGATE-real recording of a family to ``out_dir`` (returned).

    The printed masks are trained-like smooth designs
    (:func:`mincam_render.render.precision.smooth_masks`); the family's camera is
    the design. ``injected.json`` records every injected value and, per pixel,
    the gain and offset a fit of ``real = gain * sim + offset`` should find
    (exact when :attr:`SurrogatePerturbations.geometric` is False).
    """
    from mincam_render.scenes import load_family

    pert = perturbations or SurrogatePerturbations()
    family = load_family(family_name, seed=seed, num_frames=num_frames)
    camera, design = _design(family, mask_resolution, seed)
    pixels = np.arange(camera.num_detectors)
    rng = np.random.default_rng(stream_seed(seed, "sim2real/surrogate"))
    draw = pert.perturbation.draw(camera.num_detectors, rng)
    printed, mounted = _mount_masks(design, camera, draw)
    real_cam, board = _misplace_board(camera, draw)
    frame_index = np.arange(num_frames)
    stream = 0 if pert.common_random_numbers else 1
    power, power_design = _powers(
        family, camera, real_cam, design, printed, frame_index, spp, seed, stream, progress
    )
    volts, electronics = _measure(power, power_design, camera.electronics, pert, draw, rng)
    injected = {
        "surrogate": True,
        "perturbations": pert.to_record(),
        "render_seed_stream": stream,
        "per_pixel": {**{name: v.tolist() for name, v in electronics.items()}, **mounted},
        "board": board,
        "expected_fit": _expected_fit(electronics, camera.electronics, pert),
    }
    out = Path(out_dir)
    write_recording(
        out,
        _recording_meta(family, family_name, seed, camera, pixels),
        time_s=frame_index / float(family.fps),
        frame_index=frame_index,
        volts=volts,
        label_rows=_label_rows(family, frame_index),
        label_specs=family.labels,
        masks=design,
        injected=injected,
    )
    log.info("wrote SURROGATE recording of %s (%d frames) to %s", family_name, num_frames, out)
    return out


def _powers(
    family: SceneFamily,
    camera: FreeformCamera,
    real_cam: FreeformCamera,
    design: np.ndarray,
    printed: np.ndarray,
    frame_index: np.ndarray,
    spp: int,
    seed: int,
    stream: int,
    progress: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Powers (W) through the printed masks and through the design.

    Returns:
        ``(power[N, pixel], power_design[n, pixel])``: through ``printed`` on
        ``real_cam`` at every frame of ``frame_index`` (render seed stream ``stream``),
        and through ``design`` on ``camera`` at about 20 of them (stream 2).
    """
    pixels = np.arange(camera.num_detectors)
    label = "surrogate recording" if progress else None
    _, power = simulate_volts(
        family,
        real_cam,
        frame_index,
        printed,
        pixels,
        spp=spp,
        seed=seed,
        stream=stream,
        progress=label,
    )
    # the design's mean power (about 20 frames across the sequence) scales the stray light
    every = frame_index[:: max(1, len(frame_index) // 20)]
    _, power_design = simulate_volts(
        family, camera, every, design, pixels, spp=spp, seed=seed, stream=2
    )
    return power, power_design


def _design(
    family: SceneFamily, mask_resolution: int | None, seed: int
) -> tuple[FreeformCamera, np.ndarray]:
    """The designed camera (the family's, at ``mask_resolution`` if given) and its masks.

    Returns:
        ``(camera, M[pixel, row, col])``: trained-like smooth masks in the printable range.
    """
    from mincam_render.render.precision import smooth_masks

    camera = family.camera()
    if mask_resolution is not None:
        camera = dataclasses.replace(camera, mask_resolution=(mask_resolution, mask_resolution))
    shape = (camera.num_detectors, *camera.mask_resolution)
    return camera, smooth_masks(
        1, shape, camera.transmittance_range, stream_seed(seed, "sim2real/design")
    )[0]


def _expected_fit(
    electronics: dict[str, np.ndarray], e: DetectorElectronics, pert: SurrogatePerturbations
) -> JsonObject:
    """The gain and offset (V) per pixel a fit of ``real = gain * sim + offset`` should find.

    Stray light passes the same gain as the signal and the dark current the
    transimpedance, so a fit sees them as offset.
    """
    gain, offset = electronics["gain"], electronics["offset_v"]
    stray_w, dark_a = electronics["stray_light_w"], electronics["dark_current_a"]
    g_e = e.gain_v_per_a
    return {
        "gain": gain.tolist(),
        "offset_v": (g_e * (e.responsivity_a_per_w * gain * stray_w + dark_a) + offset).tolist(),
        "exact": not pert.geometric,
        "note": "real = gain * sim + offset holds exactly only without geometric or "
        "printing perturbations; otherwise these are the electronics' share",
    }


def _label_rows(family: SceneFamily, frame_index: np.ndarray) -> np.ndarray:
    """Ground truth ``[N, sum of label sizes]`` (float64) of each frame, in label order."""
    scene = family.build_scene()
    rows = []
    for i in frame_index:
        lab = family.set_frame(scene, int(i))
        rows.append(
            np.concatenate(
                [np.asarray(lab[s.name], np.float64).reshape(s.size) for s in family.labels]
            )
        )
    return np.asarray(rows)


def _recording_meta(
    family: SceneFamily, family_name: str, seed: int, camera: FreeformCamera, pixels: np.ndarray
) -> JsonObject:
    """``recording.json``'s content (the checksums are added when the files are written)."""
    from mincam_render.data.dataset import camera_to_dict, label_spec_to_dict

    return {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "surrogate": True,
        "note": SURROGATE_BANNER,
        "units": "V",
        "fps": float(family.fps),
        "family": family_name,
        "family_seed": seed,
        "camera": camera_to_dict(camera),
        "pixels": pixels.tolist(),
        "label_specs": [label_spec_to_dict(s) for s in family.labels],
    }
