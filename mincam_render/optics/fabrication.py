r"""The fabricated mask plane: a designed mask through the printer and the mount (torch).

From the mask logits ``M_t[pixel, row, col]`` and a
:class:`~mincam_render.optics.perturbation.PerturbationDraw`, in the order the
mask is made:

1. the design's place in the printable range, ``y = sigmoid(M_t)`` (0-1);
2. the printer's tone curve and dot gain (:func:`print_tone`):
   ``y' = 1 - c'`` with ``c = 1 - y^gamma`` the ink coverage and
   ``c' = c + 4 g c (1 - c)``;
3. the printed range: ``M = lo' + (hi' - lo') y'``;
4. the print's blur, a Gaussian of ``blur_sigma_m`` (:func:`blur_mask`);
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

import functools
import math
from typing import Any

import numpy as np
import torch
from torch.nn import functional as F

from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.perturbation import PerturbationDraw
from mincam_render.optics.pose import PoseWarp, pose_warp

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


@functools.lru_cache(maxsize=16)
def _distance_index(n: int, radius: int) -> np.ndarray:
    """``min(|i - j|, radius + 1)`` over ``[n, n]`` (numpy int, read-only; cached)."""
    d = np.minimum(np.abs(np.subtract.outer(np.arange(n), np.arange(n))), radius + 1)
    d.setflags(write=False)
    return d


def gaussian_matrix(n: int, sigma_texels: float) -> np.ndarray:
    """``B[n, n]`` (numpy): row ``i`` the normalised Gaussian around texel ``i`` (sigma > 0).

    Weights are normalised over the infinite line (3-sigma support), then cut to
    the ``n`` texels: what a blur takes from beyond the mask is the border's.
    Built in numpy, the taps looked up by texel distance: the blur's few taps
    cost microseconds, where the same in torch's small ops costs ~10x more per
    training step. Symmetric (``B[i, j] = taps[|i - j|]``).
    """
    radius = max(1, math.ceil(_KERNEL_SIGMAS * sigma_texels))
    # the few taps in plain floats: cheaper than numpy's calls for 3-7 numbers
    taps = [math.exp(-0.5 * (o / sigma_texels) ** 2) for o in range(radius + 1)]
    total = taps[0] + 2.0 * sum(taps[1:])
    by_distance = np.array([*taps, 0.0]) / total  # distance 0..radius, then beyond
    return by_distance[_distance_index(n, radius)]


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


@functools.lru_cache(maxsize=16)
def _texel_centres(shape: tuple[int, int]) -> np.ndarray:
    """``[row * col, (x, y, 1)]``: texel centres in ``grid_sample``'s units (read-only; cached)."""
    rows, cols = shape
    x = (2 * np.arange(cols) + 1) / cols - 1
    y = (2 * np.arange(rows) + 1) / rows - 1
    xx, yy = np.meshgrid(x, y)
    out = np.stack([xx.ravel(), yy.ravel(), np.ones(rows * cols)], axis=-1)
    out.setflags(write=False)
    return out


def sampling_grid(
    shape: tuple[int, int], shift_texels: np.ndarray, rotation_rad: np.ndarray
) -> np.ndarray:
    """``grid[pixel, row, col, (x, y)]`` of :func:`place_masks` in ``grid_sample``'s units (numpy).

    The sampling point ``R(-phi)(p - s)`` of each output texel centre ``p``
    (texel units about the mask centre), scaled to [-1, 1] (``align_corners=False``):
    an affine map of the texel centres per pixel, one matrix product. Written
    out in numpy: ``affine_grid`` and torch's small ops cost ~20x more here,
    and the grid needs no gradient.
    """
    rows, cols = shape
    hw, hh = cols / 2.0, rows / 2.0
    c, s = np.cos(rotation_rad), np.sin(rotation_rad)
    sy, sx = shift_texels[:, 0], shift_texels[:, 1]
    # x_in = c x + s (h/w) y - (c sx + s sy) / w;  y_in = -s (w/h) x + c y + (s sx - c sy) / h
    affine = np.stack(
        [c, -s * (hw / hh), s * (hh / hw), c, -(c * sx + s * sy) / hw, (s * sx - c * sy) / hh],
        axis=-1,
    ).reshape(-1, 3, 2)
    return (_texel_centres((rows, cols)) @ affine).reshape(-1, rows, cols, 2)


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


def check_draw(logits: torch.Tensor, draw: PerturbationDraw, camera: FreeformCamera | None) -> None:
    """ValueError unless ``draw`` is for these masks (and has a camera where it moves one)."""
    if draw.num_pixels != logits.shape[0]:
        raise ValueError(
            f"the perturbation draw is for {draw.num_pixels} pixels; the camera has "
            f"{logits.shape[0]} masks"
        )
    if draw.has_pose_error and camera is None:
        raise ValueError("a draw with a camera pose error needs the camera's geometry")


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
    return printed_transmittance(
        torch.sigmoid(logits), transmittance_range, draw, texel_size_m, camera
    )


def printed_transmittance(
    fraction: torch.Tensor,
    transmittance_range: tuple[float, float],
    draw: PerturbationDraw,
    texel_size_m: tuple[float, float],
    camera: FreeformCamera | None = None,
) -> torch.Tensor:
    """:func:`fabricated_transmittance` of designs given as their place in the printable range.

    Steps 2-6 above, for designs that are transmittances rather than logits
    (``fraction = (M - lo) / (hi - lo)``; the SURROGATE's printed masks).

    Args:
        fraction: ``y[pixel, row, col]``, the design's place in the nominal
            printable range, in [0, 1].
        transmittance_range: nominal printable ``(lo, hi)``.
        draw: the built camera; ``draw.num_pixels`` must equal the number of masks.
        texel_size_m: ``(rows, cols)`` texel size (m).
        camera: the camera's geometry; needed only when the draw has a pose error.

    Returns:
        ``M[pixel, row, col]``; ``lo + (hi - lo) y`` for an identity draw.

    Raises:
        ValueError: as :func:`fabricated_transmittance`.

    """
    check_draw(fraction, draw, camera)
    y = print_tone(fraction, draw.gamma, draw.dot_gain)
    lo, hi = draw.transmittance_range(transmittance_range)
    m = lo + (hi - lo) * y
    if draw.blur_sigma_m > 0:
        sigma = (draw.blur_sigma_m / texel_size_m[0], draw.blur_sigma_m / texel_size_m[1])
        m = blur_mask(m, sigma, lo)
    if draw.shift_m.any() or draw.rotation_rad.any():
        m = place_masks(m, draw.shift_m / np.asarray(texel_size_m), draw.rotation_rad, lo)
    if draw.has_pose_error and camera is not None:
        warp = pose_warp(camera, draw.pose_rotation_rad, draw.pose_offset_m, draw.pose_depth_m)
        m = posed_masks(m, warp)
    return m
