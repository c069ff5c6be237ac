"""A design's robustness, typed: what :mod:`.study` measures and ``robustness.json`` holds.

:meth:`DesignCurves.as_json` is a design's record, the same keys in the same
order as the dicts written before these classes, so the records kept in run
directories and in ``benchmarks/results/robustness.json`` read back
(:meth:`DesignCurves.from_json`). Increases are relative (``error / nominal -
1``); errors are the task's; levels are multiples of the default half-ranges.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.perturbation import PerturbationModel
from mincam_render.studies.robustness.config import RobustnessConfig


def _pair(values: Any) -> tuple[float, float]:
    lo, hi = values
    return lo, hi


@dataclass(frozen=True, kw_only=True)
class CurveLevel:
    """One magnitude of a curve: the increase and the error with their 95 % intervals.

    Attributes:
        level: the magnitude (x the default half-ranges).
        draws: built cameras per run (1 at level 0: the design itself).
        mean_increase: relative error increase, over runs and draws.
        ci95_increase: its interval ``(lo, hi)``.
        mean_error: the error itself (each run's nominal error times one plus
            its increase); None in records measured before it was kept.
        ci95_error: its interval (None likewise).
        increases: ``[run][draw]`` relative increases (None in a summary).
    """

    level: float
    draws: int
    mean_increase: float
    ci95_increase: tuple[float, float]
    mean_error: float | None = None
    ci95_error: tuple[float, float] | None = None
    increases: tuple[tuple[float, ...], ...] | None = None

    def as_json(self, *, increases: bool = True) -> JsonObject:
        """The level's record (without the raw ``increases`` unless ``increases``)."""
        out: JsonObject = {
            "level": self.level,
            "draws": self.draws,
            "mean_increase": self.mean_increase,
            "ci95_increase": list(self.ci95_increase),
        }
        if self.mean_error is not None:
            out["mean_error"] = self.mean_error
        if self.ci95_error is not None:
            out["ci95_error"] = list(self.ci95_error)
        if increases and self.increases is not None:
            out["increases"] = [list(run) for run in self.increases]
        return out

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> CurveLevel:
        """A level's record read back."""
        ci_error, inc = record.get("ci95_error"), record.get("increases")
        return cls(
            level=record["level"],
            draws=record["draws"],
            mean_increase=record["mean_increase"],
            ci95_increase=_pair(record["ci95_increase"]),
            mean_error=record.get("mean_error"),
            ci95_error=None if ci_error is None else _pair(ci_error),
            increases=None if inc is None else tuple(tuple(run) for run in inc),
        )


@dataclass(frozen=True, kw_only=True)
class Tolerance:
    """The largest magnitude whose mean increase stays within the allowed increase.

    Attributes:
        factor: that magnitude (x the default half-ranges).
        bounded: False when every level stayed within (the tolerance is then
            at least the largest level).
        values: the curve's fields at ``factor`` (record units: mm, deg, %, cm).
    """

    factor: float
    bounded: bool
    values: Mapping[str, float]

    def as_json(self) -> JsonObject:
        """``{"factor", "bounded", "values"}``."""
        return {"factor": self.factor, "bounded": self.bounded, "values": dict(self.values)}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> Tolerance:
        """A tolerance's record read back."""
        return cls(factor=record["factor"], bounded=record["bounded"], values=record["values"])


@dataclass(frozen=True, kw_only=True)
class Curve:
    """One perturbation term (or the mix) against magnitude.

    Attributes:
        default: the term's fields at level 1 (record units).
        levels: every magnitude measured, increasing.
        tolerance: the magnitude within the allowed increase.
        spec: the tolerance as a workshop instruction.
    """

    default: Mapping[str, float]
    levels: tuple[CurveLevel, ...]
    tolerance: Tolerance
    spec: str

    def level_at(self, level: float) -> CurveLevel:
        """The figures at magnitude ``level``.

        Raises:
            ValueError: ``level`` was not measured.
        """
        return self.levels[[v.level for v in self.levels].index(level)]

    def as_json(self, *, increases: bool = True) -> JsonObject:
        """The curve's record (raw increases only if ``increases``)."""
        return {
            "default": dict(self.default),
            "levels": [v.as_json(increases=increases) for v in self.levels],
            "tolerance": self.tolerance.as_json(),
            "spec": self.spec,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> Curve:
        """A curve's record read back."""
        return cls(
            default=record["default"],
            levels=tuple(CurveLevel.from_json(v) for v in record["levels"]),
            tolerance=Tolerance.from_json(record["tolerance"]),
            spec=record["spec"],
        )


def config_record(config: RobustnessConfig) -> JsonObject:
    """``config`` as a design's record holds it: the perturbation in record units."""
    record = asdict(config) | {"perturbation": config.perturbation.to_record()}
    return record | {"levels": list(config.levels)}  # JSON's list, in place


def config_from_record(record: Mapping[str, Any]) -> RobustnessConfig:
    """Inverse of :func:`config_record`."""
    c = dict(record)
    c["perturbation"] = PerturbationModel.from_record(c["perturbation"])
    c["levels"] = tuple(c["levels"])
    return RobustnessConfig(**c)


@dataclass(frozen=True, kw_only=True)
class DesignCurves:
    """A design under every perturbation term and the mix, from one or more runs.

    Attributes:
        name: the design's label in reports.
        robust: trained under perturbations.
        runs: training runs pooled.
        nominal_error: their mean task error as designed.
        nominal_errors: each run's.
        config: what was measured.
        curves: ``{curve: its figures}`` in :data:`~.config.CURVES` order.
    """

    name: str
    robust: bool
    runs: int
    nominal_error: float
    nominal_errors: tuple[float, ...]
    config: RobustnessConfig
    curves: Mapping[str, Curve]

    def as_json(self, *, increases: bool = True) -> JsonObject:
        """The design's record (its raw per-draw increases only if ``increases``)."""
        return {
            "name": self.name,
            "robust": self.robust,
            "runs": self.runs,
            "nominal_error": self.nominal_error,
            "nominal_errors": list(self.nominal_errors),
            "config": config_record(self.config),
            "curves": {c: v.as_json(increases=increases) for c, v in self.curves.items()},
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> DesignCurves:
        """A design's record read back (``robustness.json`` of a run or a report).

        Raises:
            ValueError: its configuration is out of range.
        """
        return cls(
            name=record["name"],
            robust=record["robust"],
            runs=record["runs"],
            nominal_error=record["nominal_error"],
            nominal_errors=tuple(record["nominal_errors"]),
            config=config_from_record(record["config"]),
            curves={c: Curve.from_json(v) for c, v in record["curves"].items()},
        )
