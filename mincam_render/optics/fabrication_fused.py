r"""The fabricated mask plane as one autograd node: robust training's hot path (torch).

:func:`~mincam_render.optics.fabrication.fabricated_transmittance` composes the
steps of the fabricated mask plane (tone, printed range, blur, mount, pose) out
of about 25 small torch ops, each its own autograd node, on masks of a few
thousand texels: a robust step's time went to per-op and per-node overhead, not
arithmetic. :func:`fused_fabricated_transmittance` makes the same masks (equal
to float rounding, checked against the composition and by finite differences
in ``tests/physics/test_fabrication_fused.py``) as one node with a hand-written
backward. Everything after the tone curve is linear in the printed fraction, so
with ``x = M - lo'``:

.. math::

    x = (hi' - lo')\,\bigl((1 - 4g)\,y + 4g\,y^2\bigr), \quad y = \sigma(M_t)^\gamma,
    \qquad M_{eff} = \frac{1}{G}\,\mathrm{splat}\bigl(G_a\,(P_k B_r x B_c + lo')\bigr)

(:func:`~mincam_render.optics.fabrication.print_tone` multiplied out, ``g`` the
dot gain; ``B`` the blur matrices, ``P_k`` the mount's bilinear resampling with
the border at ``lo'``, ``G_a = G`` where the content is ahead, else 0). The
forward is the tone's 2-6 ops and 2-4 per step taken; the backward the adjoints
in reverse (the splat's is ``grid_sample``, the resampling's is its input
gradient, the blur's the transposed matrices) times the tone's derivative
``dx/dM_t = (hi' - lo')\,\gamma\,y\,(1 - \sigma)\,(1 - 4g + 8g\,y)``. The
per-draw constants (blur matrices, both sampling grids) are built in numpy; the
angular weights are cached per camera.

The mount and the pose stay two resamplings: a bilinear lookup followed by a
bilinear splat is no single bilinear lookup, so one composed sampling grid
would change the measurement.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch.autograd.function import once_differentiable

from mincam_render.optics.camera import FreeformCamera
from mincam_render.optics.fabrication import (
    check_draw,
    gaussian_matrix,
    sampling_grid,
)
from mincam_render.optics.perturbation import PerturbationDraw
from mincam_render.optics.pose import angular_weight, pose_warp, texel_directions

#: ``grid_sampler_2d`` codes: bilinear interpolation; zero and border padding.
_BILINEAR, _ZEROS, _BORDER = 0, 0, 1
#: ``grid_sample``'s input gradient: the splat (adjoint of the bilinear lookup).
_GRID_SAMPLE_BACKWARD = torch.ops.aten.grid_sampler_2d_backward.default


@dataclass(frozen=True)
class _Plan:
    """One draw's constants of the mask plane (torch, in the logits' dtype and device).

    ``blur``: ``(B_rows, B_cols^T)`` (symmetric); ``mount``: ``grid[pixel, row, col, 2]``;
    ``pose``: ``(grid[1, row, col, 2], G_a, 1 / G)``. None where the step is
    skipped (its drawn value is exactly zero).
    """

    lo: float
    span: float
    gamma: float
    dot_gain: float
    blur: tuple[torch.Tensor, torch.Tensor] | None
    mount: torch.Tensor | None
    pose: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None


#: numpy's dtype of each torch dtype whose constants cross by ``torch.from_numpy``.
_NUMPY_DTYPES = {torch.float32: np.float32, torch.float64: np.float64}


def _to_torch(array: np.ndarray, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """``array`` (numpy float64) in ``dtype`` on ``device``: a copy, writable."""
    np_dtype = _NUMPY_DTYPES.get(dtype)
    if device.type == "cpu" and np_dtype is not None:
        # ~3x cheaper than torch.as_tensor with a dtype (measured, 2 KB arrays)
        return torch.from_numpy(array.astype(np_dtype))
    return torch.as_tensor(array, dtype=dtype, device=device)


@functools.lru_cache(maxsize=8)
def _angular_weights(
    camera: FreeformCamera, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(G, 1 / G)`` of the camera's texels (torch; cached: every draw of a run shares them)."""
    g = angular_weight(camera, *texel_directions(camera))
    return _to_torch(g, dtype, device), _to_torch(1.0 / g, dtype, device)


def _pose_constants(
    camera: FreeformCamera, draw: PerturbationDraw, dtype: torch.dtype, device: torch.device
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(grid[1, row, col, 2], G_a, 1 / G)`` of the draw's camera pose (torch)."""
    warp = pose_warp(camera, draw.pose_rotation_rad, draw.pose_offset_m, draw.pose_depth_m)
    g, inverse_g = _angular_weights(camera, dtype, device)
    if not warp.ahead.all():  # content behind the designed camera: dropped
        g = _to_torch(warp.angular_weight * warp.ahead, dtype, device)
    return _to_torch(warp.grid[None], dtype, device), g, inverse_g


def _plan(
    logits: torch.Tensor,
    transmittance_range: tuple[float, float],
    draw: PerturbationDraw,
    texel_size_m: tuple[float, float],
    camera: FreeformCamera | None,
) -> _Plan:
    """The :class:`_Plan` of ``draw`` for masks like ``logits`` (constants built in numpy)."""
    lo, hi = draw.transmittance_range(transmittance_range)
    rows, cols = logits.shape[1:]
    dtype, device = logits.dtype, logits.device
    blur = mount = pose = None
    if draw.blur_sigma_m > 0:
        sigma = (draw.blur_sigma_m / texel_size_m[0], draw.blur_sigma_m / texel_size_m[1])
        b_rows = _to_torch(gaussian_matrix(rows, sigma[0]), dtype, device)
        # B_cols^T = B_cols: the matrices are symmetric; square texels share one
        same = sigma[0] == sigma[1] and rows == cols
        b_cols = b_rows if same else _to_torch(gaussian_matrix(cols, sigma[1]), dtype, device)
        blur = (b_rows, b_cols)
    if draw.shift_m.any() or draw.rotation_rad.any():
        shift_texels = draw.shift_m / np.asarray(texel_size_m)
        grid = sampling_grid((rows, cols), shift_texels, draw.rotation_rad)
        mount = _to_torch(grid, dtype, device)
    if camera is not None and draw.has_pose_error:
        pose = _pose_constants(camera, draw, dtype, device)
    return _Plan(lo, hi - lo, float(draw.gamma), float(draw.dot_gain), blur, mount, pose)


def _splat(values: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """Adjoint of bilinear ``grid_sample`` (border padding): ``values[1, c, r, q]`` spread."""
    # "input" only gives the output's shape: no gradient of the grid is asked
    out, _ = _GRID_SAMPLE_BACKWARD(values, values, grid, _BILINEAR, _BORDER, False, [True, False])
    return out


class _FabricatedMaskPlane(torch.autograd.Function):
    """Logits -> the masks as built, one node (see the module docstring)."""

    @staticmethod
    def forward(ctx: Any, logits: torch.Tensor, plan: _Plan) -> torch.Tensor:
        k, rows, cols = logits.shape
        s = y = torch.sigmoid(logits)
        if plan.gamma != 1.0:  # as print_tone (pow is slower at 16 masks); s = 0 gives 0
            y = torch.exp(torch.log(s) * plan.gamma)
        g4 = 4.0 * plan.dot_gain
        x = y * (plan.span * (1.0 - g4))
        if g4 != 0.0:
            x = torch.addcmul(x, y, y, value=plan.span * g4)
        if plan.blur is not None:
            x = plan.blur[0] @ x @ plan.blur[1]
        if plan.mount is not None:
            x = x.view(k, 1, rows, cols)
            x = torch.grid_sampler_2d(x, plan.mount, _BILINEAR, _ZEROS, False)
        ctx.save_for_backward(s, y)
        ctx.plan = plan
        if plan.pose is None:
            return (x + plan.lo).view(k, rows, cols)
        grid, source, inverse_weight = plan.pose
        spread = _splat(x.add(plan.lo).mul_(source).view(1, k, rows, cols), grid)
        return spread.view(k, rows, cols) * inverse_weight

    @staticmethod
    @once_differentiable
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        plan: _Plan = ctx.plan
        k, rows, cols = grad.shape
        if plan.pose is not None:
            grid, source, inverse_weight = plan.pose
            pulled = torch.grid_sampler_2d(
                (grad * inverse_weight).view(1, k, rows, cols), grid, _BILINEAR, _BORDER, False
            )
            grad = pulled.view(k, rows, cols).mul_(source)
        if plan.mount is not None:
            g = grad.view(k, 1, rows, cols)
            g, _ = _GRID_SAMPLE_BACKWARD(g, g, plan.mount, _BILINEAR, _ZEROS, False, [True, False])
            grad = g.view(k, rows, cols)
        if plan.blur is not None:  # the blur matrices are symmetric: their own adjoints
            grad = plan.blur[0] @ grad @ plan.blur[1]
        return grad * _tone_slope(ctx, plan), None


def _tone_slope(ctx: Any, plan: _Plan) -> torch.Tensor:
    """``dx/dM_t = span gamma y (1 - s) (1 - 4g + 8g y)`` of the forward's saved tensors."""
    s, y = ctx.saved_tensors
    scale = plan.span * plan.gamma
    slope = torch.rsub(s, 1.0).mul_(y)
    if plan.dot_gain == 0.0:
        return slope.mul_(scale)
    g4 = 4.0 * plan.dot_gain
    return torch.addcmul(slope * ((1.0 - g4) * scale), slope, y, value=2.0 * g4 * scale)


def fused_fabricated_transmittance(
    logits: torch.Tensor,
    transmittance_range: tuple[float, float],
    draw: PerturbationDraw,
    texel_size_m: tuple[float, float],
    camera: FreeformCamera | None = None,
) -> torch.Tensor:
    """:func:`~mincam_render.optics.fabrication.fabricated_transmittance` as one autograd node.

    Same arguments, result (to float rounding; exactly where only the printed
    range differs) and errors; differentiable once in ``logits`` (no double backward).
    """
    check_draw(logits, draw, camera)
    plan = _plan(logits, transmittance_range, draw, texel_size_m, camera)
    return _FabricatedMaskPlane.apply(logits, plan)
