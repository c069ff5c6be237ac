"""Path tracing with sunlit-patch connections: closed form, agreement with Mitsuba, bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytestmark = pytest.mark.usefixtures("variant")

#: Ceiling height (m), side of the square hole in it (m), sun irradiance (W m^-2)
#: and albedos of the floor and the ceiling of the closed-form scene.
H_M, HOLE_M, SUN_W_M2, FLOOR_ALBEDO, CEILING_ALBEDO = 2.5, 1.0, 800.0, 0.5, 0.7
CEILING_HALF_M = 6.0  # half-size of the ceiling; the floor is smaller, so that
FLOOR_HALF_M = 3.0  # an oblique beam passing beside the ceiling misses it


def _hole_scene(sun_travel):
    """A floor, a ceiling with a square hole centred above the origin, the sun through it."""
    from mincam_render.render import mitsuba_scene as ms

    def ceiling(x0, x1, y0, y1):
        centre = ((x0 + x1) / 2, (y0 + y1) / 2, H_M)
        return ms.rectangle(
            centre, (centre[0], centre[1], 0.0), (x1 - x0, y1 - y0), ms.diffuse(CEILING_ALBEDO)
        )

    a, h, f = HOLE_M / 2, CEILING_HALF_M, 2 * FLOOR_HALF_M
    shapes = {
        "floor": ms.rectangle((0, 0, 0), (0, 0, 1), (f, f), ms.diffuse(FLOOR_ALBEDO)),
        "c1": ceiling(-h, -a, -h, h),
        "c2": ceiling(a, h, -h, h),
        "c3": ceiling(-a, a, -h, -a),
        "c4": ceiling(-a, a, a, h),
        "sun": ms.directional_light(sun_travel, SUN_W_M2),
    }
    return ms.load_scene(ms.scene_dict(shapes, max_depth=3))


def _hole_window():
    a = HOLE_M / 2
    return (-a, -a, H_M), (HOLE_M, 0.0, 0.0), (0.0, HOLE_M, 0.0)  # edge_u x edge_v = +z, out


def _view_factor_corner(x: float, y: float, c: float) -> float:
    """Point-to-parallel-rectangle view factor, point above a corner of an x by y rectangle.

    Odd in ``x`` and in ``y``, so signed corners add up any rectangle.
    """
    rx, ry = math.hypot(x, c), math.hypot(y, c)
    return (x / rx * math.atan(y / rx) + y / ry * math.atan(x / ry)) / (2 * math.pi)


def _radiance_at(scene, integrator, point, n_rays: int, seed: int) -> tuple[float, float]:
    """Mean and standard error of the radiance leaving ``point`` downward (ceiling)."""
    import drjit as dr
    import mitsuba as mi

    from mincam_render.render.sun_patch import sun_sampled_apart

    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(seed, n_rays)
    origin = mi.Point3f(point[0], point[1], point[2] - 1.0)
    ray = mi.Ray3f(dr.zeros(mi.Point3f, n_rays) + origin, mi.Vector3f(0.0, 0.0, 1.0))
    with sun_sampled_apart(scene):
        radiance, _, _ = integrator.sample(scene, sampler, ray, mi.Bool(True))
    values = np.asarray(radiance, dtype=np.float64).ravel()
    return float(values.mean()), float(values.std() / math.sqrt(values.size))


@pytest.mark.parametrize("sun_travel", [(0.0, 0.0, -1.0), (0.35, -0.2, -1.0)])
@pytest.mark.parametrize("patch_vertices", [0, 2])
def test_ceiling_lit_by_the_sun_patch_matches_the_view_factor(sun_travel, patch_vertices):
    """Depth 3: ceiling point <- sunlit floor patch <- sun, against the closed form.

    The sun through a square hole in the ceiling lights a square patch of floor
    (the hole shifted along the beam) with irradiance ``E |t_z|``; the patch's
    radiance is ``rho_f E |t_z| / pi`` and a ceiling point receives
    ``pi L F`` from it, ``F`` the view factor of the patch, so it leaves with
    ``L_P = rho_c / pi * rho_f E |t_z| F``. Nothing else reaches the ceiling's
    underside in three segments.
    """
    from mincam_render.render.sun_patch import SunPatchPathIntegrator

    t = np.asarray(sun_travel, dtype=np.float64)
    t /= np.linalg.norm(t)
    shift = t[:2] * (H_M / -t[2])  # where the beam lands, relative to the hole
    point = (1.3, 0.4, H_M)
    lo = -HOLE_M / 2 + shift - np.asarray(point[:2])
    hi = HOLE_M / 2 + shift - np.asarray(point[:2])
    f = sum(
        sx * sy * _view_factor_corner(x, y, H_M)
        for x, sx in ((hi[0], 1), (lo[0], -1))
        for y, sy in ((hi[1], 1), (lo[1], -1))
    )
    expected = CEILING_ALBEDO / math.pi * FLOOR_ALBEDO * SUN_W_M2 * abs(t[2]) * f

    scene = _hole_scene(tuple(t))
    integrator = SunPatchPathIntegrator(*_hole_window(), max_depth=3, patch_vertices=patch_vertices)
    mean, err = _radiance_at(scene, integrator, point, 1 << 18, seed=1)
    # 5 sigma of the estimator's own standard error, plus float32 accumulation
    assert abs(mean - expected) <= 5 * err + 1e-4 * expected, (mean, expected, err)


def test_patch_strategy_is_far_less_noisy_than_path_tracing_here():
    """The same closed-form scene: Mitsuba's path tracer finds the patch only by chance."""
    import mitsuba as mi

    from mincam_render.render.sun_patch import SunPatchPathIntegrator

    scene = _hole_scene((0.0, 0.0, -1.0))
    point = (1.3, 0.4, H_M)
    ours = SunPatchPathIntegrator(*_hole_window(), max_depth=3)
    path = mi.load_dict({"type": "path", "max_depth": 3})
    n = 1 << 16
    _, err_ours = _radiance_at(scene, ours, point, n, seed=2)
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(3, n)
    import drjit as dr

    ray = mi.RayDifferential3f(
        dr.zeros(mi.Point3f, n) + mi.Point3f(point[0], point[1], point[2] - 1.0),
        mi.Vector3f(0.0, 0.0, 1.0),
    )
    radiance, _, _ = path.sample(scene, sampler, ray, active=True)
    values = np.asarray(radiance, dtype=np.float64).ravel()
    err_path = values.std() / math.sqrt(n)
    # measured: 0.5 against 15.7 per sample (2^20 rays); ask for a factor 5
    assert err_ours * 5 < err_path, (err_ours, err_path)


@pytest.fixture(scope="module")
def workspace():
    from dataclasses import replace

    from mincam_render.scenes.registry import load_family

    family = load_family("workspace", seed=0, num_frames=2000)
    camera = replace(family.config.camera, detectors=1, mask_resolution=8).camera()
    return family, family.build_scene(), camera


def _total(scene, camera, sun_window, seeds, spp=2048, max_depth=6):
    from mincam_render.render.transport import render_transport

    totals = [
        render_transport(
            scene, camera, spp=spp, seed=s, max_depth=max_depth, sun_window=sun_window
        ).sum(dtype=np.float64)
        for s in seeds
    ]
    return float(np.mean(totals)), float(np.std(totals, ddof=1) / math.sqrt(len(totals)))


def test_workspace_background_agrees_with_mitsubas_path_tracer(workspace):
    """Sun, sky through the window, a ceiling light, bounces: same expectation as ``path``.

    Each total has a standard error of about 0.18 % at 2048 spp (6 seeds), so a
    bias like the corridor's coplanar back face (+1.8 %) would show.
    """
    family, scene, camera = workspace
    family.set_background(scene, 0, 60.0)
    window = family.sun_window()
    ours, err_ours = _total(scene, camera, window, range(6))
    path, err_path = _total(scene, camera, None, range(100, 106))
    assert abs(ours - path) <= 4 * math.hypot(err_ours, err_path), (ours, path)


def test_sun_sampled_apart_restores_the_weight_and_the_renders(workspace):
    import mitsuba as mi

    from mincam_render.render.sun_patch import find_sun, sun_sampled_apart
    from mincam_render.render.transport import render_transport

    family, scene, camera = workspace
    family.set_background(scene, 0, 60.0)
    key = f"{find_sun(scene).id()}.sampling_weight"
    before = render_transport(scene, camera, spp=4, seed=5, max_depth=3)
    with sun_sampled_apart(scene):
        assert float(mi.traverse(scene)[key]) == 0.0
    assert float(mi.traverse(scene)[key]) == 1.0
    np.testing.assert_array_equal(
        render_transport(scene, camera, spp=4, seed=5, max_depth=3), before
    )


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"edge_v_m": (1.0, 0.0, 1.0)}, "perpendicular"),
        ({"edge_u_m": (0.0, 0.0, 0.0)}, "perpendicular"),
        ({"corner_m": (0.0, 0.0)}, "3-vectors"),
        ({"max_depth": 0}, "max_depth"),
        ({"max_depth": 2.5}, "max_depth"),
        ({"rr_depth": 0}, "rr_depth"),
        ({"patch_vertices": -1}, "patch_vertices"),
    ],
)
def test_bad_arguments_are_refused(kwargs, match):
    from mincam_render.render.sun_patch import SunPatchPathIntegrator

    args = {
        "corner_m": (0.0, 0.0, 1.0),
        "edge_u_m": (1.0, 0.0, 0.0),
        "edge_v_m": (0.0, 0.0, 1.0),
        "max_depth": 4,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        SunPatchPathIntegrator(**args)


def test_two_suns_are_refused():
    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.render.sun_patch import find_sun

    scene = ms.load_scene(
        ms.scene_dict(
            {
                "floor": ms.rectangle((0, 0, 0), (0, 0, 1), (1, 1), ms.diffuse(0.5)),
                "sun": ms.directional_light((0, 0, -1), 100.0),
                "sun2": ms.directional_light((0, 1, -1), 100.0),
            }
        )
    )
    with pytest.raises(ValueError, match="directional emitters"):
        find_sun(scene)


def test_plugin_renders_like_the_class_through_mi_render(workspace):
    """The registered plugin (``mi.render``) gives the class's expectation: same mean image."""
    import mitsuba as mi

    from mincam_render.render import mitsuba_scene as ms
    from mincam_render.render.sun_patch import sun_sampled_apart

    family, scene, camera = workspace
    family.set_background(scene, 0, 60.0)
    integrator = mi.load_dict(ms.sun_patch_integrator(*family.sun_window(), max_depth=4))
    sensor = mi.load_dict(
        {
            "type": "perspective",
            "fov": 60.0,
            "to_world": mi.ScalarTransform4f().look_at(
                origin=list(camera.position), target=list(camera.look_at), up=list(camera.up)
            ),
            "film": {"type": "hdrfilm", "width": 8, "height": 8, "pixel_format": "luminance"},
        }
    )
    with sun_sampled_apart(scene):
        ours = [
            mi.render(scene, sensor=sensor, integrator=integrator, spp=512, seed=s) for s in (1, 2)
        ]
    path = mi.load_dict({"type": "path", "max_depth": 4})
    plain = [mi.render(scene, sensor=sensor, integrator=path, spp=512, seed=s) for s in (3, 4)]
    ours_total = [float(np.asarray(x).sum()) for x in ours]
    plain_total = [float(np.asarray(x).sum()) for x in plain]
    spread = abs(ours_total[0] - ours_total[1]) + abs(plain_total[0] - plain_total[1])
    assert abs(np.mean(ours_total) - np.mean(plain_total)) <= 3 * spread + 1e-3 * np.mean(
        plain_total
    )
