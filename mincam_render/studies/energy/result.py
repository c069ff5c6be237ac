"""The energy study's result: frozen records of budgets, days and comparisons.

:func:`~mincam_render.studies.energy.study.run` returns an
:class:`EnergyResult`; the report, its figures and the benchmark read its
attributes, :meth:`EnergyResult.as_json` is ``energy.json`` and
:meth:`EnergyResult.from_json` reads it back. Powers in W,
energies in J, illuminance in lx, hours of local solar time.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from mincam_render.core.config import parse, to_dict
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.energy.config import EnergyConfig
from mincam_render.studies.energy.matching import Match
from mincam_render.studies.energy.panel import PanelPose


@dataclass(frozen=True, kw_only=True)
class BudgetRecord:
    """A frame budget with its power and threshold illuminance at the configured rate.

    Attributes:
        pixels: measurements per frame.
        energy_per_frame_j, wake_j, readout_j, compute_j, radio_j: per frame (J).
        static_w: drawn all the time (W).
        payload_bytes, packets: sent per frame.
        head_flops: the head's operations per frame.
        max_fps: the rate at which the MCU never sleeps (1/s).
        power_at_fps_w: mean load power at the configured rate (W).
        threshold_lux: panel illuminance that pays for it (lx).
    """

    pixels: int
    energy_per_frame_j: float
    wake_j: float
    readout_j: float
    compute_j: float
    radio_j: float
    static_w: float
    payload_bytes: int
    packets: int
    head_flops: int
    max_fps: float
    power_at_fps_w: float
    threshold_lux: float

    def as_json(self) -> JsonObject:
        """The record's fields."""
        return {
            "pixels": self.pixels,
            "energy_per_frame_j": self.energy_per_frame_j,
            "wake_j": self.wake_j,
            "readout_j": self.readout_j,
            "compute_j": self.compute_j,
            "radio_j": self.radio_j,
            "static_w": self.static_w,
            "payload_bytes": self.payload_bytes,
            "packets": self.packets,
            "head_flops": self.head_flops,
            "max_fps": self.max_fps,
            "power_at_fps_w": self.power_at_fps_w,
            "threshold_lux": self.threshold_lux,
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> BudgetRecord:
        """The record :meth:`as_json` wrote (other keys beside it are ignored)."""
        return cls(**{f.name: record[f.name] for f in dataclasses.fields(cls)})


@dataclass(frozen=True, kw_only=True)
class Threshold:
    """The first family's budget of ``max_pixels`` pixels beside the paper's illuminance."""

    budget: BudgetRecord
    family: str
    paper_lux: float

    def as_json(self) -> JsonObject:
        """The budget's fields with ``family`` and ``paper_lux``."""
        return self.budget.as_json() | {"family": self.family, "paper_lux": self.paper_lux}

    @classmethod
    def from_json(cls, record: JsonObject) -> Threshold:
        """The record :meth:`as_json` wrote."""
        return cls(
            budget=BudgetRecord.from_json(record),
            family=record["family"],
            paper_lux=record["paper_lux"],
        )


@dataclass(frozen=True, kw_only=True)
class ComparedBudget:
    """One camera of a comparison: its budget, and against the minimalist one.

    Attributes:
        budget: the frame budget.
        name: the module's name (None for the minimalist camera).
        power_ratio: its power over the minimalist camera's (None for that one).
        hours_at_fps: hours at the configured rate over the family's day (None
            when the family's day was not rendered).
    """

    budget: BudgetRecord
    name: str | None = None
    power_ratio: float | None = None
    hours_at_fps: float | None = None

    def as_json(self) -> JsonObject:
        """The budget's fields, with the others that are set."""
        out: JsonObject = {} if self.name is None else {"name": self.name}
        out |= self.budget.as_json()
        if self.power_ratio is not None:
            out["power_ratio"] = self.power_ratio
        if self.hours_at_fps is not None:
            out["hours_at_fps"] = self.hours_at_fps
        return out

    @classmethod
    def from_json(cls, record: JsonObject) -> ComparedBudget:
        """The record :meth:`as_json` wrote (a key it left out is None)."""
        return cls(
            budget=BudgetRecord.from_json(record),
            name=record.get("name"),
            power_ratio=record.get("power_ratio"),
            hours_at_fps=record.get("hours_at_fps"),
        )


@dataclass(frozen=True, kw_only=True)
class Comparison:
    """The minimalist design and the conventional module of equal task error.

    Attributes:
        match: the design and grid of equal error, and where the match is from.
        mincam: the minimalist camera.
        module: the module as configured.
        module_outputs_only: the module at its best (head on the MCU, outputs alone sent).
    """

    match: Match
    mincam: ComparedBudget
    module: ComparedBudget
    module_outputs_only: ComparedBudget

    def cameras(self) -> tuple[tuple[str, ComparedBudget], ...]:
        """``(key, camera)`` in the order of the report: mincam, module, outputs only."""
        return (
            ("mincam", self.mincam),
            ("module", self.module),
            ("module_outputs_only", self.module_outputs_only),
        )

    def as_json(self) -> JsonObject:
        """``{"match", "mincam", "module", "module_outputs_only"}``."""
        return {"match": to_dict(self.match)} | {k: c.as_json() for k, c in self.cameras()}

    @classmethod
    def from_json(cls, record: JsonObject) -> Comparison:
        """The record :meth:`as_json` wrote."""
        return cls(
            match=_match(record["match"]),
            mincam=ComparedBudget.from_json(record["mincam"]),
            module=ComparedBudget.from_json(record["module"]),
            module_outputs_only=ComparedBudget.from_json(record["module_outputs_only"]),
        )


def _match(record: JsonObject) -> Match:
    """A :class:`Match` from its ``to_dict`` record (lists back to tuples)."""

    def interval(v: list[float] | None) -> tuple[float, float, float] | None:
        return None if v is None else (v[0], v[1], v[2])

    return Match(
        family=record["family"],
        pixels=record["pixels"],
        grid=(record["grid"][0], record["grid"][1]),
        source=record["source"],
        mincam_error=interval(record["mincam_error"]),
        baseline_error=interval(record["baseline_error"]),
        error_name=record["error_name"],
        matched=record["matched"],
    )


@dataclass(frozen=True, kw_only=True)
class StorageDay:
    """The capacitor over the reported day, sampled every schedule step, and its energy book.

    Attributes:
        hours: sample times (h from the day's start), shape (S,).
        voltage_v: capacitor voltage (V), shape (S,).
        stored_j: capacitor energy (J), shape (S,).
        balance_j: harvested minus everything booked, over both days (J): 0 up to rounding.
        harvested_j, consumed_j, leaked_j, spilled_j: over both simulated days (J).
    """

    hours: tuple[float, ...]
    voltage_v: tuple[float, ...]
    stored_j: tuple[float, ...]
    balance_j: float
    harvested_j: float
    consumed_j: float
    leaked_j: float
    spilled_j: float

    def as_json(self) -> JsonObject:
        """The record's fields (sequences as lists)."""
        return {
            "hours": list(self.hours),
            "voltage_v": list(self.voltage_v),
            "stored_j": list(self.stored_j),
            "balance_j": self.balance_j,
            "harvested_j": self.harvested_j,
            "consumed_j": self.consumed_j,
            "leaked_j": self.leaked_j,
            "spilled_j": self.spilled_j,
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> StorageDay:
        """The record :meth:`as_json` wrote (lists back to tuples)."""
        return cls(
            hours=tuple(record["hours"]),
            voltage_v=tuple(record["voltage_v"]),
            stored_j=tuple(record["stored_j"]),
            balance_j=record["balance_j"],
            harvested_j=record["harvested_j"],
            consumed_j=record["consumed_j"],
            leaked_j=record["leaked_j"],
            spilled_j=record["spilled_j"],
        )


@dataclass(frozen=True, kw_only=True)
class Estimate:
    """A rendered irradiance component: mean and standard error (W/m^2)."""

    mean_w_m2: float
    stderr_w_m2: float

    @classmethod
    def from_pair(cls, pair: list[float]) -> Estimate:
        """``[mean, stderr]``, as ``energy.json`` writes a component."""
        return cls(mean_w_m2=pair[0], stderr_w_m2=pair[1])


@dataclass(frozen=True, kw_only=True)
class RenderStats:
    """How a family's panel light was rendered, and its error.

    Attributes:
        seconds: wall time of the renders (s).
        spp: samples per component.
        max_depth: path depth.
        max_relative_error_component: largest stderr/mean of a component.
        max_relative_error_total: largest stderr/mean of the day's scheduled total.
    """

    seconds: float
    spp: int
    max_depth: int
    max_relative_error_component: float
    max_relative_error_total: float


@dataclass(frozen=True, kw_only=True)
class FamilyBudget:
    """One family's day: light on the panel, frame rates, hours, storage, budgets.

    Attributes:
        hours: local solar hours of the samples, shape (T,).
        irradiance_w_m2: visible-band irradiance on the panel (W/m^2), shape (T,).
        lux: the same in lux, shape (T,).
        harvest_w: power into the capacitor (W), shape (T,).
        sustainable_fps: per pixel count, the rate each sample's light pays (1/s), shape (T,).
        hours_at_fps: per pixel count, hours at the configured rate (storage simulated).
        day_mean_sustainable_fps: per pixel count, the rate the day's mean harvest pays.
        storage_trace: the capacitor with ``max_pixels`` pixels at the configured rate.
        lights_w_m2: per light, its component with that light alone on.
        daylight_w_m2: per sample, the daylight component (None below civil twilight).
        render: how the light was rendered.
        panel: the panel's pose in the scene.
        panel_area_m2: the panel's area (m^2).
        budgets: the frame budgets of 1..max_pixels pixels.
    """

    hours: tuple[float, ...]
    irradiance_w_m2: tuple[float, ...]
    lux: tuple[float, ...]
    harvest_w: tuple[float, ...]
    sustainable_fps: Mapping[int, tuple[float, ...]]
    hours_at_fps: Mapping[int, float]
    day_mean_sustainable_fps: Mapping[int, float]
    storage_trace: StorageDay
    lights_w_m2: Mapping[str, Estimate]
    daylight_w_m2: tuple[Estimate | None, ...]
    render: RenderStats
    panel: PanelPose
    panel_area_m2: float
    budgets: tuple[BudgetRecord, ...]

    def as_json(self) -> JsonObject:
        """The family's record in ``energy.json`` (pixel counts as string keys)."""
        return {
            "hours": list(self.hours),
            "irradiance_w_m2": list(self.irradiance_w_m2),
            "lux": list(self.lux),
            "harvest_w": list(self.harvest_w),
            "sustainable_fps": {str(k): list(v) for k, v in self.sustainable_fps.items()},
            "hours_at_fps": {str(k): v for k, v in self.hours_at_fps.items()},
            "day_mean_sustainable_fps": {
                str(k): v for k, v in self.day_mean_sustainable_fps.items()
            },
            "storage_trace": self.storage_trace.as_json(),
            "components": {
                "lights_w_m2": {
                    n: [e.mean_w_m2, e.stderr_w_m2] for n, e in self.lights_w_m2.items()
                },
                "daylight_w_m2": [
                    None if d is None else [d.mean_w_m2, d.stderr_w_m2] for d in self.daylight_w_m2
                ],
            },
            "render": to_dict(self.render),
            "panel": to_dict(self.panel) | {"area_m2": self.panel_area_m2},
            "budgets": [b.as_json() for b in self.budgets],
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> FamilyBudget:
        """The record :meth:`as_json` wrote (string pixel counts back to ints)."""
        comp = record["components"]
        panel = dict(record["panel"])
        area = panel.pop("area_m2")
        return cls(
            hours=tuple(record["hours"]),
            irradiance_w_m2=tuple(record["irradiance_w_m2"]),
            lux=tuple(record["lux"]),
            harvest_w=tuple(record["harvest_w"]),
            sustainable_fps={int(k): tuple(v) for k, v in record["sustainable_fps"].items()},
            hours_at_fps={int(k): v for k, v in record["hours_at_fps"].items()},
            day_mean_sustainable_fps={
                int(k): v for k, v in record["day_mean_sustainable_fps"].items()
            },
            storage_trace=StorageDay.from_json(record["storage_trace"]),
            lights_w_m2={n: Estimate.from_pair(e) for n, e in comp["lights_w_m2"].items()},
            daylight_w_m2=tuple(
                None if d is None else Estimate.from_pair(d) for d in comp["daylight_w_m2"]
            ),
            render=RenderStats(**record["render"]),
            panel=PanelPose(**{k: tuple(v) for k, v in panel.items()}),
            panel_area_m2=area,
            budgets=tuple(BudgetRecord.from_json(b) for b in record["budgets"]),
        )


@dataclass(frozen=True, kw_only=True)
class EnergyResult:
    """The self-powered budget of some families (:func:`~.study.run`).

    Attributes:
        config: the description analysed.
        families: per family rendered, its day.
        comparisons: per family (rendered, or with a study table), the matched module.
        threshold: the first family's budget of ``max_pixels`` pixels.
    """

    config: EnergyConfig
    families: Mapping[str, FamilyBudget]
    comparisons: Mapping[str, Comparison]
    threshold: Threshold

    def as_json(self) -> JsonObject:
        """``energy.json``: ``{"config", "families", "comparisons", "threshold"}``."""
        return {
            "config": to_dict(self.config),
            "families": {n: f.as_json() for n, f in self.families.items()},
            "comparisons": {n: c.as_json() for n, c in self.comparisons.items()},
            "threshold": self.threshold.as_json(),
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> EnergyResult:
        """The result of an ``energy.json`` (:meth:`as_json`).

        Raises:
            ConfigError: its ``config`` is not a valid description.
            KeyError: a record lacks a key :meth:`as_json` writes.
        """
        return cls(
            config=parse(EnergyConfig, record["config"], source="energy.json config"),
            families={n: FamilyBudget.from_json(f) for n, f in record["families"].items()},
            comparisons={n: Comparison.from_json(c) for n, c in record["comparisons"].items()},
            threshold=Threshold.from_json(record["threshold"]),
        )
