"""The patches scene's transport as a linear operator W on the plane image (``T = W L``)."""

import mitsuba as mi
import numpy as np
import pytest

from mincam_render import render_transport
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.precision import measurement_relative_error
from mincam_render.scenes import load_family
from mincam_render.scenes.patches import PLANE_RADIANCE_PARAM
from mincam_render.scenes.patches_linear import (
    PlaneGeometry,
    PlaneTransport,
    build_plane_transport,
    linear_transport_batches,
    radiance_images,
)

SPP = 1024


@pytest.fixture(scope="module")
def patches_family():
    # small masks keep Mitsuba renders and the operator fast (4 detectors, 8x8 texels)
    return load_family(
        "patches", seed=0, num_frames=8, overrides={"camera": {"mask_resolution": 8}}
    )


@pytest.fixture(scope="module")
def operator(patches_family):
    return build_plane_transport(
        PlaneGeometry.of(patches_family), patches_family.camera(), spp=SPP, seed=1
    )


def _corner_image(n: int) -> np.ndarray:
    """A bright patch in the plane's top-left, inside the camera's ~70 deg view."""
    img = np.full((n, n), 0.2, np.float32)
    img[n // 5 : n // 3, n // 5 : n // 3] = 10.0
    return img


def _render(patches_family, scene, images, spp, seed):
    out = []
    for img in images:
        params = mi.traverse(scene)
        params[PLANE_RADIANCE_PARAM] = ms.emitter_image_data(img)
        params.update()
        out.append(render_transport(scene, patches_family.camera(), spp=spp, seed=seed))
    return np.stack(out)


def test_linear_transport_matches_mitsuba_within_monte_carlo_noise(
    variant, patches_family, operator
):
    """Same estimator, same spp: W L - T_mitsuba is distributed like T_mitsuba - T_mitsuba'.

    Both are unbiased estimates at SPP samples per texel, so their distances to a
    16x-spp reference (whose own error is 1/4 of theirs) must agree. The texel RMS
    over 4 frames x 4 detectors x 64 texels has a sampling spread of a few % (ratio
    0.95-1.01 in trials); shifting the plane image by half a plane texel
    (0.04 mask texel) raised it to ~2 in a trial, a flipped axis far more.
    """
    scene = patches_family.build_scene()
    n = patches_family.config.image_resolution
    images = np.concatenate([radiance_images(patches_family, [0, 1, 2]), _corner_image(n)[None]])
    lin = operator.apply(images)
    mit = _render(patches_family, scene, images, SPP, seed=5)
    ref = _render(patches_family, scene, images, 16 * SPP, seed=7)
    rms_lin = np.sqrt(np.mean((lin - ref) ** 2))
    rms_mit = np.sqrt(np.mean((mit - ref) ** 2))
    assert 0.75 < rms_lin / rms_mit < 1.33, (rms_lin, rms_mit)
    assert abs(lin.sum() / ref.sum() - 1) < 0.02
    err_lin = measurement_relative_error(lin, ref, patches_family.camera().transmittance_range)
    err_mit = measurement_relative_error(mit, ref, patches_family.camera().transmittance_range)
    assert err_lin["rms"] < 1.5 * err_mit["rms"] + 1e-3, (err_lin, err_mit)


def test_corner_patch_lands_in_the_matching_mask_corner(operator, patches_family):
    """Top-left of the plane (row 0 up, col 0 left as seen from the camera) -> top-left of T."""
    t = operator.apply(_corner_image(patches_family.config.image_resolution) - np.float32(0.2))
    for k in range(t.shape[0]):
        rows, cols = t[k].shape
        assert t[k, : rows // 2, : cols // 2].sum() > 0.97 * t[k].sum()


@pytest.mark.parametrize("block", [(28, 36), (56, 56), (84, 20), (20, 96)])
def test_footprint_centroid_is_the_projection_of_the_plane_block(operator, patches_family, block):
    """Independent path: a 16x16-texel spot of the plane lands where the camera projects it."""
    cam = patches_family.camera()
    plane = operator.plane
    n = plane.resolution
    row, col = block
    img = np.zeros((n, n), np.float32)
    img[row : row + 16, col : col + 16] = 1.0
    centres = plane.texel_centers_m()
    point = 0.5 * (centres[row + 7, col + 7] + centres[row + 8, col + 8])  # the spot's centre
    t = operator.apply(img)
    vv, uu = np.mgrid[0:8, 0:8] + 0.5
    for k in range(cam.num_detectors):
        assert t[k].sum() > 0
        centroid = (np.sum(t[k] * vv) / t[k].sum(), np.sum(t[k] * uu) / t[k].sum())
        expected = cam.project_to_texel(point, k)
        # the spot (~1.3 mask texels) blurred by the detector (~0.5 texel) is nearly
        # symmetric about its projection: measured deviations 0.03-0.09 texel
        # (perspective, texel discretisation, noise); a flipped axis is off by texels
        np.testing.assert_allclose(centroid, expected, atol=0.2)


def test_operator_geometry_matches_the_scene_and_totals_are_positive(operator, patches_family):
    cam = patches_family.camera()
    assert operator.matrix.shape == (
        cam.num_detectors * 64,
        patches_family.config.image_resolution**2,
    )
    assert operator.transport_shape == (cam.num_detectors, 8, 8)
    # a uniform plane of 1 W m^-2 sr^-1 filling the view: every texel receives light
    t = operator.apply(np.ones((128, 128), np.float32))
    assert np.all(t > 0)
    right, up, fwd = cam.frame
    ax, ay, az = operator.plane.axes
    np.testing.assert_allclose(ax, right, atol=1e-12)
    np.testing.assert_allclose(ay, up, atol=1e-12)
    np.testing.assert_allclose(az, -fwd, atol=1e-12)


def test_radiance_images_equal_the_painting_described_by_the_frame_state(patches_family):
    """The fast 1-D painting of PatchesFamily.image equals the 2-D definition."""
    n = patches_family.config.image_resolution
    ys, xs = (np.mgrid[0:n, 0:n] + 0.5) / n
    imgs = radiance_images(patches_family, range(8))
    for i in range(8):
        state = patches_family.frame_state(i)
        img = np.full((n, n), patches_family.config.background_radiance_w_m2_sr)
        for p in state["patches"]:
            (cx, cy), (w, h) = p["center"], p["size"]
            img[(np.abs(xs - cx) <= w / 2) & (np.abs(ys - cy) <= h / 2)] = p["radiance"]
        il = state["illumination"]
        o = il["orientation_rad"]
        illum = 1.0 + il["amplitude"] * np.sin(
            2 * np.pi * (xs * np.cos(o) + ys * np.sin(o)) / il["period"] + il["phase_rad"]
        )
        np.testing.assert_array_equal(imgs[i], (img * illum).astype(np.float32))


def test_batches_give_labels_and_transport_of_each_frame(operator, patches_family):
    got = list(linear_transport_batches(patches_family, operator, range(5), batch=2))
    assert [len(t) for t, _ in got] == [2, 2, 1]
    t = np.concatenate([t for t, _ in got])
    counts = np.concatenate([c for _, c in got])
    np.testing.assert_array_equal(t, operator.apply(radiance_images(patches_family, range(5))))
    assert counts.tolist() == [[patches_family.frame_state(i)["count"]] for i in range(5)]


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"spp": 0}, r"spp = 0"), ({"seed": -1}, r"seed = -1"), ({"spp": 2.0}, r"spp = 2.0")],
)
def test_build_rejects_bad_arguments(patches_family, kwargs, match):
    with pytest.raises(ValueError, match=match):
        build_plane_transport(PlaneGeometry.of(patches_family), patches_family.camera(), **kwargs)


def test_operator_validates_shape_and_image(operator):
    with pytest.raises(ValueError, match="expected"):
        PlaneTransport(
            matrix=operator.matrix,
            camera=operator.camera,
            plane=PlaneGeometry(
                center_m=(0, 0, 1), facing_m=(0, 0, 0), up=(0, 1, 0), side_m=1.0, resolution=64
            ),
            spp=1,
            seed=0,
        )
    with pytest.raises(ValueError, match=r"expected \(frames, 128, 128\)"):
        operator.apply(np.zeros((2, 64, 64), np.float32))
    with pytest.raises(ValueError, match="side_m"):
        PlaneGeometry(center_m=(0, 0, 1), facing_m=(0, 0, 0), up=(0, 1, 0), side_m=0, resolution=8)
