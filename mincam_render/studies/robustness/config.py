"""What the robustness study measures, as data (no PyTorch or Mitsuba import)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from mincam_render.core.checks import check_int, check_number
from mincam_render.optics.perturbation import PerturbationModel, PerturbationTerm

#: The curve of every term at once.
MIX = "mix"
#: Curves in order: every term alone, then the mix.
CURVES = (*(t.value for t in PerturbationTerm), MIX)


@dataclass(frozen=True, kw_only=True)
class RobustnessConfig:
    """What :func:`~mincam_render.studies.robustness.study.robustness_curves` measures.

    Args:
        perturbation: the default half-ranges (level 1).
        levels: magnitudes as multiples of the defaults, increasing from 0.
        draws: built cameras per level (Monte Carlo), >= 2.
        seed: root seed of the draws.
        allowed_increase: relative error increase a tolerance allows, (0, 10).
    """

    perturbation: PerturbationModel = field(default_factory=PerturbationModel)
    levels: tuple[float, ...] = (0.0, 0.5, 1.0, 1.5, 2.0)
    draws: int = 20
    seed: int = 0
    allowed_increase: float = 0.10

    def __post_init__(self) -> None:
        levels = tuple(float(v) for v in self.levels)
        ok = len(levels) >= 2 and levels[0] == 0.0 and all(map(math.isfinite, levels))
        if not ok or any(b <= a for a, b in zip(levels, levels[1:], strict=False)):
            raise ValueError(
                f"RobustnessConfig.levels = {self.levels!r}: allowed at least 2 finite "
                "multiples of the defaults, increasing from 0"
            )
        object.__setattr__(self, "levels", levels)
        check_int("RobustnessConfig.draws", self.draws, 2)
        check_number(
            "RobustnessConfig.allowed_increase",
            self.allowed_increase,
            0,
            10,
            lo_open=True,
            hi_open=True,
            numpy=True,
        )
