"""The fused mask plane (one autograd node) against the step-by-step reference composition."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from mincam_render.optics.camera import DetectorLayout, DirectionalResponse, FreeformCamera
from mincam_render.optics.fabrication import fabricated_transmittance
from mincam_render.optics.fabrication_fused import fused_fabricated_transmittance
from mincam_render.optics.maskplane import transmittance
from mincam_render.optics.perturbation import (
    PerturbationDraw,
    PerturbationModel,
    PerturbationTerm,
)

RANGE = (0.01, 0.67)


def _camera(shape: tuple[int, int] = (12, 12), **kw: object) -> FreeformCamera:
    return FreeformCamera(
        mask_resolution=shape,
        layout=DetectorLayout(positions_m=((0.0, 0.0),)),
        position=(1.0, 2.0, 1.5),
        look_at=(3.0, 5.0, 1.0),
        up=(0.0, 0.0, 1.0),
        **kw,  # type: ignore[arg-type]
    )


def _values_and_gradients(fn, logits, draw, cam, weights):
    """``fn``'s masks and the gradient of ``sum(M * weights)`` in the logits."""
    x = logits.detach().clone().requires_grad_(True)
    m = fn(x, RANGE, draw, cam.texel_size_m, camera=cam)
    (m * weights).sum().backward()
    return m.detach(), x.grad


def _compare(draw, cam, rng, dtype, k):
    rows, cols = cam.mask_resolution
    logits = torch.from_numpy(rng.normal(0, 3, (k, rows, cols))).to(dtype)
    weights = torch.from_numpy(rng.normal(size=(k, rows, cols))).to(dtype)
    ref = _values_and_gradients(fabricated_transmittance, logits, draw, cam, weights)
    fused = _values_and_gradients(fused_fabricated_transmittance, logits, draw, cam, weights)
    # float64: rounding of a few dozen ops; float32: the reference's own rounding
    tol = {"rtol": 1e-12, "atol": 1e-14} if dtype == torch.float64 else {"rtol": 2e-5, "atol": 2e-6}
    torch.testing.assert_close(fused[0], ref[0], **tol)
    torch.testing.assert_close(fused[1], ref[1], **tol)


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32], ids=["f64", "f32"])
@pytest.mark.parametrize("scale", [1.0, 2.5])
def test_fused_masks_and_gradients_equal_the_reference_on_random_draws(dtype, scale, rng):
    cam = _camera()
    model = PerturbationModel().scaled(scale)  # 2.5: dot gain at its bound 0.25
    for _ in range(6):
        _compare(model.draw(3, rng), cam, rng, dtype, k=3)


@pytest.mark.parametrize("term", list(PerturbationTerm), ids=lambda t: t.value)
def test_each_term_alone_fused_equals_the_reference(term, rng):
    """Every skipped-step branch of the node (gamma 1, no dot gain, no blur, ...)."""
    cam = _camera((10, 7))  # rows != cols: two blur matrices
    draw = PerturbationModel().scaled(2.5).only(term).draw(2, rng)
    _compare(draw, cam, rng, torch.float64, k=2)


@pytest.mark.parametrize("dot_gain", [-0.25, 0.25])
@pytest.mark.parametrize("gamma", [0.3, 1.0, 1.9])
def test_extreme_tone_curves_fused_equals_the_reference(gamma, dot_gain, rng):
    draw = dataclasses.replace(PerturbationModel().draw(2, rng), gamma=gamma, dot_gain=dot_gain)
    _compare(draw, _camera(), rng, torch.float64, k=2)


def test_content_behind_the_camera_and_a_directional_response_fused_equals_the_reference(rng):
    """A wide view turned far: part of the moved view has no content ahead (dropped)."""
    response = DirectionalResponse(
        angles_deg=(0.0, 30.0, 60.0, 90.0), relative_sensitivity=(1.0, 0.9, 0.6, 0.2)
    )
    cam = _camera((9, 9), mask_distance_m=0.002, directional_response=response)
    draw = dataclasses.replace(
        PerturbationModel().draw(2, rng),
        pose_rotation_rad=np.radians([28.0, -25.0, 10.0]),
        pose_offset_m=np.array([0.03, -0.02, 0.05]),
    )
    from mincam_render.optics.pose import pose_warp

    warp = pose_warp(cam, draw.pose_rotation_rad, draw.pose_offset_m, draw.pose_depth_m)
    assert 0.0 < warp.ahead.mean() < 1.0
    _compare(draw, cam, rng, torch.float64, k=2)


def test_fused_gradient_matches_central_differences(rng):
    cam = _camera((6, 5))
    logits = torch.from_numpy(rng.normal(0, 2, (2, 6, 5))).requires_grad_(True)
    draw = PerturbationDraw(
        shift_m=[[0.31e-3, -0.17e-3], [-0.4e-3, 0.2e-3]],
        rotation_rad=np.radians([3.0, -1.5]),
        gamma=0.8,
        dot_gain=0.12,
        min_transmittance_error=0.003,
        max_transmittance_error=-0.04,
        blur_sigma_m=0.9e-3,
        pose_rotation_rad=np.radians([1.5, -2.0, 3.0]),
        pose_offset_m=[0.01, -0.02, 0.015],
    )
    weights = torch.from_numpy(rng.normal(size=(2, 6, 5)))

    def f(x: torch.Tensor) -> torch.Tensor:
        return (
            fused_fabricated_transmittance(x, RANGE, draw, cam.texel_size_m, cam) * weights
        ).sum()

    assert torch.autograd.gradcheck(f, (logits,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_an_identity_draw_is_exactly_the_nominal_transmittance(rng):
    logits = torch.from_numpy(rng.normal(0, 2, (3, 8, 8))).float()
    m = fused_fabricated_transmittance(
        logits, RANGE, PerturbationDraw.identity(3), _camera((8, 8)).texel_size_m
    )
    assert torch.equal(m, transmittance(logits, RANGE))


def test_the_fused_node_refuses_what_the_reference_refuses():
    cam = _camera((4, 4))
    with pytest.raises(ValueError, match="pixels"):
        fused_fabricated_transmittance(
            torch.zeros(2, 4, 4), RANGE, PerturbationDraw.identity(3), cam.texel_size_m
        )
    moved = dataclasses.replace(PerturbationDraw.identity(1), pose_rotation_rad=[0.02, 0.0, 0.0])
    with pytest.raises(ValueError, match="camera's geometry"):
        fused_fabricated_transmittance(torch.zeros(1, 4, 4), RANGE, moved, cam.texel_size_m)


def test_the_camera_model_measures_through_the_fused_node_as_through_the_reference(rng):
    from support import linear_task

    from mincam_render.learn import train as tr
    from mincam_render.optics.maskplane import power_through

    data = linear_task(n=30, k=3)
    model = tr.build_mincam(data, 3)
    t = torch.from_numpy(data.transport)
    draw = PerturbationModel().scaled(2.0).draw(3, rng)
    cam = model.camera
    ref_mask = fabricated_transmittance(
        model.logits, cam.transmittance_range, draw, cam.texel_size_m, camera=cam
    )
    assert torch.allclose(model.power(t, draw), power_through(t, ref_mask), rtol=1e-5, atol=0)
