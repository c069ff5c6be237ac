"""Camera pose error in the mask plane: geometry, closed forms, gradients, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from mincam_render.optics.camera import MM, DetectorLayout, DirectionalResponse, FreeformCamera
from mincam_render.optics.fabrication import fabricated_transmittance, place_masks, posed_masks
from mincam_render.optics.maskplane import transmittance
from mincam_render.optics.perturbation import CM, DEG, PerturbationDraw, PerturbationModel
from mincam_render.optics.pose import (
    angular_weight,
    content_homography,
    pose_warp,
    posed_camera,
    texel_directions,
)

RANGE = (0.01, 0.67)


def _camera(res: int = 8, **kw: object) -> FreeformCamera:
    return FreeformCamera(
        mask_resolution=(res, res),
        layout=DetectorLayout(positions_m=((0.0, 0.0),)),
        position=(1.0, 2.0, 1.5),
        look_at=(3.0, 5.0, 1.0),
        up=(0.0, 0.0, 1.0),
        **kw,  # type: ignore[arg-type]
    )


def _pose(rotation_deg=(0.0, 0.0, 0.0), offset_cm=(0.0, 0.0, 0.0), depth_m=2.0, k=1):
    return dataclasses.replace(
        PerturbationDraw.identity(k),
        pose_rotation_rad=np.asarray(rotation_deg, float) * DEG,
        pose_offset_m=np.asarray(offset_cm, float) * CM,
        pose_depth_m=depth_m,
    )


def _tangent(cam: FreeformCamera, row_col: tuple[float, float]) -> np.ndarray:
    """Tangent coordinates of a point given as ``project_to_texel``'s (row, col)."""
    row, col = row_col
    d, (th, tw), w = cam.mask_distance_m, cam.texel_size_m, cam.mask_size_m
    return np.array([(col * tw - 0.5 * w) / d, (0.5 * w - row * th) / d])


@pytest.mark.parametrize(
    ("rotation_deg", "offset_m", "depths"),
    [
        ((3.0, -2.0, 5.0), (0.0, 0.0, 0.0), (0.5, 2.0, 40.0)),  # a rotation: any depth
        ((0.0, 0.0, 0.0), (0.02, -0.01, 0.03), (2.5,)),
        ((1.5, 2.0, -4.0), (-0.02, 0.015, -0.02), (2.5,)),
    ],
)
def test_the_homography_maps_what_the_moved_camera_sees_to_where_the_design_saw_it(
    rotation_deg, offset_m, depths, rng
):
    """Against the camera's own projection: a moved camera built independently."""
    cam = _camera(32)
    moved = posed_camera(cam, np.radians(rotation_deg), offset_m)
    right, up, fwd = cam.frame
    for depth in depths:
        h = content_homography(np.radians(rotation_deg), offset_m, depth if any(offset_m) else 2.5)
        for a, b in rng.uniform(-0.5, 0.5, (6, 2)):
            x = np.asarray(cam.position) + depth * (fwd + a * right + b * up)
            q = _tangent(cam, cam.project_to_texel(x, 0))
            p = _tangent(moved, moved.project_to_texel(x, 0))
            mapped = h @ np.array([p[0], p[1], 1.0])
            np.testing.assert_allclose(mapped[:2] / mapped[2], q, rtol=0, atol=1e-12)


def test_pan_turns_the_view_right_tilt_up_and_roll_clockwise():
    cam = _camera()
    right, up, fwd = cam.frame
    panned = posed_camera(cam, (10.0 * DEG, 0.0, 0.0), (0.0, 0.0, 0.0)).frame
    assert np.dot(panned[2], right) == pytest.approx(np.sin(np.radians(10.0)))
    tilted = posed_camera(cam, (0.0, 10.0 * DEG, 0.0), (0.0, 0.0, 0.0)).frame
    assert np.dot(tilted[2], up) == pytest.approx(np.sin(np.radians(10.0)))
    rolled = posed_camera(cam, (0.0, 0.0, 10.0 * DEG), (0.0, 0.0, 0.0)).frame
    assert np.dot(rolled[1], right) == pytest.approx(np.sin(np.radians(10.0)))
    moved = posed_camera(cam, (0.0, 0.0, 0.0), (0.01, 0.02, 0.03))
    np.testing.assert_allclose(
        np.subtract(moved.position, cam.position), 0.01 * right + 0.02 * up + 0.03 * fwd
    )


def test_a_draw_without_pose_error_is_exactly_the_design(rng):
    cam = _camera()
    logits = torch.from_numpy(rng.normal(0, 2, (1, 8, 8)))
    draw = PerturbationModel().only("pose_orientation").scaled(0.0).draw(1, rng)
    assert not draw.has_pose_error
    m = fabricated_transmittance(logits, RANGE, draw, cam.texel_size_m, camera=cam)
    assert torch.equal(m, transmittance(logits, RANGE))


@pytest.mark.parametrize("response", [None, ((0.0, 30.0, 60.0, 90.0), (1.0, 0.95, 0.7, 0.2))])
@pytest.mark.parametrize(
    ("rotation_deg", "offset_cm"),
    [((2.0, -1.0, 3.0), (0.0, 0.0, 0.0)), ((-3.0, 2.0, 0.5), (2.0, -1.5, 2.0))],
)
def test_a_uniform_scene_measures_the_same_from_any_pose(rotation_deg, offset_cm, response, rng):
    """Uniform radiance, T = L G: every pose sees the same, so every measurement is unchanged.

    Exact even where the moved camera sees beyond the rendered field (the border
    stands in for it, and a uniform scene's border is the scene).
    """
    dr = (
        None
        if response is None
        else DirectionalResponse(angles_deg=response[0], relative_sensitivity=response[1])
    )
    cam = _camera(16, directional_response=dr)
    g = angular_weight(cam, *texel_directions(cam))
    mask = torch.from_numpy(rng.uniform(0.01, 0.67, (2, 16, 16)))
    warp = pose_warp(cam, np.radians(rotation_deg), np.asarray(offset_cm) * CM, 2.0)
    assert warp.extrapolated_fraction() > 0.01
    t = torch.from_numpy(g)
    moved = (posed_masks(mask, warp) * t).sum(dim=(1, 2))
    torch.testing.assert_close(moved, (mask * t).sum(dim=(1, 2)), rtol=1e-12, atol=0)


def test_a_quarter_roll_rotates_every_mask_like_a_quarter_turn_of_the_mask(rng):
    """Roll 90 deg (clockwise from the camera) = every mask turned clockwise by 90 deg."""
    cam = _camera(6)
    mask = torch.from_numpy(rng.uniform(0.1, 0.6, (3, 6, 6)))
    warp = pose_warp(cam, (0.0, 0.0, np.pi / 2), np.zeros(3), 2.0)
    assert warp.extrapolated_fraction() == 0.0  # the square field maps onto itself
    expected = torch.rot90(mask, k=-1, dims=(1, 2))
    torch.testing.assert_close(posed_masks(mask, warp), expected, rtol=0, atol=1e-12)
    torch.testing.assert_close(
        place_masks(mask, np.zeros((3, 2)), np.full(3, np.pi / 2), fill=0.0), expected
    )
    # a transport symmetric under the quarter turn measures exactly as designed
    t = torch.from_numpy(rng.uniform(0, 1, (6, 6)))
    t = t + t.rot90(1) + t.rot90(2) + t.rot90(3)
    torch.testing.assert_close(
        (posed_masks(mask, warp) * t).sum(dim=(1, 2)),
        (mask * t).sum(dim=(1, 2)),
        rtol=1e-14,
        atol=0,
    )


def test_a_sideways_move_of_one_texel_at_the_plane_depth_shifts_the_content_one_texel(rng):
    """Camera moved right: content at the plane slides left; closed form with its weights."""
    cam = _camera(8)
    depth = 2.0
    offset = cam.texel_size_m[1] / cam.mask_distance_m * depth  # one texel at the plane
    warp = pose_warp(cam, np.zeros(3), (offset, 0.0, 0.0), depth)
    mask = torch.from_numpy(rng.uniform(0.1, 0.6, (1, 8, 8)))
    g = torch.from_numpy(angular_weight(cam, *texel_directions(cam)))
    expected = torch.zeros_like(mask)
    # the moved camera's texel p sees what the design saw one texel to the right
    expected[0, :, 1:] = mask[0, :, :-1] * g[:, :-1] / g[:, 1:]
    expected[0, :, -1] += mask[0, :, -1]  # beyond the field: the border column stands in
    torch.testing.assert_close(posed_masks(mask, warp), expected, rtol=1e-12, atol=1e-14)
    share = float(g[:, -1].sum() / g.sum())
    assert warp.extrapolated_fraction() == pytest.approx(share, rel=1e-12)


def test_the_guessed_share_grows_with_the_angle():
    cam = _camera(32)
    shares = [
        pose_warp(cam, (a * DEG, 0.0, 0.0), np.zeros(3), 2.0).extrapolated_fraction()
        for a in (0, 1, 2, 4)
    ]
    assert shares[0] == pytest.approx(0.0, abs=1e-12)
    assert all(b > a for a, b in zip(shares, shares[1:], strict=False))
    # a 2-deg pan: a strip ~ d tan(2 deg) (1/cos^2 at the edge) wide along one edge
    assert 0.02 < shares[2] < 0.08


def test_gradient_through_a_camera_off_its_pose_matches_central_differences(rng):
    cam = _camera(6)
    logits = torch.from_numpy(rng.normal(0, 2, (2, 6, 6))).requires_grad_(True)
    draw = dataclasses.replace(
        _pose((1.5, -2.0, 3.0), (1.0, -2.0, 1.5), k=2),
        shift_m=np.array([[0.31, -0.17], [-0.4, 0.2]]) * MM,
        rotation_rad=np.radians([3.0, -1.5]),
        blur_sigma_m=0.4 * MM,
        gamma=0.8,
    )
    weights = torch.from_numpy(rng.normal(size=(2, 6, 6)))

    def f(x: torch.Tensor) -> torch.Tensor:
        m = fabricated_transmittance(x, RANGE, draw, cam.texel_size_m, camera=cam)
        return (m * weights).sum()

    assert torch.autograd.gradcheck(f, (logits,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_the_camera_model_measures_through_its_pose(rng):
    from support import linear_task

    from mincam_render.learn import train as tr

    data = linear_task(n=20, k=2)
    model = tr.build_mincam(data, 2)
    t = torch.from_numpy(data.transport)
    nominal = model.measure(t, noise=False)
    moved = model.measure(t, noise=False, draw=_pose((2.0, 1.0, 0.0), k=2))
    assert not torch.allclose(moved, nominal, rtol=1e-3)
    assert torch.equal(model.measure(t, noise=False, draw=_pose(k=2)), nominal)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pose_rotation_rad": [1.0, 2.0]}, "PerturbationDraw.pose_rotation_rad"),
        ({"pose_offset_m": [0.0, np.nan, 0.0]}, "PerturbationDraw.pose_offset_m"),
        ({"pose_depth_m": 0.0}, "pose_depth_m"),
    ],
)
def test_bad_pose_draws_are_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(PerturbationDraw.identity(1), **kwargs)


def test_a_pose_error_needs_the_camera_and_a_depth_in_front():
    draw = _pose((1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="camera's geometry"):
        fabricated_transmittance(torch.zeros(1, 8, 8), RANGE, draw, (0.5 * MM, 0.5 * MM))
    with pytest.raises(ValueError, match="reaches the depth"):
        pose_warp(_camera(), np.zeros(3), (0.0, 0.0, 2.0), 2.0)
    with pytest.raises(ValueError, match="3 finite angles"):
        posed_camera(_camera(), (1.0, 2.0), np.zeros(3))


def test_a_uniform_depth_map_is_the_plane_and_a_rotation_ignores_depth(rng):
    cam = _camera(8)
    off = np.array([0.02, -0.01, 0.015])
    plane = pose_warp(cam, np.zeros(3), off, 2.0)
    mapped = pose_warp(cam, np.zeros(3), off, np.full((8, 8), 2.0))
    np.testing.assert_allclose(plane.grid, mapped.grid, rtol=0, atol=1e-12)
    rot = np.radians((1.5, -2.0, 3.0))
    depths = rng.uniform(0.5, 8.0, (8, 8))
    a, b = pose_warp(cam, rot, np.zeros(3), 2.0), pose_warp(cam, rot, np.zeros(3), depths)
    np.testing.assert_allclose(a.grid, b.grid, rtol=0, atol=1e-12)
    far = pose_warp(cam, np.zeros(3), off, np.full((8, 8), np.inf))  # nothing near: no parallax
    np.testing.assert_allclose(far.grid, pose_warp(cam, np.zeros(3), np.zeros(3), 2.0).grid)
    with pytest.raises(ValueError, match="depth map"):
        pose_warp(cam, np.zeros(3), off, np.full((4, 4), 2.0))
    with pytest.raises(ValueError, match="depth map"):
        pose_warp(cam, np.zeros(3), off, np.full((8, 8), 0.01))  # behind the forward offset


def test_the_depth_map_of_a_tilted_wall_is_its_closed_form(variant):
    """A wall ``z = 3 + 0.5 y`` in front of a camera looking along +z: depth 3 / (1 - b/2)."""
    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.render.fidelity import depth_map_m, nearest_depth_m

    cam = FreeformCamera(mask_resolution=(8, 8), layout=DetectorLayout(positions_m=((0.0, 0.0),)))
    # front facing the point (0, 0.5, 2): normal (0, 0.5, -1)
    wall = ms.rectangle((0.0, 0.0, 3.0), (0.0, 0.5, 2.0), (20.0, 20.0), radiance_w_m2_sr=1.0)
    scene = ms.load_scene(ms.scene_dict({"wall": wall}, max_depth=1))
    _, b = texel_directions(cam)
    depth = depth_map_m(scene, cam)
    np.testing.assert_allclose(depth, 3.0 / (1.0 - 0.5 * b), rtol=1e-5)
    near = nearest_depth_m(scene, cam)
    assert near["min"] < 3.0 < near["max"]
