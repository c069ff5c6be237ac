"""Sample counts from measured errors: Monte Carlo error falls as 1/sqrt(spp)."""

from __future__ import annotations

import math
from collections.abc import Mapping

from mincam_render.render.fidelity.constants import PILOT_SPP
from mincam_render.render.fidelity.records import NoiseBudget


def spp_for(error_at_pilot: float, target: float, cap: int, steps_per_octave: int = 1) -> int:
    """Smallest spp whose predicted error (1/sqrt(spp)) meets ``target`` (rounded up)."""
    return round_up_spp(PILOT_SPP * (error_at_pilot / target) ** 2, cap, steps_per_octave)


def round_up_spp(need: float, cap: int, steps_per_octave: int = 4) -> int:
    """``need`` rounded up on a grid of ``steps_per_octave`` steps per octave, in [1, cap].

    With ``steps_per_octave`` = 4: to ``m 2^e`` with ``m`` in 4..7 (at most 25 %
    above), then up to the next full stratification grid (a multiple of its
    integer square root, at most ``2 / sqrt(n)`` more), so that a frame's
    samples take one pass (:func:`mincam_render.render.transport.sample_passes`).
    """
    need = max(need, 1.0)
    octave = 2 ** math.floor(math.log2(need))
    step = max(octave // steps_per_octave, 1)
    n = int(step * math.ceil(need / step - 1e-9))
    while n % math.isqrt(n):
        n += 1
    return int(min(cap, n))


def split_noise_budget(
    target: float,
    biases: Mapping[str, float],
    difference: tuple[float, float, int | None],
    background: tuple[float, float, int | None],
) -> NoiseBudget:
    """Share the error left by ``biases`` between the noises of ``X - C`` and of ``B``.

    Errors add in quadrature: ``target^2 = sum(bias^2) + x^2 + y^2`` with ``x``
    the noise of ``X - C`` and ``y`` that of the background. With ``x = a_x
    sqrt(PILOT_SPP / spp_x)`` and cost ``c_x spp_x`` per frame (likewise for
    ``y``), the cheapest split has ``x^2 / y^2 = a_x sqrt(c_x) / (a_y sqrt(c_y))``.
    A noise whose spp is set by a flag takes its share first.

    Args:
        target: target relative measurement error.
        biases: ``{name: rms}`` of the fixed (sample-independent) errors.
        difference: ``(noise at PILOT_SPP, cost per sample per frame, spp flag or None)``.
        background: the same for the background.

    Returns:
        The noise each of ``difference_noise`` and ``background_noise`` may have.
    """
    fixed2 = sum(b * b for b in biases.values())
    # biases eating the budget leave each noise at least a tenth of the target
    left2 = max(target * target - fixed2, 0.1 * target * target)
    noises = {"difference_noise": difference, "background_noise": background}
    shares = {
        name: pilot * math.sqrt(PILOT_SPP / flag)
        for name, (pilot, _, flag) in noises.items()
        if flag is not None
    }
    free = [(name, pilot, cost) for name, (pilot, cost, flag) in noises.items() if flag is None]
    rest2 = max(left2 - sum(v * v for v in shares.values()), 0.05 * left2)
    weights = {name: pilot * math.sqrt(max(cost, 1e-12)) for name, pilot, cost in free}
    total = sum(weights.values()) or 1.0
    for name, w in weights.items():
        shares[name] = math.sqrt(rest2 * w / total)
    return NoiseBudget(
        target=target,
        biases=dict(biases),
        noises=shares,
        biases_exceed_target=fixed2 > 0.9 * target * target,
    )
