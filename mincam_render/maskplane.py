r"""The differentiable mask plane: mask logits -> transmittance -> detector power.

This is the one module that converts between Dr.Jit and PyTorch (``dr.wrap``).
The measurement of detector ``k`` for frame ``b`` is

.. math::

    P_{bk} = \sum_{v,u} T_{bkvu}\, M_{kvu}, \qquad
    M = m_{lo} + (m_{hi} - m_{lo})\,\sigma(M_t)

(paper eqs. 1-2 with the printable range of supplement B). ``T`` is the
transport image in watts (see :mod:`mincam_render.transport`), ``M_t`` the
unbounded logits that training optimises.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
import torch


def _sigmoid(x):
    """Logistic function of a Dr.Jit array, finite with finite gradients for any x.

    exp(-|x|) never overflows, so neither branch of the select (whose unused
    branch still receives a zero cotangent) can produce inf or NaN; the gradient
    at |x| = 50 is e^-50 ~ 2e-22, a normal float32. |x| is written as a select,
    not dr.abs, whose derivative at exactly 0 (the usual initial logit) is 0.
    """
    z = dr.exp(dr.select(x >= 0, -x, x))
    return dr.select(x >= 0, 1.0 / (1.0 + z), z / (1.0 + z))


@dr.wrap(source="torch", target="drjit")
def _power_drjit(transport, logits, lo: float, hi: float):
    """Dr.Jit side of :func:`mask_power`; tensors arrive as Dr.Jit TensorXf(64)."""
    t_shape = transport.shape
    n_det, rows, cols = logits.shape
    n_tex = rows * cols
    batch = t_shape[0]
    float_t = type(transport.array)
    index_t = dr.uint32_array_t(float_t)
    m = lo + (hi - lo) * _sigmoid(logits.array)
    idx = dr.arange(index_t, batch * n_det * n_tex) % (n_det * n_tex)
    prod = transport.array * dr.gather(float_t, m, idx)
    power = dr.block_sum(prod, n_tex)
    return type(transport)(power, (batch, n_det))


def transmittance(logits: torch.Tensor, transmittance_range: tuple[float, float]) -> torch.Tensor:
    """Mask transmittance ``M`` (0-1) from logits, same shape; differentiable (torch)."""
    lo, hi = transmittance_range
    return lo + (hi - lo) * torch.sigmoid(logits)


def logits_for_transmittance(
    m: np.ndarray | torch.Tensor, transmittance_range: tuple[float, float]
) -> torch.Tensor:
    """Inverse of :func:`transmittance`; ``m`` must lie strictly inside the range."""
    lo, hi = transmittance_range
    m_t = torch.as_tensor(m, dtype=torch.float32)
    if torch.any(m_t <= lo) or torch.any(m_t >= hi):
        raise ValueError(
            f"transmittance values must lie strictly inside ({lo:g}, {hi:g}); got "
            f"[{float(m_t.min()):g}, {float(m_t.max()):g}]"
        )
    y = (m_t - lo) / (hi - lo)
    return torch.log(y) - torch.log1p(-y)


def mask_power(
    transport: torch.Tensor, logits: torch.Tensor, transmittance_range: tuple[float, float]
) -> torch.Tensor:
    """Power on each detector through its mask, differentiable in both inputs (torch).

    Args:
        transport: ``T[batch, detector, row, col]`` in watts, float32 or float64.
        logits: ``M_t[detector, row, col]``, unbounded, same dtype and device.
        transmittance_range: ``(lo, hi)`` printable transmittance, 0 <= lo < hi <= 1.

    Returns:
        ``P[batch, detector]`` in watts.

    Raises:
        ValueError: shapes, dtypes or devices do not match.

    """
    if transport.ndim != 4:
        raise ValueError(
            f"transport has shape {tuple(transport.shape)}: expected (batch, detector, row, col)"
        )
    if tuple(logits.shape) != tuple(transport.shape[1:]):
        raise ValueError(
            f"logits shape {tuple(logits.shape)} does not match transport's (detector, row, col) "
            f"= {tuple(transport.shape[1:])}"
        )
    if transport.dtype != logits.dtype or transport.dtype not in (torch.float32, torch.float64):
        raise ValueError(
            f"transport ({transport.dtype}) and logits ({logits.dtype}) must share float32 or "
            "float64"
        )
    if transport.device != logits.device:
        raise ValueError(f"transport on {transport.device} but logits on {logits.device}")
    lo, hi = (float(v) for v in transmittance_range)
    if not 0.0 <= lo < hi <= 1.0:
        raise ValueError(f"transmittance_range = {transmittance_range}: need 0 <= lo < hi <= 1")
    # dr.wrap converts plain tensors only: pass views, never an nn.Parameter itself
    transport = transport.contiguous().view(transport.shape)
    return _power_drjit(transport, logits.contiguous().view(logits.shape), lo, hi)
