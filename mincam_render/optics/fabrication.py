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
   bilinear resampling);
6. the camera's pose: the whole camera turned and moved against the pose the
   transport was rendered for, the same effective-mask splat for every
   detector (:func:`posed_masks`, :mod:`mincam_render.optics.pose`).

Outside the printed design the film carries the darkest printable ink (the mask
is printed with an opaque border), so texels that a shift or a blur brings in
from beyond the design read ``lo'``. Every step whose drawn value is exactly
zero is skipped, so a zero draw gives exactly the nominal
:func:`~mincam_render.optics.maskplane.transmittance`. Every step is
differentiable in the logits.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch.nn import functional as F

from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.perturbation import PerturbationDraw
from mincam_render.optics.pose import CM, PoseWarp, pose_warp

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


def gaussian_matrix(n: int, sigma_texels: float) -> np.ndarray:
    """``B[n, n]`` (numpy): row ``i`` the normalised Gaussian around texel ``i`` (sigma > 0).

    Weights are normalised over the infinite line (3-sigma support), then cut to
    the ``n`` texels: what a blur takes from beyond the mask is the border's.
    Built in numpy: the blur's few taps as banded identities cost microseconds,
    where the same in torch's small ops costs ~10x more per training step.
    """
    radius = max(1, math.ceil(_KERNEL_SIGMAS * sigma_texels))
    offsets = np.arange(-radius, radius + 1)
    taps = np.exp(-0.5 * (offsets / sigma_texels) ** 2)
    taps /= taps.sum()
    return sum(t * np.eye(n, k=-int(o)) for t, o in zip(taps, offsets, strict=True))


def blur_mask(mask: torch.Tensor, sigma_texels: tuple[float, float], fill: float) -> torch.Tensor:
    """Gaussian blur of ``M[pixel, row, col]`` with the region outside at ``fill`` (torch).

    Separable: ``B_rows (M - fill) B_cols^T + fill``, two small matrix products
    (a 3-tap ``conv2d`` measured ~10x slower on 8 masks of 32x32 texels).

    Args:
        mask: transmittance ``M[pixel, row, col]``.
        sigma_texels: ``(rows, cols)`` sigma in texels, each > 0.
        fill: transmittance outside the mask (the printed border).

    Returns:
        The blurred mask, same shape; differentiable in ``mask``.

    """
    rows, cols = mask.shape[-2:]
    b_rows = torch.as_tensor(gaussian_matrix(rows, sigma_texels[0]), dtype=mask.dtype)
    b_cols = torch.as_tensor(gaussian_matrix(cols, sigma_texels[1]).T, dtype=mask.dtype)
    b_rows, b_cols = b_rows.to(mask.device), b_cols.to(mask.device)
    return b_rows @ (mask - fill) @ b_cols + fill


def sampling_grid(
    shape: tuple[int, int], shift_texels: np.ndarray, rotation_rad: np.ndarray
) -> np.ndarray:
    """``grid[pixel, row, col, (x, y)]`` of :func:`place_masks` in ``grid_sample``'s units (numpy).

    The sampling point ``R(-phi)(p - s)`` of each output texel centre ``p``
    (texel units about the mask centre), scaled to [-1, 1] (``align_corners=False``).
    Written out in numpy: ``affine_grid`` and torch's small ops cost ~20x more here,
    and the grid needs no gradient.
    """
    rows, cols = shape
    half_w, half_h = cols / 2.0, rows / 2.0
    x = ((2 * np.arange(cols) + 1) / cols - 1).reshape(1, 1, -1)
    y = ((2 * np.arange(rows) + 1) / rows - 1).reshape(1, -1, 1)
    c = np.cos(rotation_rad).reshape(-1, 1, 1)
    s = np.sin(rotation_rad).reshape(-1, 1, 1)
    sy = shift_texels[:, 0].reshape(-1, 1, 1)
    sx = shift_texels[:, 1].reshape(-1, 1, 1)
    x_in = c * x + s * (half_h / half_w) * y - (c * sx + s * sy) / half_w
    y_in = -s * (half_w / half_h) * x + c * y + (s * sx - c * sy) / half_h
    return np.stack(np.broadcast_arrays(x_in, y_in), axis=-1)


def place_masks(
    mask: torch.Tensor,
    shift_texels: np.ndarray,
    rotation_rad: np.ndarray,
    fill: float,
) -> torch.Tensor:
    """Each mask shifted and rotated about its centre, bilinear resampling (torch).

    ``out[k](p) = mask[k](R(-phi_k) (p - s_k))`` about the mask centre, in texel
    units (rows down, columns right), so a positive column shift moves the
    pattern right and an integer shift is a roll with the border entering.

    Args:
        mask: transmittance ``M[pixel, row, col]``.
        shift_texels: ``[pixel, 2]`` displacement in texels (rows down, columns right; numpy).
        rotation_rad: ``[pixel]`` rotation (rad), clockwise as seen from the camera (numpy).
        fill: transmittance outside the design (the printed border).

    Returns:
        The placed masks, same shape; differentiable in ``mask``.

    """
    grid = sampling_grid(
        (mask.shape[1], mask.shape[2]), np.asarray(shift_texels), np.asarray(rotation_rad)
    )
    out = F.grid_sample(
        (mask - fill).unsqueeze(1),
        torch.as_tensor(grid, dtype=mask.dtype, device=mask.device),
        mode="bilinear",
        padding_mode="zeros",
        align_corners=False,
    )
    return out.squeeze(1) + fill


class _BilinearSplat(torch.autograd.Function):
    """The adjoint of ``grid_sample`` (bilinear, border, ``align_corners=False``).

    ``values[n, c, p]`` spread onto the texels they would be sampled from at
    ``grid[n, p]``: one fused kernel (``grid_sample``'s own input gradient),
    and its backward is ``grid_sample`` itself. The output has ``values``'
    shape (the moved and the rendered texels are the same grid).
    """

    @staticmethod
    def forward(ctx: Any, values: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(grid)
        # "input" only gives the output's shape: no input gradient of the grid is asked
        out, _ = torch.ops.aten.grid_sampler_2d_backward(
            values, values, grid, 0, 1, False, [True, False]
        )
        return out

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (grid,) = ctx.saved_tensors
        pulled = F.grid_sample(
            grad, grid, mode="bilinear", padding_mode="border", align_corners=False
        )
        return pulled, None


def posed_masks(mask: torch.Tensor, warp: PoseWarp) -> torch.Tensor:
    """The effective masks ``M_eff[pixel, row, col]`` of a camera off its pose (torch).

    ``M_eff = splat(G M, warp.grid) / G`` for every pixel at once (one fused
    kernel each way): linear and differentiable in ``mask``.
    """
    dtype, device = mask.dtype, mask.device
    source = torch.as_tensor(warp.angular_weight * warp.ahead, dtype=dtype, device=device)
    grid = torch.as_tensor(warp.grid, dtype=dtype, device=device).unsqueeze(0)
    out = _BilinearSplat.apply((mask * source).unsqueeze(0), grid)
    return out.squeeze(0) * torch.as_tensor(1.0 / warp.angular_weight, dtype=dtype, device=device)


def fabricated_transmittance(
    logits: torch.Tensor,
    transmittance_range: tuple[float, float],
    draw: PerturbationDraw,
    texel_size_m: tuple[float, float],
    camera: FreeformCamera | None = None,
) -> torch.Tensor:
    """Transmittance ``M[pixel, row, col]`` of the masks as built (steps 1-6 above; torch).

    With a pose error, the effective masks (``M_eff`` of :mod:`~mincam_render.optics.pose`)
    that measure the rendered transport as the moved camera would.

    Args:
        logits: ``M_t[pixel, row, col]`` mask logits.
        transmittance_range: nominal printable ``(lo, hi)``.
        draw: the built camera; ``draw.num_pixels`` must equal the number of masks.
        texel_size_m: ``(rows, cols)`` texel size (m).
        camera: the camera's geometry; needed only when the draw has a pose error.

    Returns:
        ``M[pixel, row, col]``, equal to the nominal transmittance for an identity draw.

    Raises:
        ValueError: the draw is for another number of pixels, or has a pose
            error and no camera was given.

    """
    if draw.num_pixels != logits.shape[0]:
        raise ValueError(
            f"the perturbation draw is for {draw.num_pixels} pixels; the camera has "
            f"{logits.shape[0]} masks"
        )
    if draw.has_pose_error and camera is None:
        raise ValueError("a draw with a camera pose error needs the camera's geometry")
    y = print_tone(torch.sigmoid(logits), draw.gamma, draw.dot_gain)
    lo, hi = draw.transmittance_range(transmittance_range)
    m = lo + (hi - lo) * y
    texel_mm = (texel_size_m[0] / MM, texel_size_m[1] / MM)
    if draw.blur_sigma_mm > 0:
        m = blur_mask(m, (draw.blur_sigma_mm / texel_mm[0], draw.blur_sigma_mm / texel_mm[1]), lo)
    if draw.shift_mm.any() or draw.rotation_deg.any():
        m = place_masks(m, draw.shift_mm / texel_mm, np.radians(draw.rotation_deg), lo)
    if draw.has_pose_error and camera is not None:
        rot, off, depth = draw.pose_rotation_deg, draw.pose_offset_cm * CM, draw.pose_depth_m
        m = posed_masks(m, pose_warp(camera, rot, off, depth))
    return m
