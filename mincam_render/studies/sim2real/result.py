"""The sim2real study's result: frozen records of fits, pixels, tasks and the verdict.

:func:`~mincam_render.studies.sim2real.study.run` returns a
:class:`Sim2RealResult`; the report, its figures and the command line read its
attributes, and :meth:`Sim2RealResult.as_json` is ``sim2real.json``. Arrays are
numpy float64; voltages in volts, time in seconds.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.strict_json import JsonObject

if TYPE_CHECKING:
    from mincam_render.learn.evaluation import Evaluation


class PixelVerdict(enum.Enum):
    """Does a pixel's simulated time series reproduce the measured one (see :class:`Thresholds`)?"""

    AGREES = "agrees"
    AGREES_CALIBRATED = "agrees after gain/offset calibration"
    DISAGREES = "disagrees"


@dataclass(frozen=True, kw_only=True)
class Thresholds:
    """Verdict thresholds (documented in the report).

    Attributes:
        min_correlation: simulated and measured time series move together.
        max_gain_error: ``|gain - 1|`` for 'agrees without calibration'.
        max_offset_fraction: ``|offset|`` / mean simulated voltage, same.
        max_ks_calibrated: KS statistic after the per-pixel gain/offset fit.
        max_task_gap: task error may exceed the real-trained one by this fraction.
    """

    min_correlation: float = 0.9
    max_gain_error: float = 0.1
    max_offset_fraction: float = 0.05
    max_ks_calibrated: float = 0.2
    max_task_gap: float = 0.2

    def as_json(self) -> dict[str, float]:
        """``{name: value}`` in field order."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, record: Mapping[str, float]) -> Thresholds:
        """The thresholds :meth:`as_json` wrote."""
        return cls(**record)


@dataclass(frozen=True, kw_only=True)
class GainOffsetFit:
    """Least-squares ``real = gain * sim + offset`` (NaN where the fit is undefined).

    Attributes:
        gain, gain_se: gain and its standard error.
        offset_v, offset_se_v: offset and its standard error (V).
        correlation: of simulated and measured voltages.
        residual_std_v: residual standard deviation (V).
    """

    gain: float
    offset_v: float
    gain_se: float
    offset_se_v: float
    correlation: float
    residual_std_v: float


@dataclass(frozen=True, kw_only=True)
class InjectedComparison:
    """A pixel's fit against what a SURROGATE injected (z in standard errors), explained."""

    injected_gain: float
    injected_offset_v: float
    expected_gain: float
    expected_offset_v: float
    gain_z: float
    offset_z: float
    explanation: str


@dataclass(frozen=True, kw_only=True)
class PixelComparison:
    """One pixel's fit, residual percentiles, distribution gap and verdict.

    Attributes:
        pixel: the measurement column.
        detector: the camera's detector it belongs to.
        fit: ``real = gain * sim + offset``.
        mean_sim_v, mean_real_v: mean voltages (V).
        residual_percentiles_v: per percentile (%), the residual after the fit (V).
        ks_raw, ks_calibrated: KS statistic before and after the fit.
        wasserstein_raw_v, wasserstein_calibrated_v: 1-Wasserstein distance (V), same.
        verdict: against :class:`Thresholds`.
        injected: for SURROGATE data, the fit against what was injected; else None.
    """

    pixel: int
    detector: int
    fit: GainOffsetFit
    mean_sim_v: float
    mean_real_v: float
    residual_percentiles_v: Mapping[int, float]
    ks_raw: float
    ks_calibrated: float
    wasserstein_raw_v: float
    wasserstein_calibrated_v: float
    verdict: PixelVerdict
    injected: InjectedComparison | None = None

    def as_json(self) -> JsonObject:
        """The pixel's record in ``sim2real.json`` (fit and injected values flattened in)."""
        out: JsonObject = {
            "pixel": self.pixel,
            "detector": self.detector,
            **dataclasses.asdict(self.fit),
            "mean_sim_v": self.mean_sim_v,
            "mean_real_v": self.mean_real_v,
            "residual_percentiles_v": {str(q): v for q, v in self.residual_percentiles_v.items()},
            "ks_raw": self.ks_raw,
            "ks_calibrated": self.ks_calibrated,
            "wasserstein_raw_v": self.wasserstein_raw_v,
            "wasserstein_calibrated_v": self.wasserstein_calibrated_v,
            "verdict": self.verdict.value,
        }
        if self.injected is not None:
            out |= dataclasses.asdict(self.injected)
        return out

    @classmethod
    def from_json(cls, record: JsonObject) -> PixelComparison:
        """The record :meth:`as_json` wrote (a null number, strict JSON's NaN, is NaN again)."""
        injected = None
        if "injected_gain" in record:
            injected = InjectedComparison(**_fields(InjectedComparison, record))
        return cls(
            pixel=record["pixel"],
            detector=record["detector"],
            fit=GainOffsetFit(**_fields(GainOffsetFit, record)),
            mean_sim_v=_number(record["mean_sim_v"]),
            mean_real_v=_number(record["mean_real_v"]),
            residual_percentiles_v={
                int(q): _number(v) for q, v in record["residual_percentiles_v"].items()
            },
            ks_raw=_number(record["ks_raw"]),
            ks_calibrated=_number(record["ks_calibrated"]),
            wasserstein_raw_v=_number(record["wasserstein_raw_v"]),
            wasserstein_calibrated_v=_number(record["wasserstein_calibrated_v"]),
            verdict=PixelVerdict(record["verdict"]),
            injected=injected,
        )


def _number(value: float | None) -> float:
    """A number read back from strict JSON, which writes NaN and infinities as null."""
    return math.nan if value is None else value


def _fields(cls: type, record: JsonObject) -> JsonObject:
    """The values of ``cls``'s fields in a flattened ``record``; null (a NaN's) as NaN.

    Every field of the records read this way that may be null is a number.
    """
    return {f.name: _number(record[f.name]) for f in dataclasses.fields(cls)}


@dataclass(frozen=True, kw_only=True)
class DistributionGap:
    """Means over pixels of the KS statistics and 1-Wasserstein distances (V)."""

    ks_raw_mean: float
    ks_calibrated_mean: float
    wasserstein_raw_mean_v: float
    wasserstein_calibrated_mean_v: float


@dataclass(frozen=True, kw_only=True)
class TaskMetrics:
    """Task errors on the real test segment (:func:`~.tasks.task_metrics`).

    Attributes:
        sim_on_sim: trained on simulation, tested on simulation.
        sim_on_real: trained on simulation, tested on real.
        sim_head_retrained_on_real: the sim-trained head retrained on real, tested on real.
        real_on_real: trained and tested on real.
    """

    sim_on_sim: Evaluation
    sim_on_real: Evaluation
    sim_head_retrained_on_real: Evaluation
    real_on_real: Evaluation

    def as_json(self) -> JsonObject:
        """Each evaluation's record, and ``video_simulation`` (None: not implemented)."""
        return {
            "sim_on_sim": self.sim_on_sim.as_json(),
            "sim_on_real": self.sim_on_real.as_json(),
            "sim_head_retrained_on_real": self.sim_head_retrained_on_real.as_json(),
            "real_on_real": self.real_on_real.as_json(),
            "video_simulation": None,
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> TaskMetrics:
        """The metrics :meth:`as_json` wrote."""
        from mincam_render.learn.evaluation import Evaluation

        return cls(
            sim_on_sim=Evaluation.from_json(record["sim_on_sim"]),
            sim_on_real=Evaluation.from_json(record["sim_on_real"]),
            sim_head_retrained_on_real=Evaluation.from_json(record["sim_head_retrained_on_real"]),
            real_on_real=Evaluation.from_json(record["real_on_real"]),
        )


@dataclass(frozen=True, kw_only=True)
class Verdict:
    """The overall verdict: in words, pixel counts per verdict, the task line, one summary."""

    overall: str
    counts: Mapping[str, int]
    task: str
    summary: str


@dataclass(frozen=True, kw_only=True, eq=False)
class Series:
    """The compared time series: ``time_s[N]`` (s), ``sim_v[N, P]`` and ``real_v[N, P]`` (V).

    Equal to another when every array is (:func:`numpy.array_equal`).
    """

    time_s: np.ndarray
    sim_v: np.ndarray
    real_v: np.ndarray

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Series):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, name), getattr(other, name))
            for name in ("time_s", "sim_v", "real_v")
        )

    __hash__ = None  # type: ignore[assignment]  # arrays: not hashable


@dataclass(frozen=True, kw_only=True)
class Sim2RealResult:
    """A recording against its simulation (:func:`~.study.run`).

    Attributes:
        surrogate: the recording is SURROGATE data (generated, not measured).
        banner: the SURROGATE banner, or None for real data.
        recording: the recording directory (absolute).
        recording_sha256: per file of the recording, its SHA-256.
        family: the recording's scene family.
        num_samples: measured samples N.
        fps: sample rate (1/s).
        units_in_file: the file's measurement units ('V' or 'counts').
        spp: samples per texel of the simulation renders.
        seed: render and training seed.
        thresholds: the verdicts' thresholds.
        pixels: per pixel, its comparison.
        distribution_gap: means over pixels.
        injected: a SURROGATE's ``injected.json`` as read, or None.
        series: the compared time series.
        tasks: task metrics, or None when not computed.
        video_simulation_note: why the paper's video-based simulation is omitted.
        verdict: the overall verdict.
    """

    surrogate: bool
    banner: str | None
    recording: str
    recording_sha256: Mapping[str, str]
    family: str
    num_samples: int
    fps: float
    units_in_file: str
    spp: int
    seed: int
    thresholds: Thresholds
    pixels: tuple[PixelComparison, ...]
    distribution_gap: DistributionGap
    injected: JsonObject | None
    series: Series
    tasks: TaskMetrics | None
    video_simulation_note: str
    verdict: Verdict

    def as_json(self) -> JsonObject:
        """``sim2real.json``: every number of the comparison."""
        return {
            "surrogate": self.surrogate,
            "banner": self.banner,
            "recording": self.recording,
            "recording_sha256": dict(self.recording_sha256),
            "family": self.family,
            "num_samples": self.num_samples,
            "fps": self.fps,
            "units_in_file": self.units_in_file,
            "spp": self.spp,
            "seed": self.seed,
            "thresholds": self.thresholds.as_json(),
            "pixels": [p.as_json() for p in self.pixels],
            "distribution_gap": dataclasses.asdict(self.distribution_gap),
            "injected": self.injected,
            "series": {
                "time_s": self.series.time_s.tolist(),
                "sim_v": self.series.sim_v.tolist(),
                "real_v": self.series.real_v.tolist(),
            },
            "tasks": None if self.tasks is None else self.tasks.as_json(),
            "video_simulation_note": self.video_simulation_note,
            "verdict": dataclasses.asdict(self.verdict),
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> Sim2RealResult:
        """The result of a ``sim2real.json`` (:meth:`as_json`); arrays float64.

        Raises:
            KeyError: a record lacks a key :meth:`as_json` writes.
        """
        series, tasks, gap = record["series"], record["tasks"], record["distribution_gap"]
        return cls(
            surrogate=record["surrogate"],
            banner=record["banner"],
            recording=record["recording"],
            recording_sha256=record["recording_sha256"],
            family=record["family"],
            num_samples=record["num_samples"],
            fps=record["fps"],
            units_in_file=record["units_in_file"],
            spp=record["spp"],
            seed=record["seed"],
            thresholds=Thresholds.from_json(record["thresholds"]),
            pixels=tuple(PixelComparison.from_json(p) for p in record["pixels"]),
            distribution_gap=DistributionGap(**_fields(DistributionGap, gap)),
            injected=record["injected"],
            series=Series(**{k: np.asarray(v, np.float64) for k, v in series.items()}),
            tasks=None if tasks is None else TaskMetrics.from_json(tasks),
            video_simulation_note=record["video_simulation_note"],
            verdict=Verdict(**record["verdict"]),
        )
