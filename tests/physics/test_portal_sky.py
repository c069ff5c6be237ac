"""The window portal sky: sampling density, closed-form irradiance, agreement with envmap."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.precision import measurement_relative_error
from mincam_render.render.transport import render_transport

# a 2 x 1 m skylight 1.5 m above the origin, edges chosen so edge_u x edge_v = +z (out)
CORNER = (0.5, -1.0, 1.5)
EDGE_U = (0.0, 2.0, 0.0)
EDGE_V = (-1.0, 0.0, 0.0)


def _corner_form_factor(a: float, b: float, h: float) -> float:
    """Point-to-rectangle form factor: receiver parallel, below a corner of an a x b rectangle."""
    x, y = a / h, b / h
    sx, sy = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    return (x / sx * math.atan(y / sx) + y / sy * math.atan(x / sy)) / (2 * math.pi)


def _emitter(radiance):
    import mitsuba as mi

    return mi.load_dict(ms.portal_sky(radiance, CORNER, EDGE_U, EDGE_V))


def _interaction(points):
    import mitsuba as mi

    it = mi.Interaction3f()
    pts = np.asarray(points, dtype=np.float32)
    it.p = mi.Point3f(pts[:, 0], pts[:, 1], pts[:, 2])
    return it


def test_irradiance_under_skylight_matches_form_factor(variant):
    """E = L pi F for a uniform sky: sample_direction's weights integrate the window exactly."""
    import mitsuba as mi

    radiance = 3.0
    emitter = _emitter(np.full((8, 16), radiance))
    n = 1 << 18
    rng = np.random.default_rng(0)
    it = _interaction(np.zeros((n, 3)))
    sample = mi.Point2f(*rng.random((2, n)).astype(np.float32))
    ds, weight = emitter.sample_direction(it, sample)
    cos_receiver = np.asarray(ds.d.z)
    irradiance = float(
        np.mean(np.asarray(weight[0], dtype=np.float64) * np.maximum(cos_receiver, 0.0))
    )
    # the origin lies under an interior point of the window: four corner rectangles
    h = 1.5
    f = 4 * _corner_form_factor(0.5, 1.0, h)  # x in [-0.5, 0.5], y in [-1, 1]
    expected = radiance * math.pi * f
    std = float(np.std(np.asarray(weight[0], dtype=np.float64) * cos_receiver)) / math.sqrt(n)
    assert irradiance == pytest.approx(expected, abs=4 * std + 1e-6)


def test_pdf_direction_matches_sampling_density_and_is_zero_off_window(variant):
    import mitsuba as mi

    emitter = _emitter(np.ones((8, 16)))
    rng = np.random.default_rng(1)
    pts = rng.uniform([-2, -2, 0], [2, 2, 1], size=(64, 3))  # below the window
    it = _interaction(pts)
    ds, _ = emitter.sample_direction(it, mi.Point2f(*rng.random((2, 64)).astype(np.float32)))
    pdf = np.asarray(emitter.pdf_direction(it, ds))
    np.testing.assert_allclose(pdf, np.asarray(ds.pdf), rtol=1e-3)
    assert np.all(pdf > 0)
    # straight down, away from the window: never sampled
    ds.d = mi.Vector3f(0.0, 0.0, -1.0)
    assert np.all(np.asarray(emitter.pdf_direction(it, ds)) == 0.0)


def test_eval_looks_up_the_map_in_world_directions(variant):
    """Row 0 is the zenith; a direction at a texel centre returns that texel's value."""
    import mitsuba as mi

    from mincam_render.scenes.sky import envmap_directions

    h, w = 8, 16
    rng = np.random.default_rng(2)
    radiance = rng.uniform(0.5, 2.0, size=(h, w))
    emitter = _emitter(radiance)
    dirs = envmap_directions(h, w).reshape(-1, 3)
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(*(-dirs.T.astype(np.float32)))
    got = np.asarray(emitter.eval(si)[0])
    np.testing.assert_allclose(got, radiance.ravel(), rtol=1e-4)


def test_rejects_degenerate_window(variant):
    import mitsuba as mi

    with pytest.raises(Exception, match="perpendicular"):
        mi.load_dict(ms.portal_sky(np.ones((4, 8)), CORNER, EDGE_U, (0.0, 1.0, 0.0)))


@pytest.fixture(scope="module")
def workspace_renders(variant):
    """Sky-only workspace renders with both sky samplers (lights off)."""
    import drjit as dr
    import mitsuba as mi

    from mincam_render.scenes import indoor, load_family

    family = load_family("workspace", seed=0, num_frames=60)
    cam = family.camera()
    cam = dataclasses.replace(cam, mask_resolution=(8, 8))
    state = dataclasses.replace(family.state(30), lights_on=(False,) * len(family.rig.lights))
    out = {}
    for mode in indoor.SkySampling:
        family.rig.sky_sampling = mode
        scene = family.build_scene()
        family.apply_state(scene, state)
        params = mi.traverse(scene)
        for li in family.rig.lights:
            params[li.radiance_param] = dr.opaque(mi.Float, 0.0)
        params.update()
        out[mode] = [render_transport(scene, cam, spp=64, seed=s, max_depth=6) for s in range(4)]
    return cam, out


def test_portal_agrees_with_envmap_and_is_less_noisy(workspace_renders):
    """Same light (within noise and the maps' lookups), several times less variance."""
    from mincam_render.scenes.indoor import SkySampling

    cam, out = workspace_renders
    lo_hi = cam.transmittance_range
    portal = np.stack(out[SkySampling.PORTAL])
    envmap = np.stack(out[SkySampling.ENVMAP])
    noise = {}
    for mode, r in ((SkySampling.PORTAL, portal), (SkySampling.ENVMAP, envmap)):
        noise[mode] = measurement_relative_error(r[:2], r[2:], lo_hi)["rms"]
    assert noise[SkySampling.PORTAL] < 0.5 * noise[SkySampling.ENVMAP]
    # total power: the mean of 4 envmap renders has ~noise/2 relative error per measurement
    ratio = portal.sum() / envmap.sum()
    assert ratio == pytest.approx(1.0, abs=0.03)
