"""Perturbation model and fabricated mask plane: identities, closed forms, gradients, bad input."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from mincam_render.optics.camera import MM, DetectorLayout, FreeformCamera
from mincam_render.optics.fabrication import (
    blur_mask,
    fabricated_transmittance,
    place_masks,
    print_tone,
)
from mincam_render.optics.maskplane import transmittance
from mincam_render.optics.perturbation import (
    CM,
    DEG,
    MAGNITUDES,
    TERM_FIELDS,
    PerturbationDraw,
    PerturbationModel,
    PerturbationTerm,
    record_name,
)

RANGE = (0.01, 0.67)
TEXEL_M = (0.5 * MM, 0.5 * MM)  # the prototype's 16 mm / 32 texels


def _logits(rng: np.random.Generator, k: int = 3, res: int = 8) -> torch.Tensor:
    return torch.from_numpy(rng.normal(0, 2, (k, res, res)))


@pytest.mark.parametrize("term", list(PerturbationTerm), ids=lambda t: t.value)
def test_each_term_at_magnitude_zero_is_exactly_the_design(term, rng):
    logits = _logits(rng)
    draw = PerturbationModel().only(term).scaled(0.0).draw(3, rng)
    m = fabricated_transmittance(logits, RANGE, draw, TEXEL_M)
    assert torch.equal(m, transmittance(logits, RANGE))
    assert np.array_equal(draw.gain, np.ones(3)) and np.array_equal(draw.offset_v, np.zeros(3))


@pytest.mark.parametrize("term", list(PerturbationTerm), ids=lambda t: t.value)
def test_each_term_alone_changes_only_its_own_fields(term, rng):
    base = PerturbationModel(pose_depth_m=3.5)
    model = base.only(term)
    for f in dataclasses.fields(model):
        kept = f.name in TERM_FIELDS[term] or f.name not in MAGNITUDES  # settings stay
        assert getattr(model, f.name) == (getattr(base, f.name) if kept else 0.0)
    assert model.scaled(2.0).pose_depth_m == 3.5 and PerturbationModel.zero().is_zero()


@pytest.mark.parametrize(("rows", "cols"), [(2, 0), (0, -3), (1, 2)])
def test_an_integer_shift_is_a_roll_with_the_border_entering(rows, cols, rng):
    m = torch.from_numpy(rng.uniform(0.1, 0.6, (2, 8, 8)))
    shift = np.array([[rows, cols], [rows, cols]], dtype=np.float64)
    out = place_masks(m, shift, np.zeros(2), fill=0.01)
    rolled = torch.roll(m, shifts=(rows, cols), dims=(1, 2)).clone()
    if rows > 0:
        rolled[:, :rows] = 0.01
    if cols > 0:
        rolled[:, :, :cols] = 0.01
    if cols < 0:
        rolled[:, :, cols:] = 0.01
    torch.testing.assert_close(out, rolled, rtol=0, atol=1e-12)


def test_a_shift_in_metres_moves_the_mask_by_texels(rng):
    logits = _logits(rng, k=1)
    draw = PerturbationDraw(shift_m=[[0.0, 1.0 * MM]], rotation_rad=[0.0])  # 2 texels right
    m = fabricated_transmittance(logits, RANGE, draw, TEXEL_M)
    nominal = transmittance(logits, RANGE)
    torch.testing.assert_close(m[:, :, 2:], nominal[:, :, :-2], rtol=0, atol=1e-12)
    torch.testing.assert_close(m[:, :, :2], torch.full_like(m[:, :, :2], RANGE[0]))


def test_a_quarter_turn_rotates_the_mask_clockwise(rng):
    m = torch.from_numpy(rng.uniform(0.1, 0.6, (1, 6, 6)))
    out = place_masks(m, np.zeros((1, 2)), np.array([math.pi / 2]), fill=0.0)
    # clockwise as seen with row 0 up: the top row becomes the right column
    torch.testing.assert_close(out, torch.rot90(m, k=-1, dims=(1, 2)), rtol=0, atol=1e-12)


def test_blur_keeps_a_uniform_mask_uniform_away_from_the_border_and_preserves_mass():
    m = torch.full((1, 32, 32), 0.4, dtype=torch.float64)
    out = blur_mask(m, (1.0, 1.0), fill=0.4)
    torch.testing.assert_close(out, m, rtol=0, atol=1e-12)
    spike = torch.zeros((1, 16, 16), dtype=torch.float64)
    spike[0, 8, 8] = 1.0
    blurred = blur_mask(spike, (1.5, 0.7), fill=0.0)
    assert float(blurred.sum()) == pytest.approx(1.0, abs=1e-12)
    # separable Gaussian: the variance along each axis is sigma^2 (3-sigma kernel)
    rows = torch.arange(16, dtype=torch.float64)
    var_r = float((blurred[0].sum(1) * (rows - 8) ** 2).sum())
    assert var_r == pytest.approx(1.5**2, rel=0.03)


@pytest.mark.parametrize(
    ("gamma", "dot_gain"), [(0.7, 0.0), (1.3, 0.25), (1.0, -0.25), (0.85, 0.1)]
)
def test_tone_curve_is_monotone_and_stays_in_the_printable_range(gamma, dot_gain):
    y = torch.linspace(0, 1, 1001, dtype=torch.float64)
    out = print_tone(y, gamma, dot_gain)
    assert torch.all(out.diff() >= -1e-15)
    assert float(out.min()) >= 0.0 and float(out.max()) <= 1.0
    assert float(out[0]) == pytest.approx(0.0, abs=1e-12)
    assert float(out[-1]) == pytest.approx(1.0, abs=1e-12)
    # closed form at the middle of the range
    c = 1 - 0.5**gamma
    assert float(print_tone(torch.tensor([0.5], dtype=torch.float64), gamma, dot_gain)) == (
        pytest.approx(1 - (c + 4 * dot_gain * c * (1 - c)), rel=1e-12)
    )


def test_fabricated_masks_stay_within_the_printed_range(rng):
    logits = _logits(rng, k=4, res=16) * 4
    # the mask as built (a pose error makes effective masks, not transmittances)
    built = PerturbationModel(pose_orientation_rad=0.0, pose_position_m=0.0)
    for _ in range(5):
        draw = built.scaled(2.0).draw(4, rng)
        lo, hi = draw.transmittance_range(RANGE)
        m = fabricated_transmittance(logits, RANGE, draw, TEXEL_M)
        assert float(m.min()) >= lo - 1e-12 and float(m.max()) <= hi + 1e-12


def test_gradient_through_the_fabricated_mask_plane_matches_central_differences(rng):
    logits = _logits(rng, k=2, res=6).requires_grad_(True)
    draw = PerturbationDraw(
        shift_m=[[0.31 * MM, -0.17 * MM], [-0.4 * MM, 0.2 * MM]],
        rotation_rad=np.radians([3.0, -1.5]),
        gamma=0.8,
        dot_gain=0.12,
        min_transmittance_error=0.003,
        max_transmittance_error=-0.04,
        blur_sigma_m=0.4 * MM,
    )
    weights = torch.from_numpy(rng.normal(size=(2, 6, 6)))

    def f(x: torch.Tensor) -> torch.Tensor:
        return (fabricated_transmittance(x, RANGE, draw, TEXEL_M) * weights).sum()

    assert torch.autograd.gradcheck(f, (logits,), eps=1e-6, atol=1e-7, rtol=1e-5)


def test_gain_mismatch_scales_measurements_exactly_and_offset_adds_volts(rng):
    from support import linear_task

    from mincam_render.learn import train as tr

    data = linear_task(n=40, k=3)
    model = tr.build_mincam(data)
    t = torch.from_numpy(data.transport)
    k = model.num_pixels
    gain = rng.uniform(0.9, 1.1, k)
    offset = rng.uniform(-2e-3, 2e-3, k)
    base = PerturbationDraw.identity(k)
    nominal = model.measure(t, noise=False).detach()
    assert 0 < float(nominal.max()) < model.camera.electronics.full_scale_v  # unsaturated
    scaled = model.measure(t, noise=False, draw=dataclasses.replace(base, gain=gain))
    expected = nominal * torch.from_numpy(gain).float()
    torch.testing.assert_close(scaled, expected, rtol=1e-6, atol=0)
    shifted = model.measure(t, noise=False, draw=dataclasses.replace(base, offset_v=offset))
    torch.testing.assert_close(
        shifted, nominal + torch.from_numpy(offset).float(), rtol=0, atol=1e-7
    )
    assert torch.equal(model.measure(t, noise=False, draw=base), nominal)


@pytest.mark.parametrize(
    ("kwargs", "field", "unit"),
    [
        ({"mask_shift_m": -0.1 * MM}, "mask_shift_m", "m"),
        ({"mask_shift_m": 0.3}, "mask_shift_m", "m"),  # 0.3 m: millimetres given as metres
        ({"mask_rotation_rad": float("nan")}, "mask_rotation_rad", "rad"),
        ({"mask_rotation_rad": 2.0}, "mask_rotation_rad", "rad"),  # degrees given as radians
        ({"gamma_deviation": 1.0}, "gamma_deviation", ""),
        ({"dot_gain_deviation": 0.3}, "dot_gain_deviation", ""),
        ({"gain_mismatch_fraction": float("inf")}, "gain_mismatch_fraction", ""),
        ({"gain_mismatch_fraction": 5.0}, "gain_mismatch_fraction", ""),  # percent as fraction
        ({"dark_offset_v": "2mV"}, "dark_offset_v", "V"),
        ({"mask_blur_m": True}, "mask_blur_m", "m"),
        ({"pose_orientation_rad": -2.0 * DEG}, "pose_orientation_rad", "rad"),
        ({"pose_orientation_rad": 31.0 * DEG}, "pose_orientation_rad", "rad"),
        ({"pose_position_m": -0.5 * CM}, "pose_position_m", "m"),
        ({"pose_depth_m": 0.0}, "pose_depth_m", "m"),
        ({"pose_depth_m": -2.0}, "pose_depth_m", "m"),
    ],
)
def test_bad_magnitudes_are_refused_naming_the_field_and_unit(kwargs, field, unit):
    with pytest.raises(ValueError, match=rf"PerturbationModel.{field} = .*[\])] ?{unit}$"):
        PerturbationModel(**kwargs)


@pytest.mark.parametrize(
    ("record", "field"),
    [
        ({"mask_shift_mm": -0.1}, "mask_shift_mm = -0.1"),
        ({"mask_rotation_deg": 46.0}, "mask_rotation_deg = 46.0"),
        ({"gain_mismatch_percent": 100.0}, "gain_mismatch_percent = 100.0"),
        ({"pose_orientation_deg": 40}, "pose_orientation_deg = 40"),
        ({"pose_position_cm": float("nan")}, "pose_position_cm = nan"),
        ({"mask_shift_m": 3e-4}, "unknown field.*mask_shift_m"),  # SI names are not records'
    ],
)
def test_bad_records_are_refused_naming_the_records_field(record, field):
    with pytest.raises(ValueError, match=f"PerturbationModel.*{field}"):
        PerturbationModel.from_record(record)


def test_records_keep_the_workshop_units_and_round_trip():
    """Files and options hold mm, deg, % and cm; the model holds metres, radians, fractions."""
    record = PerturbationModel().to_record()
    assert record == {
        "mask_shift_mm": 0.3,
        "mask_rotation_deg": 2.0,
        "gamma_deviation": 0.15,
        "dot_gain_deviation": 0.1,
        "min_transmittance_error": 0.005,
        "max_transmittance_error": 0.05,
        "mask_blur_mm": 0.1,
        "gain_mismatch_percent": 5.0,
        "dark_offset_v": 2e-3,
        "pose_orientation_deg": 2.0,
        "pose_position_cm": 2.0,
        "pose_depth_m": 4.0,
    }
    assert PerturbationModel.from_record(record) == PerturbationModel()
    model = PerturbationModel.from_record({"mask_shift_mm": 0.5, "mask_rotation_deg": 90 / 4})
    assert model.mask_shift_m == pytest.approx(5e-4, rel=1e-15)
    assert model.mask_rotation_rad == pytest.approx(math.pi / 8, rel=1e-15)
    assert model.gain_mismatch_fraction == 0.05 and model.pose_position_m == 0.02
    assert set(record) == {record_name(f.name) for f in dataclasses.fields(PerturbationModel)}


@pytest.mark.parametrize("gamma", [0.0, -1.0, float("nan")])
def test_gamma_must_be_positive(gamma):
    with pytest.raises(ValueError, match="gamma"):
        print_tone(torch.ones(3), gamma, 0.0)
    with pytest.raises(ValueError, match="PerturbationDraw.gamma"):
        PerturbationDraw(shift_m=np.zeros((1, 2)), rotation_rad=[0.0], gamma=gamma)


def test_draws_of_bad_shape_or_range_are_refused():
    with pytest.raises(ValueError, match="rotation_rad"):
        PerturbationDraw(shift_m=np.zeros((2, 2)), rotation_rad=[0.0])
    with pytest.raises(ValueError, match="PerturbationDraw.blur_sigma_m = -1.0 m"):
        PerturbationDraw(shift_m=np.zeros((1, 2)), rotation_rad=[0.0], blur_sigma_m=-1.0)
    with pytest.raises(ValueError, match="PerturbationDraw.dot_gain = 0.3"):
        PerturbationDraw(shift_m=np.zeros((1, 2)), rotation_rad=[0.0], dot_gain=0.3)
    with pytest.raises(ValueError, match="is empty"):
        PerturbationDraw(
            shift_m=np.zeros((1, 2)), rotation_rad=[0.0], max_transmittance_error=-0.7
        ).transmittance_range(RANGE)
    with pytest.raises(ValueError, match="factor"):
        PerturbationModel().scaled(-1.0)
    with pytest.raises(ValueError, match="pixels"):
        fabricated_transmittance(torch.zeros(2, 4, 4), RANGE, PerturbationDraw.identity(3), TEXEL_M)


def test_draws_are_within_their_ranges_and_reproducible():
    model = PerturbationModel()
    a = model.draw(8, np.random.default_rng(5))
    b = model.draw(8, np.random.default_rng(5))
    assert np.array_equal(a.shift_m, b.shift_m) and a.gamma == b.gamma
    assert np.abs(a.shift_m).max() <= 0.3 * MM and np.abs(a.rotation_rad).max() <= 2.0 * DEG
    assert abs(a.gamma - 1) <= 0.15 and 0 <= a.blur_sigma_m <= 0.1 * MM
    assert np.abs(a.gain - 1).max() <= 0.05 and np.abs(a.offset_v).max() <= 2e-3
    assert np.abs(a.pose_rotation_rad).max() <= 2.0 * DEG
    assert np.abs(a.pose_offset_m).max() <= 2.0 * CM
    assert a.has_pose_error and a.pose_depth_m == 4.0


@pytest.mark.parametrize("scale", [0.5, 1.0, 2.5])
def test_draws_at_the_extremes_of_u_pass_the_draws_own_checks(scale):
    """draw_from skips the draw's checks (valid by construction): the checks agree."""
    model = PerturbationModel().scaled(scale)
    n = model.uniforms_needed(3)
    for u in (np.zeros(n), np.ones(n), np.random.default_rng(7).random(n)):
        draw = model.draw_from(u, 3)
        checked = dataclasses.replace(draw)  # runs PerturbationDraw's validation
        for f in dataclasses.fields(draw):
            assert np.array_equal(getattr(checked, f.name), getattr(draw, f.name)), f.name
            assert np.asarray(getattr(draw, f.name)).dtype == np.float64


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan")])
def test_uniforms_outside_the_unit_interval_are_refused(bad):
    model = PerturbationModel()
    u = np.full(model.uniforms_needed(2), 0.5)
    u[4] = bad
    with pytest.raises(ValueError, match=r"u must be uniforms in \[0, 1\]"):
        model.draw_from(u, 2)


def test_camera_texel_size_is_what_the_fabrication_uses():
    cam = FreeformCamera(mask_resolution=(32, 32), layout=DetectorLayout.row(count=1, pitch_m=0.02))
    assert cam.texel_size_m == pytest.approx(TEXEL_M)


def test_no_rotation_and_no_shift_place_every_texel_where_it_was(rng):
    m = torch.from_numpy(rng.uniform(0.1, 0.6, (3, 7, 5)))
    out = place_masks(m, np.zeros((3, 2)), np.zeros(3), fill=0.01)
    torch.testing.assert_close(out, m, rtol=0, atol=1e-15)


def test_gamma_one_and_no_dot_gain_print_the_design_exactly():
    y = torch.linspace(0, 1, 101, dtype=torch.float64)
    assert torch.equal(print_tone(y, 1.0, 0.0), y)


@pytest.mark.parametrize("dot_gain", [-0.25, -0.1, 0.05, 0.25])
def test_dot_gain_darkens_mid_tones_by_its_value_and_leaves_film_and_full_ink(dot_gain):
    """Dot gain g is the ink coverage gained at 50 %: bare film and full ink keep their tone.

    Tones ``y`` 0, 1/4, 1/2, 3/4, 1 (coverage ``c = 1 - y``) print as
    ``y - 4 g y (1 - y)``: 0, 1/4 - 3g/4, 1/2 - g, 3/4 - 3g/4, 1.
    """
    stripes = torch.tensor([[[0.0, 0.25, 0.5, 0.75, 1.0]]], dtype=torch.float64)
    logits = torch.logit(stripes.clamp(1e-300, 1.0))  # sigmoid(logit(1)) = 1 in float64
    draw = dataclasses.replace(PerturbationDraw.identity(1), dot_gain=dot_gain)
    m = fabricated_transmittance(logits, RANGE, draw, TEXEL_M)
    lo, hi = RANGE
    g = dot_gain
    expected = torch.tensor(
        [[[0.0, 0.25 - 0.75 * g, 0.5 - g, 0.75 - 0.75 * g, 1.0]]], dtype=torch.float64
    )
    torch.testing.assert_close(m, lo + (hi - lo) * expected, rtol=0, atol=1e-14)
