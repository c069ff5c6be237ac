"""The fidelity benchmark's result: per family, one row per knob level, and its JSON.

Each record's :meth:`as_json` writes the keys and values ``fidelity.json`` has
always held (the file is written with sorted keys, so their order is free);
:meth:`from_json` reads them back, results from before the label-signal errors
included (their rows and config have none).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from mincam_render.core.strict_json import JsonObject
from mincam_render.render.fidelity import FidelityPlan
from mincam_render.render.precision import StorageDtype
from mincam_render.studies.fidelity.config import REFERENCE_DEPTH, FidelityBenchConfig


class RenderSharing(enum.StrEnum):
    """Who the transport is rendered for: every detector, or one centre render for all."""

    PER_DETECTOR = "per_detector"
    SHARED = "shared"  # one render at the board centre replicated: no parallax


class DetectorModel(enum.StrEnum):
    """How the diode is sampled."""

    AREA = "area"  # its area, as built
    POINT = "point"  # a 1 um diode rescaled by area: no detector blur


@dataclass(frozen=True, kw_only=True)
class KnobSettings:
    """The level of every knob in one setting (a row's ``settings``, the base's).

    Args:
        spp: samples per texel.
        mask_res: texels per side of the transport image.
        max_depth: path depth (1 = emitters only, 2 = direct light, ...).
        render: per-detector or shared render.
        detector: area-sampled or point diode.
        storage: storage type of the transport.
    """

    spp: int
    mask_res: int
    max_depth: int
    render: RenderSharing = RenderSharing.PER_DETECTOR
    detector: DetectorModel = DetectorModel.AREA
    storage: StorageDtype = StorageDtype.FLOAT32

    def as_json(self) -> JsonObject:
        """``{"spp", "mask_res", "max_depth", "render", "detector", "storage"}``."""
        return {
            "spp": self.spp,
            "mask_res": self.mask_res,
            "max_depth": self.max_depth,
            "render": self.render.value,
            "detector": self.detector.value,
            "storage": self.storage.value,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> KnobSettings:
        """Read back :meth:`as_json` (extra keys of a record around it are ignored)."""
        return cls(
            spp=record["spp"],
            mask_res=record["mask_res"],
            max_depth=record["max_depth"],
            render=RenderSharing(record["render"]),
            detector=DetectorModel(record["detector"]),
            storage=StorageDtype(record["storage"]),
        )


@dataclass(frozen=True, kw_only=True)
class SignalErrors:
    """A setting's error relative to the label signal (RMS, dimensionless).

    Args:
        random: of the random printable masks.
        finest_box: of single-texel box pixels; None for a transport at a coarser
            resolution (it has no single texel).
    """

    random: float
    finest_box: float | None


@dataclass(frozen=True, kw_only=True)
class KnobErrors:
    """Relative RMS errors of a setting's measurements against the reference.

    Args:
        error_random: of the random printable masks, relative to the total light.
        error_trained: of the trained-like masks, relative to the total light.
        signal: relative to the label signal, or None (not measured).
    """

    error_random: float
    error_trained: float
    signal: SignalErrors | None

    @property
    def error(self) -> float:
        """The larger of the two mask kinds' errors."""
        return max(self.error_random, self.error_trained)

    def as_json(self) -> JsonObject:
        """``{"error_random", "error_trained", "error", ["error_signal_*"]}``."""
        record: JsonObject = {
            "error_random": self.error_random,
            "error_trained": self.error_trained,
            "error": self.error,
        }
        if self.signal is not None:
            record["error_signal_random"] = self.signal.random
            record["error_signal_finest_box"] = self.signal.finest_box
        return record

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> KnobErrors:
        """Read back :meth:`as_json` (extra keys of a row around it are ignored)."""
        signal = None
        if "error_signal_random" in record:
            signal = SignalErrors(
                random=record["error_signal_random"],
                finest_box=record["error_signal_finest_box"],
            )
        return cls(
            error_random=record["error_random"],
            error_trained=record["error_trained"],
            signal=signal,
        )


@dataclass(frozen=True, kw_only=True)
class FidelityRow:
    """One knob at one level, changed away from the base setting.

    Args:
        family: the family's name.
        knob: one of :data:`~.config.KNOBS`.
        level: the knob's level (a number, or a name such as ``"shared"``).
        errors: its errors against the reference.
        effect: the systematic error it adds, ``sqrt(max(e^2 - e_base^2, 0))``.
        seconds: render seconds per frame (median of the timed runs).
        seconds_spread: max - min of the timed runs' seconds per frame.
        settings: every knob's level in this setting.
    """

    family: str
    knob: str
    level: int | str
    errors: KnobErrors
    effect: float
    seconds: float
    seconds_spread: float
    settings: KnobSettings

    @property
    def error(self) -> float:
        """The larger of the two mask kinds' errors (relative to the total light)."""
        return self.errors.error

    def as_json(self) -> JsonObject:
        """The row as ``fidelity.json`` holds it (errors flat beside the rest)."""
        return {
            "family": self.family,
            "knob": self.knob,
            "level": self.level,
            **self.errors.as_json(),
            "seconds": self.seconds,
            "seconds_spread": self.seconds_spread,
            "settings": self.settings.as_json(),
            "effect": self.effect,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> FidelityRow:
        """Read back :meth:`as_json`."""
        return cls(
            family=record["family"],
            knob=record["knob"],
            level=record["level"],
            errors=KnobErrors.from_json(record),
            effect=record["effect"],
            seconds=record["seconds"],
            seconds_spread=record["seconds_spread"],
            settings=KnobSettings.from_json(record["settings"]),
        )


@dataclass(frozen=True, kw_only=True)
class ReferenceRun:
    """The converged reference: per detector, area diode, deep paths, float32.

    Args:
        spp: samples per texel (two halves of half as many).
        seconds: render seconds per frame of both halves.
        reference_noise: its own relative Monte Carlo error (from its two halves);
            errors below it are not resolved.
        max_depth: its path depth.
    """

    spp: int
    seconds: float
    reference_noise: float
    max_depth: int = REFERENCE_DEPTH

    def as_json(self) -> JsonObject:
        """The record with its fixed render, detector and storage beside the figures."""
        return {
            "spp": self.spp,
            "max_depth": self.max_depth,
            "render": RenderSharing.PER_DETECTOR.value,
            "detector": DetectorModel.AREA.value,
            "storage": StorageDtype.FLOAT32.value,
            "seconds": self.seconds,
            "reference_noise": self.reference_noise,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> ReferenceRun:
        """Read back :meth:`as_json` (its fixed render, detector and storage checked)."""
        fixed = {"render": "per_detector", "detector": "area", "storage": "float32"}
        if any(record[k] != v for k, v in fixed.items()):
            raise ValueError(f"a reference is rendered {fixed}, not {record}")
        return cls(
            spp=record["spp"],
            seconds=record["seconds"],
            reference_noise=record["reference_noise"],
            max_depth=record["max_depth"],
        )


@dataclass(frozen=True, kw_only=True)
class BaseRun:
    """The base setting every knob is changed away from.

    Args:
        settings: its knobs' levels.
        error: its error against the reference (its Monte Carlo error, mostly).
        seconds: its render seconds per frame, None when ``base_spp`` is not a
            level of the spp knob (it is then not timed).
    """

    settings: KnobSettings
    error: float
    seconds: float | None

    def as_json(self) -> JsonObject:
        """``{**settings, "error", "seconds"}``."""
        return {**self.settings.as_json(), "error": self.error, "seconds": self.seconds}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> BaseRun:
        """Read back :meth:`as_json`."""
        return cls(
            settings=KnobSettings.from_json(record),
            error=record["error"],
            seconds=record["seconds"],
        )


@dataclass(frozen=True, kw_only=True)
class BenchCamera:
    """The camera benched: detectors, mask texels ``(rows, cols)``, diode side (m)."""

    detectors: int
    mask_resolution: tuple[int, int]
    detector_size_m: float

    def as_json(self) -> JsonObject:
        """``{"detectors", "mask_resolution": [rows, cols], "detector_size_m"}``."""
        return {
            "detectors": self.detectors,
            "mask_resolution": list(self.mask_resolution),
            "detector_size_m": self.detector_size_m,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> BenchCamera:
        """Read back :meth:`as_json`."""
        rows, cols = record["mask_resolution"]
        return cls(
            detectors=record["detectors"],
            mask_resolution=(rows, cols),
            detector_size_m=record["detector_size_m"],
        )


@dataclass(frozen=True, kw_only=True)
class Machine:
    """Where the benchmark ran: platform, processor, Mitsuba variant, git revision."""

    platform: str
    processor: str
    variant: str
    git_revision: str

    def as_json(self) -> JsonObject:
        """``{"platform", "processor", "variant", "git_revision"}``."""
        return {
            "platform": self.platform,
            "processor": self.processor,
            "variant": self.variant,
            "git_revision": self.git_revision,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> Machine:
        """Read back :meth:`as_json`."""
        return cls(**{k: record[k] for k in ("platform", "processor", "variant", "git_revision")})


@dataclass(frozen=True, kw_only=True)
class FamilyFidelity:
    """One family's benchmark: every knob's rows against the reference, and the verdicts.

    Args:
        family: the family's name.
        frames: the frames rendered per setting.
        camera: the camera benched.
        config: the benchmark's configuration.
        scene_max_depth: the scene integrator's path depth (None: not a path tracer).
        base: the base setting.
        reference: the converged reference.
        rows: one per knob level, in :data:`~.config.KNOBS` order.
        auto: the automatic fidelity choice (its plan), or None when not run.
        statements: one sentence per effect (:func:`.report.fidelity_statements`).
        machine: where it ran.
    """

    family: str
    frames: tuple[int, ...]
    camera: BenchCamera
    config: FidelityBenchConfig
    scene_max_depth: int | None
    base: BaseRun
    reference: ReferenceRun
    rows: tuple[FidelityRow, ...]
    auto: FidelityPlan | None
    statements: tuple[str, ...]
    machine: Machine

    def as_json(self) -> JsonObject:
        """The family's record of ``fidelity.json``."""
        auto = self.auto
        return {
            "family": self.family,
            "frames": list(self.frames),
            "camera": self.camera.as_json(),
            "config": self.config.sizes_json(),
            "scene_max_depth": self.scene_max_depth,
            "base": self.base.as_json(),
            "reference": self.reference.as_json(),
            "rows": [r.as_json() for r in self.rows],
            "auto": None
            if auto is None
            else {"settings": auto.settings(), "decisions": auto.decisions},
            "statements": list(self.statements),
            "machine": self.machine.as_json(),
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any], config: FidelityBenchConfig) -> FamilyFidelity:
        """Read back :meth:`as_json`, with the benchmark's ``config``."""
        auto = record["auto"]
        return cls(
            family=record["family"],
            frames=tuple(record["frames"]),
            camera=BenchCamera.from_json(record["camera"]),
            config=config,
            scene_max_depth=record["scene_max_depth"],
            base=BaseRun.from_json(record["base"]),
            reference=ReferenceRun.from_json(record["reference"]),
            rows=tuple(FidelityRow.from_json(r) for r in record["rows"]),
            auto=None
            if auto is None
            else FidelityPlan.from_dict(auto["settings"], auto["decisions"]),
            statements=tuple(record["statements"]),
            machine=Machine.from_json(record["machine"]),
        )


@dataclass(frozen=True, kw_only=True)
class FidelityBenchResult:
    """The benchmark of every family of ``config``: ``fidelity.json``.

    Args:
        config: the benchmark.
        families: one result per family, in ``config.families`` order.
    """

    config: FidelityBenchConfig
    families: tuple[FamilyFidelity, ...]

    def as_json(self) -> JsonObject:
        """``{"families": [each family's record]}``, as ``fidelity.json`` holds it."""
        return {"families": [f.as_json() for f in self.families]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> FidelityBenchResult:
        """Read back :meth:`as_json` (the config from the first family's record)."""
        records = data["families"]
        if not records:
            raise ValueError("a fidelity benchmark result holds at least one family")
        names = [r["family"] for r in records]
        config = FidelityBenchConfig.from_json(records[0]["config"], names)
        return cls(
            config=config,
            families=tuple(FamilyFidelity.from_json(r, config) for r in records),
        )


def effect(error: float, base_error: float) -> float:
    """The systematic error a knob adds: its error with the base's removed in quadrature."""
    return math.sqrt(max(error**2 - base_error**2, 0.0))
