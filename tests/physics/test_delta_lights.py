"""Point, spot and directional lights seen straight through the mask (render/delta_lights.py).

References are computed on the detector (float64 Gauss-Legendre over the part of
the detector whose ray to the light crosses each texel), the integral the
paper writes; the renderer samples the mask instead, so the two meet only if
the change of variables, the texel the ray crosses and the weights are right.
"""

from __future__ import annotations

import math

import mitsuba as mi
import numpy as np
import pytest

from mincam_render.data.exr import write_transport_exr
from mincam_render.optics.camera import DetectorLayout, FreeformCamera
from mincam_render.optics.photodiode import s9119_01_response
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.delta_lights import delta_emitters
from mincam_render.render.mitsuba_scene import SceneError, load_scene
from mincam_render.render.transport import render_transport, render_transport_with_noise
from mincam_render.render.user_scene import check_transport

INTENSITY_W_SR = 10.0
DISTANCE_M = 0.5  # the point light, 0.5 m in front of the board
#: Gauss-Legendre nodes per side of each texel's preimage (smooth integrand:
#: 16 nodes reach float64 round-off)
N_GL = 16


def _camera(res: int, response: bool = False, layout: DetectorLayout | None = None):
    return FreeformCamera(
        mask_resolution=(res, res),
        layout=layout or DetectorLayout(positions_m=((0.0, 0.0),)),
        directional_response=s9119_01_response() if response else None,
    )


def _point(position, intensity=INTENSITY_W_SR) -> dict:
    return {
        "type": "point",
        "position": list(map(float, position)),
        "intensity": {"type": "rgb", "value": float(intensity)},
    }


def _spot(position, target, cutoff_deg, beam_deg, intensity=INTENSITY_W_SR) -> dict:
    return {
        "type": "spot",
        "to_world": mi.ScalarTransform4f().look_at(origin=position, target=target, up=[0, 1, 0]),
        "cutoff_angle": float(cutoff_deg),
        "beam_width": float(beam_deg),
        "intensity": {"type": "rgb", "value": float(intensity)},
    }


def _scene(**items) -> dict:
    return ms.scene_dict(items, max_depth=4)


def _f(cam: FreeformCamera, cos_theta: np.ndarray) -> np.ndarray:
    """The diode's directional response beyond Lambert (1 without one)."""
    if cam.directional_response is None:
        return np.ones_like(cos_theta)
    return cam.directional_response(np.arccos(np.clip(cos_theta, -1.0, 1.0)))


def _texel_edges(cam: FreeformCamera) -> tuple[np.ndarray, np.ndarray]:
    """Board-frame texel edges from the detector centre: s by column, t by row (t falls)."""
    rows, cols = cam.mask_resolution
    w = cam.mask_size_m
    return -w / 2 + np.arange(cols + 1) * w / cols, w / 2 - np.arange(rows + 1) * w / rows


def positional_reference(cam: FreeformCamera, light_m, intensity) -> np.ndarray:
    """``T[k, row, col]`` (W) of a point-like light, integrated over the detector.

    ``intensity(u)`` is the light's intensity (W/sr) toward unit vectors ``u``
    (from the light, shape (..., 3)). Texel edges map to the detector plane
    through the light, ``q = (x - p d / h) / (1 - d / h)``; on each preimage
    rectangle, ``I cos f / |p - q|^2`` is integrated with Gauss-Legendre.
    """
    right, up, fwd = cam.frame
    a, d = cam.detector_size_m, cam.mask_distance_m
    rows, cols = cam.mask_resolution
    s_edges, t_edges = _texel_edges(cam)
    nodes, weights = np.polynomial.legendre.leggauss(N_GL)
    out = np.zeros((cam.num_detectors, rows, cols))
    for k, centre in enumerate(cam.detector_centers_m):
        rel = np.asarray(light_m, dtype=np.float64) - centre
        h = rel @ fwd
        mu = 1.0 - d / h
        qs = np.clip((s_edges - (rel @ right) * d / h) / mu, -a / 2, a / 2)
        qt = np.clip((t_edges - (rel @ up) * d / h) / mu, -a / 2, a / 2)
        for r in range(rows):
            for c in range(cols):
                s0, s1, t0, t1 = qs[c], qs[c + 1], qt[r + 1], qt[r]
                if s1 <= s0 or t1 <= t0:
                    continue
                gs, gt = s0 + (s1 - s0) * (nodes + 1) / 2, t0 + (t1 - t0) * (nodes + 1) / 2
                q = centre + gs[:, None, None] * right + gt[None, :, None] * up
                v = np.asarray(light_m) - q
                r2 = np.sum(v * v, axis=-1)
                cos = (v @ fwd) / np.sqrt(r2)
                g = intensity(-v / np.sqrt(r2)[..., None]) * cos * _f(cam, cos) / r2
                out[k, r, c] = (s1 - s0) * (t1 - t0) / 4 * (weights @ g @ weights)
    return out


def directional_reference(cam: FreeformCamera, toward_light, irradiance) -> np.ndarray:
    """``T[k, row, col]`` (W) of a directional light: exact, ``E cos f`` times overlap areas.

    The detector square, shifted by ``d tan(theta)`` along the light's lateral
    direction, overlaps each texel in a rectangle; the integrand is constant.
    """
    right, up, fwd = cam.frame
    s = np.asarray(toward_light, dtype=np.float64)
    s /= np.linalg.norm(s)
    a, d = cam.detector_size_m, cam.mask_distance_m
    cos = s @ fwd
    cs, ct = (s @ right) * d / cos, (s @ up) * d / cos
    s_edges, t_edges = _texel_edges(cam)
    ds = np.clip(np.minimum(s_edges[1:], cs + a / 2) - np.maximum(s_edges[:-1], cs - a / 2), 0, a)
    dt = np.clip(np.minimum(t_edges[:-1], ct + a / 2) - np.maximum(t_edges[1:], ct - a / 2), 0, a)
    per_texel = irradiance * cos * float(_f(cam, np.array(cos))) * np.outer(dt, ds)
    return np.broadcast_to(per_texel, (cam.num_detectors, *per_texel.shape))


def _compare(t: np.ndarray, expected: np.ndarray, tmp_path, rtol: float, what: str) -> None:
    """Per texel within ``rtol`` of the largest expected texel; totals within ``rtol``."""
    scale = float(np.abs(expected).max())
    ok = np.allclose(t, expected, rtol=0.0, atol=rtol * scale) and np.allclose(
        t.sum(axis=(1, 2)), expected.sum(axis=(1, 2)), rtol=rtol
    )
    if not ok:
        write_transport_exr(tmp_path / "T.exr", t, {"case": what})
        write_transport_exr(tmp_path / "expected.exr", expected.astype(np.float32), {})
        pytest.fail(
            f"{what}: totals {t.sum(axis=(1, 2))} vs {expected.sum(axis=(1, 2))} W; worst texel "
            f"off by {np.abs(t - expected).max() / scale:.2e} of the largest (see {tmp_path})"
        )


@pytest.mark.parametrize("response", [False, True], ids=["cosine", "S9119-01"])
@pytest.mark.parametrize("res", [5, 32])
def test_point_light_on_axis_matches_the_solid_angle_of_the_detector(
    variant, tmp_path, res, response
):
    """(a) ``P = I Omega f``: ``Omega``, the detector's solid angle seen from the light,
    all in the centre texel (odd mask) or a quarter in each of the four around
    the axis (even mask).

    The issue's ``I A cos_q cos_x / r^2`` is the small-detector limit: on axis it
    differs from the exact ``I Omega`` by ``(3/2) (a/2r)^2 = 1.2e-6``. The rays
    reach the diode within 0.071 deg of its normal, where the S9119-01's ``f``
    rises from f(0) = 0.99444 by 0.0018 per degree: ``P = I Omega f(0)`` within
    1.3e-4 (exactly: the detector integral). The sampling error is that of
    ``E cos f`` over the footprint (relative spread ~1e-6), so float32 rounding
    sets the tolerance (1e-4).
    """
    cam = _camera(res, response=response)
    t = render_transport(_scene(lamp=_point((0, 0, DISTANCE_M))), cam, spp=16, seed=0)
    alpha = cam.detector_size_m / 2
    omega = 4 * math.asin(alpha**2 / (alpha**2 + DISTANCE_M**2))
    f0 = float(_f(cam, np.array(1.0)))
    power = INTENSITY_W_SR * omega * f0
    assert float(t.sum()) == pytest.approx(power, rel=1e-4 if not response else 2e-4)
    approx = INTENSITY_W_SR * cam.detector_size_m**2 / DISTANCE_M**2 * f0
    assert float(t.sum()) == pytest.approx(approx, rel=2e-4)
    mid = slice(res // 2, res // 2 + 1) if res % 2 else slice(res // 2 - 1, res // 2 + 1)
    assert float(t[0, mid, mid].sum()) == float(t.sum())  # only the texels on the axis
    if res % 2 == 0:  # four texels share the footprint equally
        np.testing.assert_allclose(t[0, mid, mid], t.sum() / 4, rtol=1e-4)
    expected = positional_reference(cam, (0, 0, DISTANCE_M), lambda u: INTENSITY_W_SR)
    _compare(t, expected, tmp_path, 1e-4, f"on axis, {res}x{res}")


@pytest.mark.parametrize(
    ("light_m", "res"),
    [((0.175, 0.01, DISTANCE_M), 8), ((-0.2, -0.15, 0.3), 16), ((0.0, 0.0, 0.02), 32)],
    ids=["off-axis", "oblique", "near"],
)
def test_point_light_per_texel_with_the_diode_response(variant, tmp_path, light_m, res):
    """(a) Off axis with the S9119-01's directional response: each texel against the
    detector integral, texels the footprint straddles included; "near" puts the
    light 2 cm away, where ``1 - d/h = 0.43`` shrinks the footprint and ``1/r^2``
    varies by 4 % across it (measured: 1e-5 of the largest texel at 64 spp; the
    others 1e-6)."""
    cam = _camera(res, response=True)
    t = render_transport(_scene(lamp=_point(light_m)), cam, spp=64, seed=1)
    expected = positional_reference(cam, light_m, lambda u: INTENSITY_W_SR)
    assert np.count_nonzero(expected) >= 2  # the footprint straddles texels
    _compare(t, expected, tmp_path, 1e-4, f"point at {light_m}")


def test_point_light_through_a_detector_grid_with_parallax(variant, tmp_path):
    """Each of the prototype's 24 detectors gets its own footprint (parallax)."""
    cam = FreeformCamera(mask_resolution=(16, 16), directional_response=s9119_01_response())
    t = render_transport(_scene(lamp=_point((0.05, 0.02, DISTANCE_M))), cam, spp=16, seed=0)
    expected = positional_reference(cam, (0.05, 0.02, DISTANCE_M), lambda u: INTENSITY_W_SR)
    _compare(t, expected, tmp_path, 1e-4, "4x6 grid")


@pytest.mark.parametrize("radius_m", [0.01, 0.05])
def test_point_light_equals_a_small_sphere_of_the_same_intensity(variant, radius_m):
    """(b) A Lambertian sphere of radius ``rho`` and radiance ``L = I / (pi rho^2)`` has
    intensity ``I`` toward every direction, and the irradiance it gives a surface
    outside it, ``pi L sin^2(delta) cos = I cos / D^2``, is the point light's exactly.
    So per detector the two powers agree; the sphere's comes from rays that hit
    it by chance (probability ~ (d rho / D)^2 / w^2 per ray: 6e-4 at 1 cm), and
    the threshold is 4 standard errors of its estimate (from the spread of
    each texel's samples, independent across texels; its own error is ~0).
    Measured over seeds 7-9: standard errors 1.9 % (1 cm, 16384 spp) and 0.9 %
    (5 cm, 1024 spp), deviations within 1.6 of them.
    """
    cam = _camera(16, layout=DetectorLayout.row(count=3, pitch_m=0.02))
    centre = (0.0, 0.0, DISTANCE_M)
    point = render_transport(_scene(lamp=_point(centre)), cam, spp=16, seed=0)
    radiance = INTENSITY_W_SR / (math.pi * radius_m**2)
    ball = ms.sphere(centre, radius_m, radiance_w_m2_sr=radiance)
    spp = 16384 if radius_m < 0.03 else 1024
    t, rel_err = render_transport_with_noise(_scene(ball=ball), cam, spp=spp, seed=7)
    p_point, p_ball = point.sum(axis=(1, 2)), t.sum(axis=(1, 2))
    sigma = rel_err * p_ball
    assert np.all(rel_err < 0.03), rel_err  # enough hits for the error estimate to hold
    assert np.all(np.abs(p_ball - p_point) < 4 * sigma), (p_point, p_ball, sigma)


def _falloff(u: np.ndarray, axis: np.ndarray, cutoff_deg: float, beam_deg: float) -> np.ndarray:
    """Mitsuba's spot falloff: 1 inside the beam, linear in angle to 0 at the cutoff."""
    angle = np.degrees(np.arccos(np.clip(u @ axis, -1.0, 1.0)))
    ramp = (cutoff_deg - angle) / (cutoff_deg - beam_deg)
    return np.where(angle <= beam_deg, 1.0, np.where(angle < cutoff_deg, ramp, 0.0))


@pytest.mark.parametrize(
    ("aim_off_deg", "share"), [(5.0, 1.0), (25.0, 0.5), (35.0, 0.0)], ids=["beam", "ramp", "cut"]
)
def test_spot_light_cone_falloff(variant, tmp_path, aim_off_deg, share):
    """(c) A spot (cutoff 30 deg, beam 20 deg) aimed ``aim_off_deg`` away from the
    board: full intensity in the beam, half in the middle of the ramp, none past
    the cutoff; each texel against the detector integral with the falloff."""
    cam = _camera(8, response=True)
    position = np.array([0.1, 0.0, DISTANCE_M])
    to_board = -position / np.linalg.norm(position)
    tilt = math.radians(aim_off_deg)  # rotate the aim about y, away from the board
    axis = np.array(
        [
            to_board[0] * math.cos(tilt) + to_board[2] * math.sin(tilt),
            0.0,
            -to_board[0] * math.sin(tilt) + to_board[2] * math.cos(tilt),
        ]
    )
    spot = _spot(position.tolist(), (position + axis).tolist(), 30.0, 20.0)
    t = render_transport(_scene(lamp=spot), cam, spp=16, seed=0)
    expected = positional_reference(
        cam, position, lambda u: INTENSITY_W_SR * _falloff(u, axis, 30.0, 20.0)
    )
    full = positional_reference(cam, position, lambda u: INTENSITY_W_SR)
    assert float(expected.sum()) == pytest.approx(share * float(full.sum()), rel=0.01, abs=0)
    if share == 0.0:
        assert not np.any(t)
    else:
        _compare(t, expected, tmp_path, 1e-4, f"spot {aim_off_deg} deg off")


@pytest.mark.parametrize(
    ("toward_light", "res"), [((0, 0, 1), 5), ((0.3, -0.2, 1.0), 16), ((-0.5, 0.1, 0.8), 32)],
    ids=["normal", "oblique", "steep"],
)  # fmt: skip
def test_directional_light_exact_per_texel(variant, tmp_path, toward_light, res):
    """(c) A directional light: ``E cos f`` times the overlap of each texel with the
    detector square shifted by ``d tan(theta)`` (exact; the sampler draws inside
    the overlap and the integrand is constant, so float32 sets the tolerance)."""
    cam = _camera(res, response=True)
    s = np.asarray(toward_light, dtype=np.float64) / np.linalg.norm(toward_light)
    sun = ms.directional_light(-s, 800.0)
    t = render_transport(_scene(sun=sun), cam, spp=4, seed=0)
    expected = directional_reference(cam, s, 800.0)
    assert np.count_nonzero(expected) >= (1 if res == 5 else 2)
    _compare(t, expected, tmp_path, 1e-4, f"toward {toward_light}")


def _black_plate(center, size_m=0.2) -> dict:
    return ms.rectangle(center, (0.0, 0.0, 0.0), (size_m, size_m), bsdf=ms.diffuse(0.0))


@pytest.mark.parametrize(
    "light",
    [_point((0, 0, DISTANCE_M)), ms.directional_light((0.0, 0.0, -1.0), 800.0)],
    ids=["point", "directional"],
)
def test_an_occluder_between_light_and_board_removes_the_direct_term(variant, light):
    """(d) A black plate between the light and the board: nothing reaches the detector
    (the plate reflects nothing, so the direct term was all there was); moved
    aside, the light is back in full."""
    cam = _camera(8)
    open_t = render_transport(_scene(lamp=light), cam, spp=4, seed=0)
    blocked = render_transport(_scene(lamp=light, plate=_black_plate((0, 0, 0.25))), cam, spp=4)
    aside = render_transport(_scene(lamp=light, plate=_black_plate((0.5, 0, 0.25))), cam, spp=4)
    assert open_t.sum() > 0 and not np.any(blocked)
    np.testing.assert_array_equal(aside, open_t)


@pytest.mark.parametrize(
    "light",
    [
        _point((0, 0, -DISTANCE_M)),  # behind the board
        _point((0, 0, 0.005)),  # between the diode and its mask (11.4 mm)
        _point((1.0, 0, 0.1)),  # in front, outside the 70-degree field of view
        ms.directional_light((0.0, 0.0, 1.0), 800.0),  # shining on the board's back
    ],
    ids=["behind", "inside the housing", "outside the view", "directional from behind"],
)
def test_lights_the_masks_cannot_pass_give_nothing(variant, light):
    assert not np.any(render_transport(_scene(lamp=light), _camera(8), spp=4, seed=0))


def test_delta_light_renders_are_reproducible(variant):
    """No scatter and no atomics: a seed gives the same image, bit for bit."""
    scene = load_scene(_scene(lamp=_point((0.03, 0.01, 0.2)), ball=ms.sphere((0, 0, 0.6), 0.2)))
    cam = _camera(16, layout=DetectorLayout.row(count=2, pitch_m=0.02))
    first = render_transport(scene, cam, spp=16, seed=3)
    np.testing.assert_array_equal(render_transport(scene, cam, spp=16, seed=3), first)


def test_delta_emitters_are_point_spot_and_directional_lights(variant):
    scene = load_scene(
        _scene(
            a=_point((0, 0, 1)),
            b=_spot([0, 0, 1], [0, 0, 0], 20.0, 15.0),
            c=ms.directional_light((0, 0, -1), 1.0),
            d=ms.sphere((0, 0, 3), 0.1, radiance_w_m2_sr=1.0),
            e=ms.constant_environment(1.0),
        )
    )
    kinds = sorted(e.class_name() for e in delta_emitters(scene))
    assert kinds == ["DirectionalEmitter", "PointLight", "SpotLight"]


def test_no_light_error_names_the_emitters_found(variant):
    scene = load_scene(_scene(lamp=_point((0, 0, -1)), glow=ms.constant_environment(0.0)))
    with pytest.raises(
        SceneError,
        match=r"all 2 detectors see no light.*found 1 ConstantBackgroundEmitter, 1 PointLight; "
        r"point, spot and directional lights reach a detector only from in front of the board",
    ):
        check_transport(np.zeros((2, 4, 4)), scene)
    dark = load_scene(_scene(ball=ms.sphere((0, 0, 1), 0.1)))
    with pytest.raises(SceneError, match=r"its emitters \(found none\)"):
        check_transport(np.zeros((2, 4, 4)), dark)


def test_light_parameter_updates_reuse_compiled_kernels(variant):
    """Moving and dimming point, spot and directional lights (a frame's sun) between
    renders reuses the compiled kernels, as any other traced parameter."""
    import drjit as dr

    scene = load_scene(
        _scene(
            a=_point((0, 0, DISTANCE_M)),
            b=_spot([0.1, 0, DISTANCE_M], [0, 0, 0], 30.0, 20.0),
            c=ms.directional_light((0, 0, -1), 5.0),
            ball=ms.sphere((0, 0, 2), 0.3),
        )
    )
    params = mi.traverse(scene)
    dr.set_flag(dr.JitFlag.KernelHistory, True)  # before compiling: it changes the hashes
    try:
        for x in (0.0, 0.01, 0.02):
            params["a.position"] = [x, 0.0, DISTANCE_M]
            params["a.intensity.value"] = 10.0 + x
            params["b.to_world"] = mi.ScalarTransform4f().look_at(
                origin=[0.1, x, DISTANCE_M], target=[0, 0, 0], up=[0, 1, 0]
            )
            params["c.to_world"] = ms.directional_light_to_world((x, 0.0, -1.0))
            params["c.irradiance.value"] = 5.0 + x
            params.update()
            dr.kernel_history()  # clears it
            assert render_transport(scene, _camera(16), spp=16, seed=0).sum() > 0
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            if x > 0.0:  # the first update may turn literals opaque: one compilation
                assert jit and all(k["cache_hit"] for k in jit)
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
