"""Forward model at the extremes: geometry, dynamic range, gains, bad input (fuzzed)."""

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mincam_render import (
    DetectorElectronics,
    DetectorLayout,
    FreeformCamera,
    detector_voltage,
    mask_power,
    parallel_rectangles_coupling,
    render_transport,
)
from mincam_render.render import mitsuba_scene as ms

ONE = DetectorLayout(positions_m=((0.0, 0.0),))


def open_mask_power(cam: FreeformCamera, radiance: float) -> float:
    a, w, d = cam.detector_size_m, cam.mask_size_m, cam.mask_distance_m
    return radiance * parallel_rectangles_coupling(
        (-a / 2, a / 2, -a / 2, a / 2), (-w / 2, w / 2, -w / 2, w / 2), d
    )


@pytest.mark.parametrize(
    "geometry",
    [
        {"detector_size_m": 1e-6},  # point-detector limit
        # mask almost on the diode: the detector's footprint on the mask has sharp
        # edges, so texels must be fine for uniform texel sampling to converge
        {"mask_distance_m": 1e-4, "mask_resolution": (128, 128), "spp": 256},
        {"mask_distance_m": 0.5},  # far mask: narrow view
        # grazing, half-angle 89.4 deg; texels must stay ~ the mask distance or the
        # d^2/r^4 peak inside a texel makes uniform x sampling noisy
        {"mask_size_m": 0.2, "mask_distance_m": 1e-3, "mask_resolution": (512, 512)},
        {"mask_resolution": (1, 1), "spp": 8192},  # a single texel
        {"detector_size_m": 0.01, "mask_size_m": 0.01},  # detector as large as the mask
    ],
    ids=["point", "tiny-distance", "far-mask", "grazing", "single-texel", "huge-detector"],
)
def test_geometry_extremes_match_closed_form(variant, geometry):
    kw = {"mask_resolution": (32, 32), **geometry}
    spp = kw.pop("spp", 64)
    cam = FreeformCamera(layout=ONE, **kw)
    t = render_transport(ms.scene_dict({"sky": ms.constant_environment(2.0)}), cam, spp=spp, seed=0)
    assert np.all(np.isfinite(t)) and np.all(t >= 0)
    assert float(t.sum(dtype=np.float64)) == pytest.approx(open_mask_power(cam, 2.0), rel=0.01)


def test_a_tiny_detector_equals_the_point_detector_limit(variant):
    """T / A_d for a tiny diode equals the point-detector integral of d^2 / r^4 over the mask."""
    cam = FreeformCamera(layout=ONE, detector_size_m=1e-7, mask_resolution=(16, 16))
    t = render_transport(ms.scene_dict({"sky": ms.constant_environment(1.0)}), cam, spp=16, seed=0)
    d, h = cam.mask_distance_m, cam.mask_size_m / 2
    # integral of d^2 / (x^2 + y^2 + d^2)^2 over [-h, h]^2 (closed form)
    point = 4 * (h / math.sqrt(h * h + d * d)) * math.atan(h / math.sqrt(h * h + d * d))
    assert float(t.sum(dtype=np.float64)) / cam.detector_size_m**2 == pytest.approx(
        point, rel=0.005
    )


def test_empty_scene_gives_zero_not_nan(variant):
    cam = FreeformCamera(layout=ONE, mask_resolution=(8, 8))
    t = render_transport({"type": "scene"}, cam, spp=4)
    assert np.all(t == 0.0)


@pytest.mark.parametrize("radiance", [1e-6, 1.0, 1e6])
def test_radiance_dynamic_range_is_linear(variant, radiance):
    cam = FreeformCamera(layout=ONE, mask_resolution=(8, 8))
    t = render_transport(ms.scene_dict({"sky": ms.constant_environment(radiance)}), cam, spp=16)
    assert float(t.sum(dtype=np.float64)) == pytest.approx(open_mask_power(cam, radiance), rel=0.01)


def test_faint_and_blinding_emitters_in_one_scene(variant):
    """1e-6 and 1e6 W m^-2 sr^-1 side by side: both resolved, nothing overflows."""
    cam = FreeformCamera(layout=ONE, mask_resolution=(16, 16))
    scene = ms.scene_dict(
        {
            "faint": ms.rectangle(
                (0.3, 0.0, 1.0), (0.3, 0.0, 0.0), (0.3, 0.6), radiance_w_m2_sr=1e-6
            ),
            "bright": ms.rectangle(
                (-0.3, 0.0, 1.0), (-0.3, 0.0, 0.0), (0.3, 0.6), radiance_w_m2_sr=1e6
            ),
        },
        max_depth=1,
    )
    t = render_transport(scene, cam, spp=16)[0]
    assert np.all(np.isfinite(t))
    left, right = t[:, :6].sum(), t[:, -6:].sum()  # camera left = world +x (faint)
    assert left > 0 and right > 0
    assert right / left == pytest.approx(1e12, rel=0.05)


@pytest.mark.parametrize("gain", [1e4, 1e6, 1e7, 1e9])
def test_gain_range_saturates_where_physics_says(gain):
    e = DetectorElectronics(gain_v_per_a=gain)
    power = torch.tensor([[1e-9, 1e-7, 1e-5]], dtype=torch.float64)
    v = detector_voltage(power, e, noise=False)
    ideal = e.responsivity_a_per_w * power * gain
    assert torch.isfinite(v).all()
    saturated = ideal > e.full_scale_v
    assert torch.allclose(v[~saturated], ideal[~saturated])
    assert torch.all(v[saturated] < ideal[saturated]) and torch.all(v[saturated] >= e.full_scale_v)


@pytest.mark.parametrize("slope", [1e-6, 1e-3, 1.0])
def test_saturated_detectors_keep_gradients_for_any_slope(slope):
    e = DetectorElectronics(saturation_slope=slope)
    t = torch.full((1, 1, 4, 4), 1e-3)  # ~ sunlight on the diode: deeply saturated
    logits = torch.zeros(1, 4, 4, requires_grad=True)
    v = detector_voltage(mask_power(t, logits, (0.01, 0.67)), e, noise=False)
    v.sum().backward()
    assert float(v.detach()) > e.full_scale_v
    assert torch.isfinite(logits.grad).all() and (logits.grad > 0).all()


def test_many_samples_accumulate_without_float32_drift(variant):
    """2^16 samples per texel in 16 passes: float64 accumulation keeps the closed form."""
    cam = FreeformCamera(layout=ONE, mask_resolution=(4, 4))
    scene = ms.scene_dict({"sky": ms.constant_environment(1.0)})
    t = render_transport(scene, cam, spp=1 << 16, seed=0, max_rays_per_pass=1 << 16)
    assert float(t.sum(dtype=np.float64)) == pytest.approx(open_mask_power(cam, 1.0), rel=2e-4)


# ---- bad input, fuzzed ------------------------------------------------------------

_weird = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**12), max_value=10**12),
    st.text(max_size=5),
    st.none(),
    st.booleans(),
    st.lists(st.floats(allow_nan=True), max_size=4),
)
_fields = st.sampled_from(
    [
        "detector_size_m",
        "mask_size_m",
        "mask_distance_m",
        "mask_resolution",
        "position",
        "look_at",
        "up",
        "transmittance_range",
        "layout",
        "directional_response",
        "electronics",
    ]
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(field=_fields, value=_weird)
def test_fuzzed_camera_fields_either_build_or_name_the_field(field, value):
    try:
        FreeformCamera(**{field: value})
    except ValueError as err:
        # the error names this field, or the field it conflicts with (position vs look_at)
        assert "FreeformCamera." in str(err) or "DetectorLayout" in str(err), str(err)
        assert field in str(err) or field in ("position", "look_at", "up"), str(err)
        assert "\n" not in str(err)


@settings(max_examples=100, deadline=None)
@given(
    field=st.sampled_from(
        [
            "responsivity_a_per_w",
            "gain_v_per_a",
            "read_noise_v",
            "adc_bits",
            "full_scale_v",
            "saturation_slope",
            "integration_time_s",
            "dark_current_a",
        ]
    ),
    value=_weird,
)
def test_fuzzed_electronics_fields_either_build_or_name_the_field(field, value):
    try:
        DetectorElectronics(**{field: value})
    except ValueError as err:
        assert f"DetectorElectronics.{field}" in str(err)


_toml_values = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=32).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.text(alphabet="abc xyz", max_size=6).map(lambda s: f'"{s}"'),
    st.just("true"),
    st.lists(st.floats(-10, 10, width=32), max_size=3).map(
        lambda v: "[" + ", ".join(map(repr, v)) + "]"
    ),
)


@settings(max_examples=120, deadline=None)
@given(
    key=st.sampled_from(
        [
            "fps",
            "plane_distance_m",
            "plane_fov_deg",
            "image_resolution",
            "max_patches",
            "patch_size",
            "patch_radiance_w_m2_sr",
            "background_radiance_w_m2_sr",
            "illumination_amplitude",
            "illumination_period",
            "no_such_key",
        ]
    ),
    value=_toml_values,
)
def test_fuzzed_scene_descriptions_fail_with_one_line_naming_file_and_field(
    tmp_path_factory, key, value
):
    from mincam_render.core.config import ConfigError
    from mincam_render.scenes import load_family

    path = tmp_path_factory.mktemp("fuzz") / "scene.toml"
    path.write_text(f'family = "patches"\n{key} = {value}\n')
    try:
        load_family(path, seed=0, num_frames=1)
    except ConfigError as err:
        msg = str(err)
        assert msg.startswith(str(path)) and key in msg and "\n" not in msg, msg
