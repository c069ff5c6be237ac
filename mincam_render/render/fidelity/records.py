"""What the planner decides and measures, as typed records with their JSON form.

Each record's :meth:`as_json` writes the keys, in the order, that plans,
manifests and benchmark JSON have always held (benchmarks dump without sorting
keys), so typing the records changed no byte of what is written.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any


class Source(enum.StrEnum):
    """Who made a choice."""

    FLAG = "flag"  # set by the request
    AUTO = "auto"  # measured on the probe frames (or nothing to measure)
    FULL = "full"  # full fidelity: no shortcut
    CAMERA = "camera"  # the camera's own (mask resolution)


@dataclass(frozen=True, kw_only=True)
class Decision:
    """One knob's choice, who made it, why, and the figures it was made from.

    Args:
        value: the chosen setting (JSON scalar: bool, int or a dtype's value).
        source: who chose it.
        reason: one sentence naming the bound and the measured error.
        measured: the measured figures, JSON-ready, in the order they are written.
    """

    value: bool | int | str
    source: Source
    reason: str
    measured: Mapping[str, Any] = field(default_factory=dict)

    def with_measured(self, **figures: Any) -> Decision:
        """This decision with ``figures`` added (existing keys keep their place)."""
        return replace(self, measured={**self.measured, **figures})

    def as_json(self) -> dict[str, Any]:
        """``{"value", "source", "reason", **measured}`` as plans and manifests hold it."""
        return {
            "value": self.value,
            "source": self.source.value,
            "reason": self.reason,
            **self.measured,
        }


@dataclass(frozen=True, kw_only=True)
class DepthRange:
    """Nearest and farthest depth (m) seen from the board centre (``inf``: only misses)."""

    min_m: float
    max_m: float

    def as_json(self) -> list[float]:
        """``[min, max]`` (m), as a decision records it."""
        return [self.min_m, self.max_m]


@dataclass(frozen=True, kw_only=True)
class NoiseBudget:
    """The error budget of differential rendering (:func:`.budget.split_noise_budget`).

    Args:
        target: target relative measurement error of the plan.
        biases: ``{name: rms}`` of the fixed (sample-independent) errors.
        noises: ``{"difference_noise", "background_noise"}``: the noise each may
            have, in the order they were shared (flagged ones first).
        biases_exceed_target: the biases take more than 90 % of ``target^2``.
    """

    target: float
    biases: Mapping[str, float]
    noises: Mapping[str, float]
    biases_exceed_target: bool

    @property
    def difference_noise(self) -> float:
        """The relative error ``X - C`` may have."""
        return self.noises["difference_noise"]

    @property
    def background_noise(self) -> float:
        """The relative error the backgrounds may have."""
        return self.noises["background_noise"]

    def as_json(self) -> dict[str, Any]:
        """``{"target", **biases, **noises, "biases_exceed_target"}``."""
        return {
            "target": self.target,
            **self.biases,
            **self.noises,
            "biases_exceed_target": self.biases_exceed_target,
        }


@dataclass(frozen=True, kw_only=True)
class Achieved:
    """The plan's error against the high-spp reference (:mod:`.check`).

    Args:
        error_rms: relative error, the reference's own noise taken out in quadrature.
        target_error: the planning target, in ``error_scale``.
        error_scale: the planning scale's value
            (:class:`~mincam_render.render.precision.ErrorScale`).
        advice: the flags to pass when the target is missed, else None.
        per_detector_error_rms: each detector's error (same scale).
        against_reference: :meth:`.probes.Probes.figures` of the plan vs the reference.
        label_signal_rms: :meth:`.probes.Probes.signal_rms` (W).
    """

    error_rms: float
    target_error: float
    error_scale: str
    advice: str | None
    per_detector_error_rms: list[float]
    against_reference: Mapping[str, Any]
    label_signal_rms: Mapping[str, float]

    @property
    def met(self) -> bool:
        """The error is within the target."""
        return self.error_rms <= self.target_error

    def as_json(self) -> dict[str, Any]:
        """The ``achieved`` record of a plan's decisions."""
        record: dict[str, Any] = {
            "error_rms": self.error_rms,
            "target_error": self.target_error,
            "error_scale": self.error_scale,
            "met": self.met,
        }
        if self.advice is not None:
            record["advice"] = self.advice
        record["per_detector_error_rms"] = self.per_detector_error_rms
        record["against_reference"] = dict(self.against_reference)
        record["label_signal_rms"] = dict(self.label_signal_rms)
        return record
