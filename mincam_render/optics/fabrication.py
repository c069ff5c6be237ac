r"""The fabricated mask plane: a designed mask through the printer and the mount (torch).

From the mask logits ``M_t[pixel, row, col]`` and a
:class:`~mincam_render.optics.perturbation.PerturbationDraw`, in the order the
mask is made:

1. the design's place in the printable range, ``y = sigmoid(M_t)`` (0-1);
2. the printer's tone curve and dot gain (:func:`print_tone`):
   ``y' = 1 - c'`` with ``c = 1 - y^gamma`` the ink coverage and
   ``c' = c + 4 g c (1 - c)``;
3. the printed range: ``M = lo' + (hi' - lo') y'``;
4. the print's blur, a Gaussian of ``blur_sigma_mm`` (:func:`blur_mask`);
5. the mount: each mask shifted and rotated about its centre (:func:`place_masks`,
   bilinear resampling).

Outside the printed design the film carries the darkest printable ink (the mask
is printed with an opaque border), so texels that a shift or a blur brings in
from beyond the design read ``lo'``. Every step whose drawn value is exactly
zero is skipped, so a zero draw gives exactly the nominal
:func:`~mincam_render.optics.maskplane.transmittance`. Every step is
differentiable in the logits.
"""

from __future__ import annotations

import math

import torch
from torch.nn import functional as F

from mincam_render.optics.perturbation import PerturbationDraw

MM = 1e-3  #: metres per millimetre
#: Gaussian kernels reach this many sigmas on each side.
_KERNEL_SIGMAS = 3.0


def print_tone(y: torch.Tensor, gamma: float, dot_gain: float) -> torch.Tensor:
    """The printed fraction of the printable range for a designed fraction ``y`` (0-1; torch).

    Args:
        y: designed place in the printable range, any shape, in [0, 1].
        gamma: tone-curve exponent (> 0): ``y -> y^gamma``.
        dot_gain: dot gain at 50 % ink coverage, [-0.25, 0.25]: coverage
            ``c -> c + 4 g c (1 - c)``, monotone and within [0, 1] in this range.

    Returns:
        ``y'`` in [0, 1], same shape; monotone non-decreasing in ``y``.

    Raises:
        ValueError: gamma <= 0 or not finite, dot gain outside [-0.25, 0.25].

    """
    if not (math.isfinite(gamma) and gamma > 0):
        raise ValueError(f"gamma = {gamma!r} is invalid: allowed a finite number > 0")
    if not abs(dot_gain) <= 0.25:
        raise ValueError(f"dot_gain = {dot_gain!r} is invalid: allowed [-0.25, 0.25]")
    if gamma != 1.0:
        # y^gamma as exp(gamma log y): y clamped off 0, where the derivative of y^gamma
        # with gamma < 1 is infinite
        y = torch.exp(gamma * torch.log(y.clamp_min(torch.finfo(y.dtype).tiny)))
    if dot_gain != 0.0:
        coverage = 1.0 - y
        y = 1.0 - (coverage + (4.0 * dot_gain) * coverage * y)
    return y


def gaussian_kernel(sigma_texels: float, dtype: torch.dtype) -> torch.Tensor:
    """A normalised 1-D Gaussian ``[2r + 1]`` (``r = ceil(3 sigma)``) of ``sigma_texels`` > 0."""
    radius = max(1, math.ceil(_KERNEL_SIGMAS * sigma_texels))
    x = torch.arange(-radius, radius + 1, dtype=dtype)
    k = torch.exp(-0.5 * (x / sigma_texels) ** 2)
    return k / k.sum()


def blur_mask(mask: torch.Tensor, sigma_texels: tuple[float, float], fill: float) -> torch.Tensor:
    """Gaussian blur of ``M[pixel, row, col]`` with the region outside at ``fill`` (torch).

    Args:
        mask: transmittance ``M[pixel, row, col]``.
        sigma_texels: ``(rows, cols)`` sigma in texels, each > 0.
        fill: transmittance outside the mask (the printed border).

    Returns:
        The blurred mask, same shape; differentiable in ``mask``.

    """
    x = (mask - fill).unsqueeze(1)  # [pixel, 1, row, col]; zero padding = the border
    for axis, sigma in enumerate(sigma_texels):
        k = gaussian_kernel(sigma, mask.dtype).to(mask.device)
        r = (len(k) - 1) // 2
        weight = k.reshape(1, 1, -1, 1) if axis == 0 else k.reshape(1, 1, 1, -1)
        x = F.conv2d(x, weight, padding=(r, 0) if axis == 0 else (0, r))
    return x.squeeze(1) + fill


def place_masks(
    mask: torch.Tensor,
    shift_texels: torch.Tensor,
    rotation_rad: torch.Tensor,
    fill: float,
) -> torch.Tensor:
    """Each mask shifted and rotated about its centre, bilinear resampling (torch).

    ``out[k](p) = mask[k](R(-phi_k) (p - s_k))`` about the mask centre, in texel
    units (rows down, columns right), so a positive column shift moves the
    pattern right and an integer shift is a roll with the border entering.

    Args:
        mask: transmittance ``M[pixel, row, col]``.
        shift_texels: ``[pixel, 2]`` displacement in texels (rows down, columns right).
        rotation_rad: ``[pixel]`` rotation (rad), clockwise as seen from the camera.
        fill: transmittance outside the design (the printed border).

    Returns:
        The placed masks, same shape; differentiable in ``mask``.

    """
    k, rows, cols = mask.shape
    half_w, half_h = cols / 2.0, rows / 2.0
    c, s = torch.cos(rotation_rad), torch.sin(rotation_rad)
    sy, sx = shift_texels[:, 0], shift_texels[:, 1]
    # sampling point of each output texel in grid_sample's normalised [-1, 1] coordinates
    theta = torch.stack(
        [
            torch.stack([c, s * (half_h / half_w), -(c * sx + s * sy) / half_w], dim=-1),
            torch.stack([-s * (half_w / half_h), c, (s * sx - c * sy) / half_h], dim=-1),
        ],
        dim=1,
    ).to(mask.dtype)
    grid = F.affine_grid(theta, [k, 1, rows, cols], align_corners=False)
    out = F.grid_sample(
        (mask - fill).unsqueeze(1), grid, mode="bilinear", padding_mode="zeros", align_corners=False
    )
    return out.squeeze(1) + fill


def fabricated_transmittance(
    logits: torch.Tensor,
    transmittance_range: tuple[float, float],
    draw: PerturbationDraw,
    texel_size_m: tuple[float, float],
) -> torch.Tensor:
    """Transmittance ``M[pixel, row, col]`` of the masks as built (steps 1-5 above; torch).

    Args:
        logits: ``M_t[pixel, row, col]`` mask logits.
        transmittance_range: nominal printable ``(lo, hi)``.
        draw: the built camera; ``draw.num_pixels`` must equal the number of masks.
        texel_size_m: ``(rows, cols)`` texel size (m).

    Returns:
        ``M[pixel, row, col]``, equal to the nominal transmittance for an identity draw.

    Raises:
        ValueError: the draw is for another number of pixels.

    """
    if draw.num_pixels != logits.shape[0]:
        raise ValueError(
            f"the perturbation draw is for {draw.num_pixels} pixels; the camera has "
            f"{logits.shape[0]} masks"
        )
    y = print_tone(torch.sigmoid(logits), draw.gamma, draw.dot_gain)
    lo, hi = draw.transmittance_range(transmittance_range)
    m = lo + (hi - lo) * y
    texel_mm = (texel_size_m[0] / MM, texel_size_m[1] / MM)
    if draw.blur_sigma_mm > 0:
        m = blur_mask(m, (draw.blur_sigma_mm / texel_mm[0], draw.blur_sigma_mm / texel_mm[1]), lo)
    if draw.shift_mm.any() or draw.rotation_deg.any():
        shift = torch.as_tensor(draw.shift_mm / texel_mm, dtype=m.dtype, device=m.device)
        angle = torch.as_tensor(draw.rotation_deg, dtype=m.dtype, device=m.device)
        m = place_masks(m, shift, torch.deg2rad(angle), lo)
    return m
