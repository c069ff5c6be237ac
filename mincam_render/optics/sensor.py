r"""Detector electronics: from optical power to the freeform pixel's output voltage.

Paper eqs. 3-5 plus photon shot noise (which the paper omits):

.. math::

    I = R\,P + I_{dark}, \qquad
    p_n = G I + n_{shot} + n_r + n_q, \qquad
    p_f = \begin{cases} p_n & p_n \le p_{max} \\
          \alpha (p_n - p_{max}) + p_{max} & p_n > p_{max} \end{cases}

with ``n_shot ~ N(0, G^2 q I / t)`` (Poisson photo-electrons over the
integration time ``t``, Gaussian limit), ``n_r ~ N(0, sigma_r^2)``,
``n_q ~ U(0, LSB)``. All tensors are torch; voltages in volts.

Noise is reparameterised (``value + sigma * eps``) so gradients flow through it.
Shot and read noise are independent Gaussians, so their sum is drawn as one,
``sqrt(G q V / t + sigma_r^2) * eps`` with ``V = G I`` (the same distribution
with one random draw and fewer ops than two). Quantisation is the paper's
additive-uniform model of rounding (eq. 4): its gradient is the identity, which
is the straight-through surrogate gradient of rounding to the LSB (an actual
``floor`` would have zero gradient almost everywhere).
"""

from __future__ import annotations

import torch

from mincam_render.optics.camera import DetectorElectronics

#: Elementary charge (C).
ELEMENTARY_CHARGE_C = 1.602176634e-19
#: Floor on the noise variance inside the square root (V^2): keeps the derivative
#: of sqrt finite in the dark without read noise (sigma 1e-15 V, below any ADC),
#: and is a normal float32.
_MIN_VARIANCE_V2 = 1e-30


def leaky_saturation(voltage_v: torch.Tensor, full_scale_v: float, slope: float) -> torch.Tensor:
    """Paper eq. 5: identity up to ``full_scale_v``, slope ``slope`` above it (V).

    Written ``v - (1 - slope) relu(v - full_scale_v)``: three ops, and slope 1
    (not ``slope``) exactly at full scale, as ``relu'(0) = 0``.
    """
    return torch.add(voltage_v, torch.relu(voltage_v - full_scale_v), alpha=slope - 1.0)


def detector_voltage(
    power_w: torch.Tensor,
    electronics: DetectorElectronics,
    *,
    noise: bool = True,
    generator: torch.Generator | None = None,
    offset_v: torch.Tensor | None = None,
) -> torch.Tensor:
    """Output voltage of each freeform pixel for the optical power on its diode.

    Args:
        power_w: ``P[..., detector]`` optical power on each diode (W), >= 0.
        electronics: responsivity, gain, noise, ADC and saturation parameters.
        noise: add shot, read and quantization noise; False gives the noiseless
            mean response (for evaluation), still with leaky saturation.
        generator: torch random generator for reproducible noise.
        offset_v: ``[detector]`` output offset of each read-out (V), added after
            the noise (it is no photocurrent: no shot noise) and before saturation;
            None adds nothing.

    Returns:
        ``p_f[..., detector]`` in volts, same shape, dtype and device as ``power_w``.

    """
    e = electronics
    g = e.gain_v_per_a
    # V = G (R P + I_dark), the constants folded in float64 once
    voltage_v = torch.add(power_w * (g * e.responsivity_a_per_w), g * e.dark_current_a)
    if noise:
        # shot variance G^2 q I / t = (G q / t) V, folded in float64: q I alone
        # underflows float32 for I < ~1e-20 A
        variance = torch.add(
            voltage_v * (g * ELEMENTARY_CHARGE_C / e.integration_time_s), e.read_noise_v**2
        ).clamp_min(_MIN_VARIANCE_V2)
        dtype, device = power_w.dtype, power_w.device
        eps = torch.randn(power_w.shape, generator=generator, dtype=dtype, device=device)
        quant = torch.rand(power_w.shape, generator=generator, dtype=dtype, device=device)
        voltage_v = torch.addcmul(voltage_v, torch.sqrt(variance), eps).add_(quant, alpha=e.lsb_v)
    if offset_v is not None:
        voltage_v = voltage_v + offset_v
    return leaky_saturation(voltage_v, e.full_scale_v, e.saturation_slope)
