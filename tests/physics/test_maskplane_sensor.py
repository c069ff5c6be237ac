"""Mask plane (Dr.Jit via dr.wrap) and detector electronics (torch)."""

import numpy as np
import pytest
import torch

from mincam_render import (
    DetectorElectronics,
    detector_voltage,
    leaky_saturation,
    logits_for_transmittance,
    mask_power,
    transmittance,
)
from mincam_render.optics.sensor import ELEMENTARY_CHARGE_C

RANGE = (0.01, 0.67)


def numpy_power(t, logits):
    m = RANGE[0] + (RANGE[1] - RANGE[0]) / (1 + np.exp(-logits))
    return (t * m[None]).sum(axis=(-2, -1))


def test_mask_power_matches_numpy(rng):
    t = rng.uniform(0, 1e-9, size=(5, 3, 4, 6))
    logits = rng.normal(0, 3, size=(3, 4, 6))
    for dtype in (torch.float32, torch.float64):
        p = mask_power(torch.tensor(t, dtype=dtype), torch.tensor(logits, dtype=dtype), RANGE)
        assert p.shape == (5, 3) and p.dtype == dtype
        np.testing.assert_allclose(
            p.numpy(), numpy_power(t, logits), rtol=1e-5 if dtype == torch.float32 else 1e-12
        )


def test_open_and_closed_masks_hit_the_printable_limits(rng):
    t = torch.tensor(rng.uniform(0, 1, size=(2, 1, 3, 3)))
    hi = mask_power(t, torch.full((1, 3, 3), 60.0, dtype=torch.float64), RANGE)
    lo = mask_power(t, torch.full((1, 3, 3), -60.0, dtype=torch.float64), RANGE)
    np.testing.assert_allclose(hi.numpy(), 0.67 * t.sum((-2, -1)).numpy(), rtol=1e-12)
    np.testing.assert_allclose(lo.numpy(), 0.01 * t.sum((-2, -1)).numpy(), rtol=1e-12)


def central_fd(f, x, h):
    g = torch.zeros_like(x)
    flat = g.view(-1)
    for i in range(x.numel()):
        xp, xm = x.clone(), x.clone()
        xp.view(-1)[i] += h
        xm.view(-1)[i] -= h
        flat[i] = (f(xp) - f(xm)) / (2 * h)
    return g


def test_mask_power_gradients_match_finite_differences(rng):
    t = torch.tensor(rng.uniform(0, 1, size=(3, 2, 3, 4)))
    logits = torch.tensor(rng.normal(0, 2, size=(2, 3, 4)))
    weights = torch.tensor(rng.normal(size=(3, 2)))

    def loss(tt, ll):
        return (mask_power(tt, ll, RANGE) * weights).sum()

    lg = logits.clone().requires_grad_()
    tg = t.clone().requires_grad_()
    loss(tg, lg).backward()
    np.testing.assert_allclose(
        lg.grad.numpy(),
        central_fd(lambda x: loss(t, x), logits, 1e-6).numpy(),
        rtol=1e-6,
        atol=1e-10,
    )
    np.testing.assert_allclose(
        tg.grad.numpy(),
        central_fd(lambda x: loss(x, logits), t, 1e-6).numpy(),
        rtol=1e-6,
        atol=1e-10,
    )


def test_torch_grad_equals_drjit_side_closed_form(rng):
    """torch .grad across dr.wrap equals the analytic d/dlogit of sum T*M."""
    t = torch.tensor(rng.uniform(0, 1, size=(4, 2, 3, 3)), dtype=torch.float32)
    logits = torch.tensor(rng.normal(0, 1, size=(2, 3, 3)), dtype=torch.float32, requires_grad=True)
    mask_power(t, logits, RANGE).sum().backward()
    s = torch.sigmoid(logits.detach())
    expected = t.sum(0) * (RANGE[1] - RANGE[0]) * s * (1 - s)
    np.testing.assert_allclose(logits.grad.numpy(), expected.numpy(), rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("logit", [0.0, 50.0, -50.0])
def test_extreme_logits_keep_finite_nonzero_gradients(logit):
    t = torch.full((1, 1, 2, 2), 1e-9)
    logits = torch.full((1, 2, 2), logit, requires_grad=True)
    p = mask_power(t, logits, RANGE)
    v = detector_voltage(p, DetectorElectronics(), noise=False)
    v.sum().backward()
    assert torch.isfinite(p).all() and torch.isfinite(logits.grad).all()
    assert (logits.grad.abs() > 0).all()


@pytest.mark.parametrize("logit", [90.0, -90.0, 500.0, -500.0, 1e6])
def test_logits_far_beyond_range_stay_finite(logit):
    logits = torch.full((1, 2, 2), logit, requires_grad=True)
    p = mask_power(torch.ones(1, 1, 2, 2), logits, RANGE)
    p.sum().backward()
    assert torch.isfinite(p).all() and torch.isfinite(logits.grad).all()


def test_transmittance_round_trip(rng):
    m = rng.uniform(0.02, 0.66, size=(3, 5))
    back = transmittance(logits_for_transmittance(m, RANGE).double(), RANGE)
    np.testing.assert_allclose(back.numpy(), m, rtol=1e-5)
    with pytest.raises(ValueError, match="strictly inside"):
        logits_for_transmittance(np.array([0.9]), RANGE)


@pytest.mark.parametrize(
    ("t_shape", "l_shape", "match"),
    [((2, 3, 4), (3, 4), "expected"), ((1, 2, 3, 4), (2, 4, 3), "does not match")],
)
def test_mask_power_shape_errors(t_shape, l_shape, match):
    with pytest.raises(ValueError, match=match):
        mask_power(torch.zeros(t_shape), torch.zeros(l_shape), RANGE)


def test_mask_power_dtype_error():
    with pytest.raises(ValueError, match="float32 or float64"):
        mask_power(torch.zeros(1, 1, 2, 2), torch.zeros(1, 2, 2, dtype=torch.float64), RANGE)


# ---- detector electronics -------------------------------------------------------


def test_noiseless_response_is_responsivity_times_gain():
    e = DetectorElectronics(responsivity_a_per_w=0.3, gain_v_per_a=1e7, dark_current_a=1e-10)
    p = torch.tensor([[0.0, 1e-7, 5e-7]], dtype=torch.float64)
    v = detector_voltage(p, e, noise=False)
    np.testing.assert_allclose(v.numpy(), (0.3 * p.numpy() + 1e-10) * 1e7, rtol=1e-12)


def test_leaky_saturation_values_and_slopes():
    v = torch.tensor([1.0, 3.2, 4.2, 103.2], dtype=torch.float64, requires_grad=True)
    out = leaky_saturation(v, 3.2, 0.01)
    np.testing.assert_allclose(out.detach().numpy(), [1.0, 3.2, 3.21, 4.2], rtol=1e-12)
    out.sum().backward()
    np.testing.assert_allclose(v.grad.numpy(), [1.0, 1.0, 0.01, 0.01])


def test_noise_statistics_match_the_model():
    e = DetectorElectronics(read_noise_v=400e-6, integration_time_s=1 / 30)
    n = 200_000
    gen = torch.Generator().manual_seed(0)
    dark = torch.zeros(n, 1, dtype=torch.float64)
    v = detector_voltage(dark, e, generator=gen)
    # read noise and U(0, LSB) quantization noise add: mean LSB/2, var sigma^2 + LSB^2/12
    assert float(v.mean()) == pytest.approx(e.lsb_v / 2, abs=5 * 400e-6 / np.sqrt(n))
    assert float(v.std()) == pytest.approx(np.sqrt(400e-6**2 + e.lsb_v**2 / 12), rel=0.01)
    # shot noise: variance G^2 q I / t on top (bright, no read noise)
    e2 = DetectorElectronics(read_noise_v=0.0, gain_v_per_a=1e7, responsivity_a_per_w=0.3)
    p = torch.full((n, 1), 2e-7, dtype=torch.float64)  # 0.6 V: unsaturated
    v2 = detector_voltage(p, e2, generator=gen)
    current = 0.3 * 2e-7
    shot_var = (1e7) ** 2 * ELEMENTARY_CHARGE_C * current / e2.integration_time_s
    assert float(v2.var()) == pytest.approx(shot_var + e2.lsb_v**2 / 12, rel=0.02)


def test_noise_off_is_deterministic_and_noise_on_is_seeded():
    e = DetectorElectronics()
    p = torch.full((4, 3), 1e-7)
    assert torch.equal(detector_voltage(p, e, noise=False), detector_voltage(p, e, noise=False))
    a = detector_voltage(p, e, generator=torch.Generator().manual_seed(3))
    b = detector_voltage(p, e, generator=torch.Generator().manual_seed(3))
    c = detector_voltage(p, e, generator=torch.Generator().manual_seed(4))
    assert torch.equal(a, b) and not torch.equal(a, c)


def test_sensor_gradcheck_float64():
    e = DetectorElectronics(full_scale_v=3.2, saturation_slope=0.05)
    p = torch.tensor(
        [[1e-8, 4e-7, 2e-6]], dtype=torch.float64, requires_grad=True
    )  # last saturates

    def f(x):
        return detector_voltage(x * 1e-6, e, generator=torch.Generator().manual_seed(1))

    assert torch.autograd.gradcheck(f, (p * 1e6,), eps=1e-6, atol=1e-6, rtol=1e-4)


def test_full_chain_gradient_matches_finite_differences_with_common_random_numbers(rng):
    """logits -> mask plane -> electronics (with noise) -> loss, float64."""
    e = DetectorElectronics()
    t = torch.tensor(rng.uniform(0, 2e-9, size=(6, 2, 4, 4)))  # some detectors saturate
    logits = torch.tensor(rng.normal(0, 1, size=(2, 4, 4)))
    target = torch.tensor(rng.uniform(0, 3, size=(6, 2)))

    def loss(x):
        v = detector_voltage(mask_power(t, x, RANGE), e, generator=torch.Generator().manual_seed(9))
        return ((v - target) ** 2).mean()

    x = logits.clone().requires_grad_()
    loss(x).backward()
    fd = central_fd(loss, logits, 1e-5)
    np.testing.assert_allclose(x.grad.numpy(), fd.numpy(), rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("radiance", [1e-6, 1.0, 1e6])
def test_chain_finite_with_gradients_from_moonless_to_sunlit(radiance):
    """Transport scales with radiance: ~1e-9 W per texel per W m^-2 sr^-1 for the prototype."""
    t = torch.full((2, 3, 8, 8), 1e-9 * radiance)
    logits = torch.zeros(3, 8, 8, requires_grad=True)
    v = detector_voltage(
        mask_power(t, logits, RANGE),
        DetectorElectronics(),
        generator=torch.Generator().manual_seed(0),
    )
    v.sum().backward()
    assert torch.isfinite(v).all() and torch.isfinite(logits.grad).all()
    assert (logits.grad.abs() > 0).all()
    if radiance == 1e6:
        assert (v > DetectorElectronics().full_scale_v).all()  # saturated, yet leaky gradients


def test_mask_power_accepts_an_nn_parameter():
    logits = torch.nn.Parameter(torch.zeros(1, 2, 2))
    p = mask_power(torch.ones(3, 1, 2, 2), logits, RANGE)
    p.sum().backward()
    np.testing.assert_allclose(p.detach().numpy(), 4 * (0.01 + 0.66 * 0.5), rtol=1e-6)
    np.testing.assert_allclose(logits.grad.numpy(), 3 * 0.66 * 0.25, rtol=1e-6)


def test_torch_mask_plane_gradcheck_float64(rng):
    """The plain-torch product (bmm on a permuted view) against autograd's numerical Jacobian."""
    from mincam_render.optics.maskplane import power_through

    t = torch.tensor(rng.uniform(0, 1, size=(5, 3, 2, 4)), requires_grad=True)
    m = torch.tensor(rng.uniform(0.01, 0.67, size=(3, 2, 4)), requires_grad=True)
    assert torch.autograd.gradcheck(power_through, (t, m), eps=1e-6, atol=1e-8, rtol=1e-6)
    logits = torch.tensor(rng.normal(0, 3, size=(3, 2, 4)), requires_grad=True)
    assert torch.autograd.gradcheck(
        lambda x: mask_power(t.detach(), x, RANGE), (logits,), eps=1e-6, atol=1e-8, rtol=1e-6
    )


@pytest.mark.parametrize("backend", ["torch", "drjit"])
def test_both_mask_plane_backends_match_numpy(rng, backend):
    from mincam_render.optics.maskplane import MaskPlaneBackend

    t = rng.uniform(0, 1e-9, size=(7, 2, 3, 5))
    logits = rng.normal(0, 3, size=(2, 3, 5))
    p = mask_power(torch.tensor(t), torch.tensor(logits), RANGE, backend=MaskPlaneBackend(backend))
    np.testing.assert_allclose(p.numpy(), numpy_power(t, logits), rtol=1e-12)
