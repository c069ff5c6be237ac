import math

import numpy as np
import pytest

from mincam_render import DetectorElectronics, DetectorLayout, DirectionalResponse, FreeformCamera
from mincam_render.optics.camera import MM


def test_prototype_defaults_match_paper():
    cam = FreeformCamera()
    assert cam.num_detectors == 24
    assert cam.detector_size_m == pytest.approx(0.88 * MM)
    assert cam.mask_size_m == pytest.approx(16 * MM)
    assert cam.mask_distance_m == pytest.approx(11.4 * MM)
    assert cam.transmittance_range == (0.01, 0.67)
    # paper: 16 mm mask 11.4 mm above the diode ~ 70 deg field of view
    assert cam.fov_deg == pytest.approx(70.1, abs=0.1)
    e = cam.electronics
    assert (e.gain_v_per_a, e.read_noise_v, e.adc_bits, e.full_scale_v) == (1e7, 400e-6, 16, 3.2)
    assert e.lsb_v == pytest.approx(3.2 / 65536)


def test_frame_is_right_handed_photo_convention():
    cam = FreeformCamera(position=(1, 2, 3), look_at=(1, 2, 10), up=(0, 1, 0.3))
    right, up, fwd = cam.frame
    np.testing.assert_allclose(fwd, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(up, [0, 1, 0], atol=1e-12)
    # looking along +z with +y up, the camera's right is world -x
    np.testing.assert_allclose(right, [-1, 0, 0], atol=1e-12)


def test_grid_layout_positions_and_texel_centres():
    lay = DetectorLayout.grid(rows=2, cols=3, pitch_m=0.02)
    np.testing.assert_allclose(
        lay.positions_m,
        [(-0.02, 0.01), (0, 0.01), (0.02, 0.01), (-0.02, -0.01), (0, -0.01), (0.02, -0.01)],
    )
    cam = FreeformCamera(layout=lay, mask_resolution=(4, 8))
    c = cam.texel_centers_m(0)
    assert c.shape == (4, 8, 3)
    # texel (0, 0) is at the top-left (camera up and left = world +y and +x)
    centre = cam.detector_centers_m[0]
    assert c[0, 0, 1] > centre[1] and c[0, 0, 0] > centre[0]
    np.testing.assert_allclose(c[..., 2], cam.mask_distance_m)
    # the pinhole projection of a texel centre (seen from its detector) is that texel
    row, col = cam.project_to_texel(centre + 10 * (c[1, 5] - centre), 0)
    assert (row, col) == (pytest.approx(1.5), pytest.approx(5.5))


BAD_FIELDS = [
    ("detector_size_m", -1e-3, "detector_size_m"),
    ("detector_size_m", 0.0, "detector_size_m"),
    ("mask_size_m", 0.0, "mask_size_m"),
    ("mask_distance_m", float("nan"), "mask_distance_m"),
    ("mask_distance_m", "11.4mm", "mask_distance_m"),
    ("mask_resolution", (0, 32), "mask_resolution"),
    ("mask_resolution", (32,), "mask_resolution"),
    ("mask_resolution", (32.5, 32), "mask_resolution"),
    ("position", (0, 0), "position"),
    ("look_at", (0, 0, 0), "look_at"),
    ("position", (1e300, 0, 0), "position"),  # its distance to look_at would overflow
    ("look_at", (0, 0, -2e50), "look_at"),
    ("up", (0, 0, 1), "up"),
    ("transmittance_range", (0.7, 0.1), "transmittance_range"),
    ("transmittance_range", (0.0, 1.5), "transmittance_range"),
    ("layout", DetectorLayout(positions_m=((0, 0), (0.01, 0))), "layout"),
    ("directional_response", [1, 2], "directional_response"),
]


@pytest.mark.parametrize(("name", "value", "quoted"), BAD_FIELDS)
def test_bad_camera_field_names_field_value_and_range(name, value, quoted):
    with pytest.raises(ValueError, match=rf"FreeformCamera\.{quoted} = .*allowed"):
        FreeformCamera(**{name: value})


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("responsivity_a_per_w", 0.0),
        ("gain_v_per_a", 1e13),
        ("read_noise_v", -1e-6),
        ("adc_bits", 0),
        ("adc_bits", 16.0),
        ("full_scale_v", 0.0),
        ("saturation_slope", 0.0),
        ("saturation_slope", 2.0),
        ("integration_time_s", 0.0),
    ],
)
def test_bad_electronics_field(name, value):
    with pytest.raises(ValueError, match=rf"DetectorElectronics\.{name} = .*allowed"):
        DetectorElectronics(**{name: value})


@pytest.mark.parametrize(
    ("angles", "values"),
    [
        ((0, 90), (1,)),
        ((10, 90), (1, 1)),
        ((0, 60, 50), (1, 1, 1)),
        ((0, 100), (1, 1)),
        ((0, 90), (1, -1)),
    ],
)
def test_bad_directional_response(angles, values):
    with pytest.raises(ValueError, match=r"DirectionalResponse\."):
        DirectionalResponse(angles_deg=angles, relative_sensitivity=values)


def test_directional_response_interpolates():
    resp = DirectionalResponse(angles_deg=(0, 30, 90), relative_sensitivity=(1.0, 0.8, 0.2))
    np.testing.assert_allclose(resp(np.radians([0, 15, 60, 90])), [1.0, 0.9, 0.5, 0.2])
    table = resp.uniform_table(181)
    assert table[30 * 2] == pytest.approx(0.8) and table.dtype == np.float32


def test_camera_at_the_coordinate_bound_keeps_a_unit_frame():
    cam = FreeformCamera(position=(1e50, 0, 0), look_at=(-1e50, 0, 0), up=(0, 1e50, 0))
    np.testing.assert_allclose(np.linalg.norm(cam.frame, axis=1), 1.0, rtol=1e-12)


def test_camera_is_frozen_and_serialisable():
    cam = FreeformCamera()
    with pytest.raises(AttributeError):
        cam.mask_distance_m = 1.0  # type: ignore[misc]
    d = cam.to_dict()
    assert d["mask_resolution"] == (32, 32) and math.isclose(d["mask_size_m"], 0.016)
