"""Label-space coverage of dataset splits: which states, counts and values each split holds.

A figure on a test split that never shows a state (a light combination, left
traffic) says nothing about that state: lighting reported 1.000 accuracy on
600 frames holding 2 of its 32 light states. :func:`label_coverage` describes
one split's samples per label kind; :func:`coverage_warnings` names what a
split misses against the training split and against the label space; and
:func:`study_coverage` does both for a study's episodes and logs the warnings.

* BINARY label of ``n`` elements: frames per joint state (``"10110"``: element
  ``i`` on at character ``i``), states seen of the ``2**n`` possible, and the
  fraction of frames each element is on (lighting: 32 light states).
* COUNT: histogram of the counts, mean per frame, frames with a count > 0
  (traffic: vehicles per frame in each direction; workspace: people).
* REGRESSION: quantiles over every frame and over the frames at or above the
  label's ``zero_below_true`` (traffic: moving traffic, its speed spread).

Arrays are numpy; labels ``{name: [frame, size]}`` in physical units.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.training_data import TrainingData

log = logging.getLogger(__name__)

#: Quantiles reported for REGRESSION labels.
QUANTILES = (0.0, 0.1, 0.5, 0.9, 1.0)
#: Joint states are enumerated for BINARY labels of at most this many elements.
MAX_STATE_ELEMENTS = 10


@dataclass(frozen=True, kw_only=True)
class StateCoverage:
    """A BINARY label's coverage: the fraction of frames each element is on, and joint states.

    Args:
        elements: the elements' names (their indices when unnamed).
        on_fraction: per element, the fraction of frames it is on (0-1).
        states: ``{"10110": frames}`` of each joint state seen (element ``i`` on
            at character ``i``); None above :data:`MAX_STATE_ELEMENTS` elements.
        states_possible: ``2**elements`` (None with ``states``).
    """

    elements: tuple[str, ...]
    on_fraction: tuple[float, ...]
    states: Mapping[str, int] | None = None
    states_possible: int | None = None

    @property
    def states_seen(self) -> int:
        """Joint states seen (0 when they are not enumerated)."""
        return 0 if self.states is None else len(self.states)

    def as_json(self) -> JsonObject:
        """``{"kind": "states", "elements", "on_fraction"[, "states_possible", ...]}``."""
        out: JsonObject = {
            "kind": "states",
            "elements": list(self.elements),
            "on_fraction": list(self.on_fraction),
        }
        if self.states is not None:
            out |= {"states_possible": self.states_possible, "states_seen": self.states_seen,
                    "states": dict(self.states)}  # fmt: skip
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> StateCoverage:
        """Inverse of :meth:`as_json`."""
        return cls(
            elements=tuple(d["elements"]),
            on_fraction=tuple(float(f) for f in d["on_fraction"]),
            states=None if "states" not in d else {k: int(n) for k, n in d["states"].items()},
            states_possible=d.get("states_possible"),
        )


@dataclass(frozen=True, kw_only=True)
class HistogramCoverage:
    """A COUNT label's coverage: frames per count (``{"2": frames}``), mean, frames above 0."""

    histogram: Mapping[str, int]
    mean: float
    frames_nonzero: int

    def as_json(self) -> JsonObject:
        """``{"kind": "histogram", "histogram", "mean", "frames_nonzero"}``."""
        return {"kind": "histogram", "histogram": dict(self.histogram), "mean": self.mean,
                "frames_nonzero": self.frames_nonzero}  # fmt: skip

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> HistogramCoverage:
        """Inverse of :meth:`as_json`."""
        return cls(histogram={k: int(n) for k, n in d["histogram"].items()},
                   mean=float(d["mean"]), frames_nonzero=int(d["frames_nonzero"]))  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class ValueCoverage:
    """A REGRESSION label's coverage: quantiles over every frame and over the active ones.

    Args:
        unit: the label's unit.
        quantiles: ``{"q10": value}`` at :data:`QUANTILES` (None without frames).
        active_threshold: frames at or above it are active (the label's unit).
        frames_active: active frames.
        active_quantiles: the quantiles of the active frames (None without any).
    """

    unit: str
    quantiles: Mapping[str, float] | None
    active_threshold: float
    frames_active: int
    active_quantiles: Mapping[str, float] | None

    def as_json(self) -> JsonObject:
        """``{"kind": "values", "unit", "quantiles", ...}``."""
        return {
            "kind": "values",
            "unit": self.unit,
            "quantiles": None if self.quantiles is None else dict(self.quantiles),
            "active_threshold": self.active_threshold,
            "frames_active": self.frames_active,
            "active_quantiles": (
                None if self.active_quantiles is None else dict(self.active_quantiles)
            ),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ValueCoverage:
        """Inverse of :meth:`as_json`."""
        return cls(unit=str(d["unit"]), quantiles=d["quantiles"],
                   active_threshold=d["active_threshold"], frames_active=int(d["frames_active"]),
                   active_quantiles=d["active_quantiles"])  # fmt: skip


#: One label's coverage, by its kind.
LabelCoverage = StateCoverage | HistogramCoverage | ValueCoverage
_KINDS: dict[str, type[StateCoverage] | type[HistogramCoverage] | type[ValueCoverage]] = {
    "states": StateCoverage,
    "histogram": HistogramCoverage,
    "values": ValueCoverage,
}


@dataclass(frozen=True, kw_only=True)
class SplitCoverage:
    """One split's samples: their number and each label's coverage."""

    frames: int
    labels: Mapping[str, LabelCoverage]

    def as_json(self) -> JsonObject:
        """``{"frames": n, "labels": {name: {...}}}``."""
        return {"frames": self.frames, "labels": {k: v.as_json() for k, v in self.labels.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SplitCoverage:
        """Inverse of :meth:`as_json`."""
        labels = {k: _KINDS[v["kind"]].from_json(v) for k, v in d["labels"].items()}
        return cls(frames=int(d["frames"]), labels=labels)


@dataclass(frozen=True, kw_only=True)
class StudyCoverage:
    """Every split's coverage and what each misses (:func:`study_coverage`)."""

    splits: Mapping[str, SplitCoverage]
    warnings: tuple[str, ...]

    def as_json(self) -> JsonObject:
        """``{"splits": {name: {...}}, "warnings": [str]}``."""
        return {"splits": {k: v.as_json() for k, v in self.splits.items()},
                "warnings": list(self.warnings)}  # fmt: skip

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> StudyCoverage:
        """Inverse of :meth:`as_json`."""
        splits = {k: SplitCoverage.from_json(v) for k, v in d["splits"].items()}
        return cls(splits=splits, warnings=tuple(d["warnings"]))


def _binary(spec: LabelSpec, y: np.ndarray) -> StateCoverage:
    on = np.asarray(y) >= 0.5
    elements = tuple(spec.element_names) or tuple(str(i) for i in range(spec.size))
    fraction = on.mean(axis=0).tolist() if len(on) else [0.0] * spec.size
    if spec.size > MAX_STATE_ELEMENTS:
        return StateCoverage(elements=elements, on_fraction=tuple(fraction))
    keys, counts = np.unique(on.astype(np.uint8), axis=0, return_counts=True)
    frames = {"".join(map(str, k)): int(c) for k, c in zip(keys, counts, strict=True)}
    return StateCoverage(elements=elements, on_fraction=tuple(fraction), states=frames,
                         states_possible=2**spec.size)  # fmt: skip


def _count(y: np.ndarray) -> HistogramCoverage:
    c = np.rint(np.asarray(y)).astype(np.int64).ravel()
    values, counts = np.unique(c, return_counts=True)
    return HistogramCoverage(
        histogram={str(v): int(n) for v, n in zip(values, counts, strict=True)},
        mean=float(c.mean()) if c.size else 0.0,
        frames_nonzero=int((c > 0).sum()),
    )


def _quantiles(v: np.ndarray) -> dict[str, float] | None:
    if v.size == 0:
        return None
    values = np.quantile(v, QUANTILES)
    return {f"q{round(q * 100):02d}": float(x) for q, x in zip(QUANTILES, values, strict=True)}


def _regression(spec: LabelSpec, y: np.ndarray) -> ValueCoverage:
    v = np.asarray(y, np.float64).ravel()
    threshold = spec.zero_below_true if spec.zero_below_true is not None else 0.0
    above = v[v >= threshold] if spec.zero_below_true is not None else v[v != 0.0]
    return ValueCoverage(
        unit=spec.unit,
        quantiles=_quantiles(v),
        active_threshold=threshold,
        frames_active=int(above.size),
        active_quantiles=_quantiles(above),
    )


def label_coverage(labels: Mapping[str, np.ndarray], specs: Sequence[LabelSpec]) -> SplitCoverage:
    """Coverage of one split's samples: its frames and each label's (module docstring).

    A REGRESSION label's *active* frames are those at or above its
    ``zero_below_true`` (moving traffic), or non-zero without one.
    """
    frames, out = 0, dict[str, LabelCoverage]()
    for s in specs:
        y = np.asarray(labels[s.name])
        frames = len(y)
        if s.kind is LabelKind.BINARY:
            out[s.name] = _binary(s, y)
        elif s.kind is LabelKind.COUNT:
            out[s.name] = _count(y)
        else:
            out[s.name] = _regression(s, y)
    return SplitCoverage(frames=frames, labels=out)


def _missing(name: str, split: SplitCoverage, train: SplitCoverage | None) -> list[str]:
    """What ``split`` misses of label ``name``: against the label space, and against ``train``."""
    lab, ref = split.labels[name], None if train is None else train.labels.get(name)
    out = []
    if isinstance(lab, StateCoverage) and lab.states is not None:
        seen, possible = lab.states_seen, lab.states_possible
        if possible is not None and seen < possible:
            out.append(f"{name}: {seen} of the {possible} states")
        if isinstance(ref, StateCoverage):
            lack = sorted(set(ref.states or {}) - set(lab.states))
            if lack:
                out.append(f"{name}: lacks {len(lack)} state(s) training has ({', '.join(lack)})")
    elif isinstance(lab, HistogramCoverage):
        if lab.frames_nonzero == 0:
            out.append(f"{name}: zero in every frame")
        if isinstance(ref, HistogramCoverage):
            lack = sorted(set(ref.histogram) - set(lab.histogram), key=int)
            if lack:
                out.append(f"{name}: lacks value(s) training has ({', '.join(lack)})")
    elif isinstance(lab, ValueCoverage) and lab.frames_active == 0:
        out.append(f"{name}: no frame at or above {lab.active_threshold:g} {lab.unit}".rstrip())
    return out


def coverage_warnings(splits: Mapping[str, SplitCoverage], train: str = "train") -> list[str]:
    """What each split misses: ``"<split>: <label>: ..."`` lines.

    Every split is checked against the label space (all ``2**n`` states of a
    BINARY label; a COUNT that is never above 0; a REGRESSION label never
    active); every split but ``train`` also against the training split (states
    or counts training has that it lacks).

    Args:
        splits: ``{split: label_coverage(...)}``.
        train: name of the training split among ``splits`` (absent: no comparison).
    """
    ref = splits.get(train)
    out = []
    for name, cov in splits.items():
        for label in cov.labels:
            out += [f"{name}: {m}" for m in _missing(label, cov, None if name == train else ref)]
    return out


def study_coverage(splits: Mapping[str, TrainingData], train: str = "train") -> StudyCoverage:
    """Coverage of every split's samples and its warnings (also logged).

    Samples are what a model sees: a temporal split's labels at the last
    frame of each window.
    """
    cov = {name: label_coverage(d.sample_labels(), d.label_specs) for name, d in splits.items()}
    warnings = coverage_warnings(cov, train)
    for w in warnings:
        log.warning("label coverage: %s", w)
    return StudyCoverage(splits=cov, warnings=tuple(warnings))


def _summary(lab: LabelCoverage) -> str:
    """One table cell describing a label's coverage."""
    if isinstance(lab, StateCoverage):
        on = ", ".join(f"{e} {f:.2f}" for e, f in zip(lab.elements, lab.on_fraction, strict=True))
        seen = f"{lab.states_seen}/{lab.states_possible} states; " if lab.states is not None else ""
        return f"{seen}fraction on: {on}"
    if isinstance(lab, HistogramCoverage):
        hist = " ".join(f"{k}:{n}" for k, n in lab.histogram.items())
        return f"mean {lab.mean:.2f}/frame; > 0 in {lab.frames_nonzero} frames; {hist}"
    q = lab.active_quantiles
    spread = "" if q is None else f"; q10/q50/q90 {q['q10']:.1f}/{q['q50']:.1f}/{q['q90']:.1f}"
    return f"{lab.frames_active} frames >= {lab.active_threshold:g} {lab.unit}{spread}"


def coverage_table(coverage: StudyCoverage) -> str:
    """Markdown: one row per split and label (:func:`study_coverage`'s output), then warnings."""
    lines = [
        "## Label coverage per split",
        "",
        "| split | frames | label | coverage |",
        "|---|---:|---|---|",
    ]
    for name, cov in coverage.splits.items():
        for label, lab in cov.labels.items():
            lines.append(f"| {name} | {cov.frames} | {label} | {_summary(lab)} |")
    lines.append("")
    lines += [f"Warning: {w}." for w in coverage.warnings] or ["Every split covers its labels."]
    return "\n".join(lines)
