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

from mincam_render.core.strict_json import JsonObject

#: What a differential plan's costs count.
COST_UNIT = "paths per texel (samples x detectors rendered), backgrounds amortized"


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

    def as_json(self) -> JsonObject:
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
class Parallax:
    """The largest parallax between detectors, seen on the mask plane.

    Args:
        parallax_texels: from the nearest depth seen (texels; 0 when only misses).
        depth_range: nearest and farthest depth seen from the board centre.
        largest_detector_offset_m: the farthest detector from the board centre (m).
        bound_texels: the request's bound on the parallax (texels).
    """

    parallax_texels: float
    depth_range: DepthRange
    largest_detector_offset_m: float
    bound_texels: float

    def as_json(self) -> JsonObject:
        """The figures as the ``shared_render`` decision records them."""
        return {
            "parallax_texels": self.parallax_texels,
            "depth_range_m": self.depth_range.as_json(),
            "largest_detector_offset_m": self.largest_detector_offset_m,
            "bound_texels": self.bound_texels,
        }


@dataclass(frozen=True, kw_only=True)
class SharingChange:
    """How much one shared centre render changes measurements, against two seeds' noise.

    Args:
        error_shared_vs_per_detector: ``{rms, max}`` relative change (common random numbers).
        noise_floor_two_seeds: ``{rms, max}`` relative difference of two seeds.
        probe_spp: samples per texel of the renders compared.
        error_bound: the change allowed (a share of the target error).
    """

    error_shared_vs_per_detector: Mapping[str, float]
    noise_floor_two_seeds: Mapping[str, float]
    probe_spp: int
    error_bound: float

    def as_json(self) -> JsonObject:
        """The figures as the ``shared_render`` decision records them."""
        return {
            "error_shared_vs_per_detector": dict(self.error_shared_vs_per_detector),
            "noise_floor_two_seeds": dict(self.noise_floor_two_seeds),
            "probe_spp": self.probe_spp,
            "error_bound": self.error_bound,
        }


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

    def as_json(self) -> JsonObject:
        """``{"target", **biases, **noises, "biases_exceed_target"}``."""
        return {
            "target": self.target,
            **self.biases,
            **self.noises,
            "biases_exceed_target": self.biases_exceed_target,
        }


@dataclass(frozen=True, kw_only=True)
class Interpolation:
    """The background halfway through a window against its ends' interpolation.

    Args:
        error: ``{rms, max}`` relative error (common random numbers: no noise in it).
        probe_spp: samples per texel of the backgrounds compared.
        at: where in the window it is measured (0-1).
    """

    error: Mapping[str, float]
    probe_spp: int
    at: float

    def as_json(self) -> JsonObject:
        """``{"error", "probe_spp", "at"}``."""
        return {"error": dict(self.error), "probe_spp": self.probe_spp, "at": self.at}


@dataclass(frozen=True, kw_only=True)
class DifferentialCost:
    """Differential rendering's settings from the error budget, and both estimators' cost.

    Args:
        frame_max_depth: path depth of ``X - C`` (0: the scene's integrator).
        frame_spp: samples per texel of the frames.
        background_spp: samples per texel of the backgrounds' components.
        difference_pilot_error_rms: relative noise of ``X - C`` at ``PILOT_SPP``.
        background_pilot_error_rms: relative noise of a background at ``PILOT_SPP``.
        background_pilot_spp: samples per texel of the background pilot.
        daylight_interpolation: the backgrounds' interpolation within a window.
        error_budget: the noise budget the spp come from.
        predicted_error_rms: the plan's predicted relative error.
        cost_per_frame: paths per texel per frame, backgrounds amortized.
        plain_cost_per_frame: the plain estimator's paths per texel per frame.
    """

    frame_max_depth: int
    frame_spp: int
    background_spp: int
    difference_pilot_error_rms: float
    background_pilot_error_rms: float
    background_pilot_spp: int
    daylight_interpolation: Interpolation
    error_budget: NoiseBudget
    predicted_error_rms: float
    cost_per_frame: float
    plain_cost_per_frame: float

    def as_json(self) -> JsonObject:
        """The figures the ``differential`` decision records, ``cost_unit`` last."""
        return {
            "frame_max_depth": self.frame_max_depth,
            "frame_spp": self.frame_spp,
            "background_spp": self.background_spp,
            "difference_pilot_error_rms": self.difference_pilot_error_rms,
            "background_pilot_error_rms": self.background_pilot_error_rms,
            "background_pilot_spp": self.background_pilot_spp,
            "daylight_interpolation": self.daylight_interpolation.as_json(),
            "error_budget": self.error_budget.as_json(),
            "predicted_error_rms": self.predicted_error_rms,
            "cost_per_frame": self.cost_per_frame,
            "plain_cost_per_frame": self.plain_cost_per_frame,
            "cost_unit": COST_UNIT,
        }


@dataclass(frozen=True, kw_only=True)
class SppRaise:
    """One raise of a differential plan's spp after its check missed the target.

    Args:
        error_found_rms: the error found before the raise (reference noise out).
        frame_spp: the frames' samples per texel after it.
        background_spp: the backgrounds' samples per texel after it.
    """

    error_found_rms: float
    frame_spp: int
    background_spp: int

    def as_json(self) -> JsonObject:
        """``{"error_found_rms", "frame_spp", "background_spp"}``."""
        return {
            "error_found_rms": self.error_found_rms,
            "frame_spp": self.frame_spp,
            "background_spp": self.background_spp,
        }


@dataclass(frozen=True, kw_only=True)
class ReferenceCheck:
    """The plan's probes against a high-spp reference (:mod:`.check`).

    Args:
        error_vs_reference: ``{rms, max}`` relative error, the reference's noise in it.
        reference_spp: samples per texel of the reference.
        reference_noise_rms: the reference's own relative error, None when no
            pilot measured it.
        spp_raised: the raises of a differential plan's spp, in order.
    """

    error_vs_reference: Mapping[str, float]
    reference_spp: int
    reference_noise_rms: float | None
    spp_raised: tuple[SppRaise, ...] = ()

    def as_json(self) -> JsonObject:
        """The figures the checked decision (``spp`` or ``differential``) adds."""
        record: JsonObject = {
            "error_vs_reference": dict(self.error_vs_reference),
            "reference_spp": self.reference_spp,
        }
        if self.reference_noise_rms is not None:
            record["reference_noise_rms"] = self.reference_noise_rms
        if self.spp_raised:
            record["spp_raised"] = [r.as_json() for r in self.spp_raised]
        return record


@dataclass(frozen=True, kw_only=True)
class ReferenceFigures:
    """Measurements of one transport against another in every metric (``{rms, max}`` each).

    Args:
        total_relative: random printable masks, relative to the total light.
        total_scale: the total scale's value
            (:class:`~mincam_render.render.precision.ErrorScale`).
        signal_relative: random printable masks, relative to the label signal
            (None: the signal is not measurable, :meth:`Probes.signal_figure`).
        signal_relative_finest_box: single-texel box pixels, relative to the
            label signal (None likewise).
    """

    total_relative: Mapping[str, float]
    total_scale: str
    signal_relative: Mapping[str, float] | None
    signal_relative_finest_box: Mapping[str, float] | None

    def as_json(self) -> JsonObject:
        """The four figures by name, as a plan's ``achieved`` record holds them."""
        return {
            "total_relative": dict(self.total_relative),
            "total_scale": self.total_scale,
            "signal_relative": _figure(self.signal_relative),
            "signal_relative_finest_box": _figure(self.signal_relative_finest_box),
        }


def _figure(figure: Mapping[str, float] | None) -> dict[str, float] | None:
    """A ``{rms, max}`` figure as JSON: a plain dict, or None where it is undefined."""
    return None if figure is None else dict(figure)


@dataclass(frozen=True, kw_only=True)
class SignalRms:
    """The label signal's RMS measurement (W): random printable masks, finest box pixels."""

    random_masks_w: float
    finest_box_w: float

    def as_json(self) -> JsonObject:
        """``{"random_masks_w", "finest_box_w"}``."""
        return {"random_masks_w": self.random_masks_w, "finest_box_w": self.finest_box_w}


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
        against_reference: the plan vs the reference in every metric.
        label_signal_rms: the label signal's RMS (W).
    """

    error_rms: float
    target_error: float
    error_scale: str
    advice: str | None
    per_detector_error_rms: list[float]
    against_reference: ReferenceFigures
    label_signal_rms: SignalRms

    @property
    def met(self) -> bool:
        """The error is within the target."""
        return self.error_rms <= self.target_error

    def as_json(self) -> JsonObject:
        """The ``achieved`` record of a plan's decisions."""
        record: JsonObject = {
            "error_rms": self.error_rms,
            "target_error": self.target_error,
            "error_scale": self.error_scale,
            "met": self.met,
        }
        if self.advice is not None:
            record["advice"] = self.advice
        record["per_detector_error_rms"] = self.per_detector_error_rms
        record["against_reference"] = self.against_reference.as_json()
        record["label_signal_rms"] = self.label_signal_rms.as_json()
        return record
