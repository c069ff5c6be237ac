"""SURROGATE-real recordings: a family rendered through a camera perturbed like hardware.

:func:`make_surrogate` (for tests and demos; no prototype data exist here)
renders a family through a perturbed camera the way hardware deviates from its
design (mask misalignment and rotation, printer transmittance curve and dot
gain, detector gain and offset mismatch, board pose error, stray light, dark
current, read noise and ADC quantization) and records every injected value in
``injected.json``. Its output is labelled SURROGATE in the files and in every
report made from it.

Arrays are numpy float64 unless a docstring says torch; lengths in metres, angles
in radians (degrees where the name says so), powers in watts, voltages in volts.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.core.checks import check_number
from mincam_render.core.seeds import stream_seed
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


@dataclasses.dataclass(frozen=True, kw_only=True)
class SurrogatePerturbations:
    """How the SURROGATE deviates from the design; 0 switches a perturbation off.

    Random values are drawn per pixel (or per board) from the stated spreads.

    Args:
        mask_shift_m: standard deviation of the mask's in-plane misalignment (m).
        mask_rotation_deg: standard deviation of the mask's in-plane rotation (deg).
        printer_gamma: printer transmittance curve ``m' = lo + (hi-lo) x^gamma`` on
            the normalised design ``x``; 1 = linear.
        dot_gain: printed dots grow: transmittance x ``(1 - dot_gain)`` and a blur
            of ``dot_gain * 10`` texels (sigma).
        gain_sigma: standard deviation of the per-pixel gain around 1 (fraction).
        offset_sigma_v: standard deviation of the per-pixel voltage offset (V).
        board_position_m: standard deviation of the board's position error (m).
        board_rotation_deg: standard deviation of the board's pointing error (deg).
        stray_light_fraction: constant stray power per pixel, uniform in
            ``[0, fraction] x`` the pixel's mean designed power (W).
        dark_current_a: per-pixel dark current, uniform in ``[0, value]`` (A).
        read_noise: add the electronics' read noise and ADC quantization.
        common_random_numbers: render with the analysis's seeds, so that without
            geometric perturbations the rendered power is identical and only the
            injected electronics differ (for exact recovery tests).
    """

    mask_shift_m: float = 0.15e-3
    mask_rotation_deg: float = 1.0
    printer_gamma: float = 1.15
    dot_gain: float = 0.05
    gain_sigma: float = 0.1
    offset_sigma_v: float = 0.01
    board_position_m: float = 5e-3
    board_rotation_deg: float = 0.5
    stray_light_fraction: float = 0.05
    dark_current_a: float = 2e-10
    read_noise: bool = True
    common_random_numbers: bool = False

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if not isinstance(v, bool):  # the switches
                check_number(f"SurrogatePerturbations.{f.name}", v, 0)
        if self.printer_gamma <= 0:
            raise ValueError("SurrogatePerturbations.printer_gamma must be > 0")
        if self.dot_gain >= 1:
            raise ValueError("SurrogatePerturbations.dot_gain must be < 1 (fraction)")

    @property
    def geometric(self) -> bool:
        """True when masks or board differ from the design (fits are then approximate)."""
        return (
            any(
                v
                for v in (
                    self.mask_shift_m,
                    self.mask_rotation_deg,
                    self.dot_gain,
                    self.board_position_m,
                    self.board_rotation_deg,
                )
            )
            or self.printer_gamma != 1.0
        )


def print_masks(
    masks: np.ndarray,
    transmittance_range: tuple[float, float],
    *,
    gamma: float,
    dot_gain: float,
    shift_texels: np.ndarray,
    rotation_rad: np.ndarray,
) -> np.ndarray:
    """What a printer and a slightly misplaced mask make of designs ``M[pixel, row, col]``.

    Printer curve, then dot gain (darkening and blur), then per-pixel shift
    ``(d_row, d_col)`` in texels and rotation (rad) about the mask centre;
    texels uncovered by the shift see the mask's frame (minimum transmittance).
    Uses torch's ``grid_sample`` (bilinear).
    """
    import torch
    import torch.nn.functional as F

    lo, hi = transmittance_range
    x = np.clip((masks - lo) / (hi - lo), 0.0, 1.0)
    m = lo + (hi - lo) * x**gamma
    m = m * (1.0 - dot_gain)
    t = torch.from_numpy(m[:, None]).double()
    sigma = 10.0 * dot_gain
    if sigma > 0:
        r = max(1, int(math.ceil(3 * sigma)))
        k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=torch.float64) / sigma) ** 2)
        k = k / k.sum()
        t = F.conv2d(F.pad(t, (r, r, 0, 0), mode="replicate"), k.view(1, 1, 1, -1))
        t = F.conv2d(F.pad(t, (0, 0, r, r), mode="replicate"), k.view(1, 1, -1, 1))
    p, rows, cols = masks.shape
    theta = torch.zeros(p, 2, 3, dtype=torch.float64)
    c, s = torch.cos(torch.from_numpy(rotation_rad)), torch.sin(torch.from_numpy(rotation_rad))
    theta[:, 0, 0], theta[:, 0, 1], theta[:, 1, 0], theta[:, 1, 1] = c, -s, s, c
    # normalised coordinates span 2 over the mask: a shift of one texel is 2 / cols
    theta[:, 0, 2] = -torch.from_numpy(shift_texels[:, 1]) * 2.0 / cols
    theta[:, 1, 2] = -torch.from_numpy(shift_texels[:, 0]) * 2.0 / rows
    grid = F.affine_grid(theta, [p, 1, rows, cols], align_corners=False)
    out = (
        F.grid_sample(t - lo, grid, mode="bilinear", padding_mode="zeros", align_corners=False) + lo
    )
    return out[:, 0].numpy().clip(0.0, 1.0)


def _mount_masks(
    design: np.ndarray,
    camera: FreeformCamera,
    pert: SurrogatePerturbations,
    rng: np.random.Generator,
) -> tuple[np.ndarray, dict[str, list]]:
    """Designs ``M[pixel, row, col]`` as printed and mounted.

    Draws the shifts, then the rotations, from ``rng``.

    Returns:
        ``(printed M[pixel, row, col], {"mask_shift_m": [pixel][row, col] (m),
        "mask_rotation_deg": [pixel]})``: the masks and what was injected.
    """
    k, _, cols = design.shape
    texel_m = camera.mask_size_m / cols
    shift_m = (
        rng.normal(0.0, pert.mask_shift_m, size=(k, 2)) if pert.mask_shift_m else np.zeros((k, 2))
    )
    rot = (
        np.radians(rng.normal(0.0, pert.mask_rotation_deg, size=k))
        if pert.mask_rotation_deg
        else np.zeros(k)
    )
    printed = print_masks(
        design,
        camera.transmittance_range,
        gamma=pert.printer_gamma,
        dot_gain=pert.dot_gain,
        shift_texels=shift_m / texel_m,
        rotation_rad=rot,
    )
    return printed, {
        "mask_shift_m": shift_m.tolist(),
        "mask_rotation_deg": np.degrees(rot).tolist(),
    }


def _rotate_about(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    return (
        v * math.cos(angle)
        + np.cross(axis, v) * math.sin(angle)
        + axis * np.dot(axis, v) * (1 - math.cos(angle))
    )


def _misplace_board(
    camera: FreeformCamera, pert: SurrogatePerturbations, rng: np.random.Generator
) -> tuple[FreeformCamera, dict[str, list[float]]]:
    """The camera as mounted, and ``injected.json``'s ``board`` (pose error in m and deg).

    Draws the position error, then the pointing error (about up, then right), from ``rng``.
    """
    right, up, _ = camera.frame
    dpos = rng.normal(0.0, pert.board_position_m, size=3) if pert.board_position_m else np.zeros(3)
    angles = (
        np.radians(rng.normal(0.0, pert.board_rotation_deg, size=2))
        if pert.board_rotation_deg
        else np.zeros(2)
    )
    aim = np.subtract(camera.look_at, camera.position)
    aim = _rotate_about(_rotate_about(aim, up, angles[0]), right, angles[1])
    real_pos = np.asarray(camera.position) + dpos
    real_cam = dataclasses.replace(camera, position=tuple(real_pos), look_at=tuple(real_pos + aim))
    board = {
        "position_error_m": dpos.tolist(),
        "rotation_error_deg": np.degrees(angles).tolist(),
        "real_position_m": list(real_cam.position),
        "real_look_at_m": list(real_cam.look_at),
    }
    return real_cam, board


def _measure(
    power: np.ndarray,
    power_design: np.ndarray,
    e: DetectorElectronics,
    pert: SurrogatePerturbations,
    rng: np.random.Generator,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Voltages ``V[N, P]`` the perturbed electronics make of powers ``P[N, P]`` (W).

    Args:
        power: ``[N, P]`` power reaching each detector through its printed mask (W).
        power_design: ``[n, P]`` power of the design, whose mean scales the stray light (W).
        e: the designed electronics.
        pert: the perturbations.
        rng: draws gain, offset, stray light, dark current, then read noise, in that order.

    Returns:
        ``(volts[N, P] (V), {"gain", "offset_v", "stray_light_w", "dark_current_a"}: [P]
        each)``.
    """
    k = power.shape[1]
    gain = 1.0 + rng.normal(0.0, pert.gain_sigma, size=k) if pert.gain_sigma else np.ones(k)
    offset = rng.normal(0.0, pert.offset_sigma_v, size=k) if pert.offset_sigma_v else np.zeros(k)
    stray_w = rng.uniform(0.0, pert.stray_light_fraction, size=k) * power_design.mean(axis=0)
    dark_a = rng.uniform(0.0, pert.dark_current_a, size=k)
    # photocurrent -> transimpedance -> per-pixel gain mismatch and offset
    clean = e.gain_v_per_a * (e.responsivity_a_per_w * (power + stray_w) + dark_a)
    volts = gain * clean + offset
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
    printed, mounted = _mount_masks(design, camera, pert, rng)
    real_cam, board = _misplace_board(camera, pert, rng)
    frame_index = np.arange(num_frames)
    stream = 0 if pert.common_random_numbers else 1
    power, power_design = _powers(
        family, camera, real_cam, design, printed, frame_index, spp, seed, stream, progress
    )
    volts, electronics = _measure(power, power_design, camera.electronics, pert, rng)
    injected = {
        "surrogate": True,
        "perturbations": dataclasses.asdict(pert),
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
) -> dict[str, Any]:
    """The gain and offset (V) per pixel a fit of ``real = gain * sim + offset`` should find.

    Stray light and dark current pass the same gains as the signal, so a fit sees
    them as offset.
    """
    gain, offset = electronics["gain"], electronics["offset_v"]
    stray_w, dark_a = electronics["stray_light_w"], electronics["dark_current_a"]
    g_e = e.gain_v_per_a
    return {
        "gain": gain.tolist(),
        "offset_v": (gain * g_e * (e.responsivity_a_per_w * stray_w + dark_a) + offset).tolist(),
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
) -> dict[str, Any]:
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
