"""Physics of render_transport against closed forms, geometry and an independent renderer."""

import math

import mitsuba as mi
import numpy as np
import pytest

from mincam_render import (
    DetectorLayout,
    DirectionalResponse,
    FreeformCamera,
    SceneError,
    parallel_rectangles_coupling,
    render_transport,
)
from mincam_render.data.exr import write_transport_exr
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.validation import render_through_mask_geometry

RADIANCE = 3.0  # W m^-2 sr^-1


def single(**kw) -> FreeformCamera:
    return FreeformCamera(layout=DetectorLayout(positions_m=((0.0, 0.0),)), **kw)


def uniform_sky() -> dict:
    return ms.scene_dict({"sky": ms.constant_environment(RADIANCE)})


def centroid(img: np.ndarray) -> tuple[float, float]:
    """Intensity centroid (row, col) in texel units, 0 at the top-left corner."""
    rows, cols = np.indices(img.shape)
    w = img / img.sum()
    return float((w * (rows + 0.5)).sum()), float((w * (cols + 0.5)).sum())


def coupling(cam: FreeformCamera, col_range=(0, None), row_range=(0, None)) -> float:
    """Closed-form coupling (m^2) of the detector with a block of texels."""
    a, w, d = cam.detector_size_m, cam.mask_size_m, cam.mask_distance_m
    rows, cols = cam.mask_resolution
    c0, c1 = col_range[0], col_range[1] if col_range[1] is not None else cols
    r0, r1 = row_range[0], row_range[1] if row_range[1] is not None else rows
    # board-frame s grows to the right with the column; t grows up as the row falls
    s0, s1 = -w / 2 + c0 * w / cols, -w / 2 + c1 * w / cols
    t1, t0 = w / 2 - r0 * w / rows, w / 2 - r1 * w / rows
    return parallel_rectangles_coupling((-a / 2, a / 2, -a / 2, a / 2), (s0, s1, t0, t1), d)


@pytest.mark.parametrize("res", [16, 32])
@pytest.mark.parametrize(
    "pose",
    [((0, 0, 0), (0, 0, 1), (0, 1, 0)), ((1.0, -2.0, 0.5), (3.0, 1.0, -4.0), (0.3, 0.2, 1.0))],
    ids=["axis", "oblique"],
)
def test_open_mask_in_uniform_sky_matches_closed_form(variant, tmp_path, res, pose):
    position, look_at, up = pose
    cam = single(mask_resolution=(res, res), position=position, look_at=look_at, up=up)
    t = render_transport(uniform_sky(), cam, spp=16, seed=0)
    assert t.shape == (1, res, res) and t.dtype == np.float32
    blocks = {
        "open": ((0, None), (0, None)),
        "right half": ((res // 2, None), (0, None)),
        "top-left quarter": ((0, res // 2), (0, res // 2)),
        "one texel": ((3, 4), (5, 6)),
    }
    for name, (cols, rows) in blocks.items():
        expected = RADIANCE * coupling(cam, cols, rows)
        got = float(t[0, rows[0] : rows[1], cols[0] : cols[1]].sum())
        if abs(got / expected - 1) >= (0.01 if name != "one texel" else 0.03):
            write_transport_exr(tmp_path / "T.exr", t, {"case": name})
            pytest.fail(f"{name}: {got:.6e} W vs closed form {expected:.6e} W (see {tmp_path})")


def test_directional_response_against_quadrature(variant):
    """f(theta) multiplies each ray: compare with a float64 Gauss-Legendre integral."""
    resp = DirectionalResponse(
        angles_deg=(0, 20, 40, 60, 90), relative_sensitivity=(1, 0.95, 0.8, 0.5, 0)
    )
    cam = single(mask_resolution=(16, 16), directional_response=resp)
    t = render_transport(uniform_sky(), cam, spp=32, seed=1)
    a, w, d = cam.detector_size_m, cam.mask_size_m, cam.mask_distance_m
    g, gw = np.polynomial.legendre.leggauss(12)
    det = g * a / 2
    det_w = gw * a / 2
    msk = g * w / 2
    msk_w = gw * w / 2
    qx, qy, x, y = np.meshgrid(det, det, msk, msk, indexing="ij")
    wts = np.einsum("i,j,k,l->ijkl", det_w, det_w, msk_w, msk_w)
    r2 = (x - qx) ** 2 + (y - qy) ** 2 + d * d
    theta = np.arccos(d / np.sqrt(r2))
    expected = RADIANCE * np.sum(wts * d * d / r2**2 * resp(theta))
    assert float(t.sum()) == pytest.approx(expected, rel=0.01)
    # and the response really bites: a Lambert-only diode collects more
    lambert = RADIANCE * coupling(cam)
    assert expected < 0.95 * lambert


def test_many_passes_accumulate_to_closed_form(variant):
    cam = single(mask_resolution=(8, 8))
    # passes of 6 x 6 + 4 + 1 samples: unequal, averaged by their sample counts
    t = render_transport(uniform_sky(), cam, spp=41, seed=0, max_rays_per_pass=8 * 8 * 7)
    assert float(t.sum()) == pytest.approx(RADIANCE * coupling(cam), rel=0.01)


def point_light_scene(center) -> dict:
    return ms.scene_dict({"bulb": ms.sphere(center, 0.015, radiance_w_m2_sr=1e4)}, max_depth=1)


def test_orientation_up_right_emitter_lands_top_right(variant):
    cam = single(mask_resolution=(32, 32))
    right, up, fwd = cam.frame
    bulb = 1.0 * fwd + 0.3 * right + 0.2 * up  # up and to the right of the axis
    t = render_transport(point_light_scene(bulb), cam, spp=512, seed=0)[0]
    row, col = centroid(t)
    assert row < 16 and col > 16, f"centroid at row {row:.2f}, col {col:.2f}"
    exp_row, exp_col = cam.project_to_texel(bulb, 0)
    assert (row, col) == (pytest.approx(exp_row, abs=0.25), pytest.approx(exp_col, abs=0.25))


def test_parallax_between_two_detectors_is_baseline_times_distance_over_depth(variant):
    baseline, depth = 0.020, 0.3
    cam = FreeformCamera(
        layout=DetectorLayout.row(count=2, pitch_m=baseline), mask_resolution=(64, 64)
    )
    t = render_transport(point_light_scene((0.0, 0.0, depth)), cam, spp=256, seed=0)
    (r0, c0), (r1, c1) = centroid(t[0]), centroid(t[1])
    texel = cam.texel_size_m[1]
    expected = baseline * cam.mask_distance_m / depth / texel  # = 3.04 texels
    assert abs(c0 - c1) == pytest.approx(expected, abs=0.1)
    assert r0 == pytest.approx(r1, abs=0.05)


def test_mirrored_scene_gives_mirrored_transport(variant):
    cam = single(mask_resolution=(16, 16))

    def scene(sign):
        return ms.scene_dict(
            {
                "lamp": ms.rectangle(
                    (sign * 0.3, 0.2, 1.0), (0, 0, 0), (0.2, 0.3), radiance_w_m2_sr=10.0
                ),
                "wall": ms.rectangle((0, 0, 2.0), (0, 0, 0), (4, 4), ms.diffuse(0.5)),
            },
            max_depth=3,
        )

    a = render_transport(scene(+1), cam, spp=4096, seed=0)
    b = render_transport(scene(-1), cam, spp=4096, seed=1)
    # column sums; the column that only the detector-area blur reaches sees the lamp
    # in ~2 % of samples (~8 % noise at 4096 spp), hence the absolute tolerance
    cols_a, cols_b = a.sum(axis=1), b[:, :, ::-1].sum(axis=1)
    np.testing.assert_allclose(cols_a, cols_b, rtol=0.03, atol=0.01 * cols_a.max())
    assert float(a.sum()) == pytest.approx(float(b.sum()), rel=0.01)


def test_batched_detectors_equal_single_renders(variant):
    lay = DetectorLayout(positions_m=((-0.03, 0.0), (0.0, 0.02), (0.025, -0.01)))
    # smooth lighting (sky, a grey wall, a ball) keeps the Monte Carlo noise of a
    # block sum near 0.3 % at 1024 spp, so 2 % tolerances are > 5 sigma
    scene = ms.scene_dict(
        {
            "sky": ms.constant_environment(2.0),
            "wall": ms.rectangle((0, 0, 1.5), (0, 0, 0), (2, 2), ms.diffuse(0.7)),
            "ball": ms.sphere((0.2, 0.1, 0.8), 0.15, ms.diffuse(0.2)),
        },
        max_depth=3,
    )
    batched = render_transport(
        scene, FreeformCamera(layout=lay, mask_resolution=(8, 8)), spp=1024, seed=0
    )
    for k, pos in enumerate(lay.positions_m):
        one = render_transport(
            scene,
            FreeformCamera(layout=DetectorLayout(positions_m=(pos,)), mask_resolution=(8, 8)),
            spp=1024,
            seed=7,
        )
        blocks_b = batched[k].reshape(4, 2, 4, 2).sum(axis=(1, 3))
        blocks_1 = one[0].reshape(4, 2, 4, 2).sum(axis=(1, 3))
        np.testing.assert_allclose(blocks_b, blocks_1, rtol=0.02)
        assert float(batched[k].sum()) == pytest.approx(float(one.sum()), rel=0.005)


@pytest.mark.parametrize("depth", [1, 3])
def test_transport_dot_mask_equals_mitsuba_render_of_mask_geometry(variant, rng, depth):
    """Linearity against an independent path: irradiance meter behind a mask sheet."""
    cam = single(
        mask_resolution=(8, 8), position=(0.1, 0.2, -0.1), look_at=(0.3, 0.5, 1.5), up=(0.2, 1, 0)
    )
    scene = ms.scene_dict(
        {
            "sky": ms.constant_environment(0.5),
            "lamp": ms.rectangle((-0.3, 0.6, 1.0), (0, 0.2, 0), (0.3, 0.3), radiance_w_m2_sr=50.0),
            "wall": ms.rectangle((0, 0, 2.0), (0, 0, 0), (3, 3), ms.diffuse(0.5)),
            "ball": ms.sphere((0.4, 0.5, 1.0), 0.2, ms.diffuse(0.8)),
        },
        max_depth=depth,
    )
    mask = rng.uniform(0.01, 0.67, size=(8, 8))
    ours = [
        float((render_transport(scene, cam, spp=2048, seed=s)[0] * mask).sum()) for s in range(4)
    ]
    ref = [
        render_through_mask_geometry(scene, cam, 0, mask, spp=1 << 19, seed=s, max_depth=depth)
        for s in range(4)
    ]
    # standard errors of the two means from the spread of independent seeds
    sigma = math.hypot(np.std(ours, ddof=1) / 2, np.std(ref, ddof=1) / 2)
    diff = abs(np.mean(ours) - np.mean(ref))
    assert diff < 4 * sigma + 1e-3 * np.mean(ref), (
        f"{np.mean(ours):.5e} vs {np.mean(ref):.5e} W, sigma {sigma:.2e}"
    )


def test_traced_parameter_update_reuses_compiled_kernels(variant):
    import drjit as dr

    cam = single(mask_resolution=(16, 16))
    scene = ms.load_scene(ms.demo_scene())
    params = mi.traverse(scene)
    # history instrumentation changes the kernels' hashes: enable it before compiling
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        # the first update may turn literal parameters into opaque ones: one
        # recompilation; every later update must reuse the compiled kernels
        for x in (0.0, 0.1, 0.3):
            params["ball.to_world"] = mi.ScalarTransform4f().translate([x, -0.6, 1.2]).scale(0.3)
            params.update()
            dr.kernel_history()  # clears the history
            render_transport(scene, cam, spp=64, seed=0)
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            if x == 0.0:
                continue
            assert jit and all(k["cache_hit"] for k in jit), [
                (k["hash"][:6], k["cache_hit"], k["size"]) for k in jit
            ]
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)


def test_seed_reproducible_and_distinct(variant):
    cam = single(mask_resolution=(8, 8))
    a = render_transport(ms.demo_scene(), cam, spp=4, seed=5)
    b = render_transport(ms.demo_scene(), cam, spp=4, seed=5)
    c = render_transport(ms.demo_scene(), cam, spp=4, seed=6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_bad_scenes_raise_clear_errors(variant, tmp_path):
    cam = single(mask_resolution=(4, 4))
    with pytest.raises(SceneError, match="does not exist"):
        render_transport(tmp_path / "missing.xml", cam)
    broken = tmp_path / "broken.xml"
    broken.write_text("<scene version='3.0.0'><shape type='nonsense'/>")
    with pytest.raises(SceneError, match="could not load"):
        render_transport(broken, cam)
    with pytest.raises(SceneError, match="type = 'scene'"):
        render_transport({"sky": ms.constant_environment(1.0)}, cam)
    with pytest.raises(SceneError, match="rejected"):
        render_transport({"type": "scene", "x": {"type": "no_such_plugin"}}, cam)
    with pytest.raises(SceneError, match="not supported"):
        render_transport(42, cam)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"spp": 0}, "spp"),
        ({"seed": -1}, "seed"),
        ({"max_depth": 0}, "max_depth"),
        ({"spp": 2.5}, "spp"),
    ],
)
def test_bad_render_arguments(variant, kw, match):
    with pytest.raises(ValueError, match=match):
        render_transport(uniform_sky(), single(mask_resolution=(4, 4)), **kw)


def test_user_xml_scene_renders(variant, tmp_path):
    xml = tmp_path / "sky.xml"
    xml.write_text(
        "<scene version='3.0.0'><emitter type='constant'>"
        "<rgb name='radiance' value='3.0'/></emitter></scene>"
    )
    cam = single(mask_resolution=(8, 8))
    t = render_transport(xml, cam, spp=16)
    assert float(t.sum()) == pytest.approx(RADIANCE * coupling(cam), rel=0.01)


def test_without_parallax_every_detector_sees_from_the_board_centre(variant):
    baseline, depth = 0.020, 0.3
    cam = FreeformCamera(
        layout=DetectorLayout.row(count=2, pitch_m=baseline), mask_resolution=(32, 32)
    )
    scene = point_light_scene((0.0, 0.0, depth))
    with_p = render_transport(scene, cam, spp=128, seed=3)
    without = render_transport(scene, cam, spp=128, seed=3, parallax=False)
    (_, c0), (_, c1) = centroid(without[0]), centroid(without[1])
    assert c0 == pytest.approx(c1, abs=0.05)
    assert c0 == pytest.approx(16.0, abs=0.1)  # the bulb is on the board's axis
    # same sample streams: detector 0 moved by 10 mm shifts its image by b d / z
    shift = (centroid(with_p[0])[1] - c0) * cam.texel_size_m[1]
    assert shift == pytest.approx(0.010 * cam.mask_distance_m / depth, rel=0.05)


@pytest.mark.parametrize(("spp", "cap"), [(1, 8), (20, 1024), (1792, 1024), (1000, 64), (7, 7)])
def test_sample_passes_sum_to_spp_in_full_grids_under_the_cap(spp, cap):
    import math

    from mincam_render.render.transport import sample_passes

    passes = sample_passes(spp, cap)
    assert sum(passes) == spp
    assert all(1 <= n <= cap and n % math.isqrt(n) == 0 for n in passes)
    assert passes == sorted(passes, reverse=True)  # largest grid first


def test_mitsuba_warnings_reach_python_logging_without_the_mono_film_notice(variant, caplog):
    import logging

    with caplog.at_level(logging.DEBUG, logger="mitsuba"):
        mi.Log(mi.LogLevel.Warn, "a real problem")
        mi.load_dict(mi.cornell_box())  # its RGB film would print the monochrome notice
    assert "a real problem" in caplog.text and "Monochrome" not in caplog.text
