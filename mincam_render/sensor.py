r"""Detector electronics: from optical power to the freeform pixel's output voltage.

Paper eqs. 3-5 plus photon shot noise (which the paper omits):

.. math::

    I = R\,P + I_{dark}, \qquad
    p_n = G I + n_{shot} + n_r + n_q, \qquad
    p_f = \begin{cases} p_n & p_n \le p_{max} \\
          \alpha (p_n - p_{max}) + p_{max} & p_n > p_{max} \end{cases}

with ``n_shot ~ N(0, G^2 q I / t)`` (Poisson photo-electrons over the
integration time ``t``, Gaussian limit), ``n_r ~ N(0, sigma_r^2)``,
``n_q ~ U(0, LSB)``. Noise is reparameterised (``value + sigma * eps``) so
gradients flow through it. All tensors are torch; voltages in volts.
"""

from __future__ import annotations

import math

import torch

from .camera import DetectorElectronics

#: Elementary charge (C).
ELEMENTARY_CHARGE_C = 1.602176634e-19
#: Floor on the photocurrent inside the shot-noise square root (A): keeps the
#: derivative of sqrt finite at zero light.
_MIN_CURRENT_A = 1e-30


def leaky_saturation(voltage_v: torch.Tensor, full_scale_v: float, slope: float) -> torch.Tensor:
    """Paper eq. 5: identity up to ``full_scale_v``, slope ``slope`` above it (V)."""
    over = voltage_v - full_scale_v
    return torch.where(over > 0, full_scale_v + slope * over, voltage_v)


def detector_voltage(
    power_w: torch.Tensor,
    electronics: DetectorElectronics,
    *,
    noise: bool = True,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Output voltage of each freeform pixel for the optical power on its diode.

    Args:
        power_w: ``P[..., detector]`` optical power on each diode (W), >= 0.
        electronics: responsivity, gain, noise, ADC and saturation parameters.
        noise: add shot, read and quantization noise; False gives the noiseless
            mean response (for evaluation), still with leaky saturation.
        generator: torch random generator for reproducible noise.

    Returns:
        ``p_f[..., detector]`` in volts, same shape, dtype and device as ``power_w``.

    """
    e = electronics
    current_a = e.responsivity_a_per_w * power_w + e.dark_current_a
    voltage_v = e.gain_v_per_a * current_a
    if noise:
        shape, kw = power_w.shape, {"dtype": power_w.dtype, "device": power_w.device}
        # sqrt(q / t) is taken in float64 here: q * I itself underflows float32 for
        # I < ~1e-20 A, and sqrt'(0) = inf then turned the gradient into inf/NaN.
        shot_sigma_v = (
            e.gain_v_per_a
            * math.sqrt(ELEMENTARY_CHARGE_C / e.integration_time_s)
            * torch.sqrt(torch.clamp(current_a, min=_MIN_CURRENT_A))
        )
        eps = torch.randn(shape, generator=generator, **kw)
        read = torch.randn(shape, generator=generator, **kw)
        quant = torch.rand(shape, generator=generator, **kw)
        voltage_v = voltage_v + shot_sigma_v * eps + e.read_noise_v * read + e.lsb_v * quant
    return leaky_saturation(voltage_v, e.full_scale_v, e.saturation_slope)
