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
from typing import Any

import numpy as np

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn.training_data import TrainingData

log = logging.getLogger(__name__)

#: Quantiles reported for REGRESSION labels.
QUANTILES = (0.0, 0.1, 0.5, 0.9, 1.0)
#: Joint states are enumerated for BINARY labels of at most this many elements.
MAX_STATE_ELEMENTS = 10


def _binary(spec: LabelSpec, y: np.ndarray) -> dict[str, Any]:
    on = np.asarray(y) >= 0.5
    out: dict[str, Any] = {
        "kind": "states",
        "elements": list(spec.element_names) or [str(i) for i in range(spec.size)],
        "on_fraction": on.mean(axis=0).tolist() if len(on) else [0.0] * spec.size,
    }
    if spec.size <= MAX_STATE_ELEMENTS:
        keys, counts = np.unique(on.astype(np.uint8), axis=0, return_counts=True)
        frames = {"".join(map(str, k)): int(c) for k, c in zip(keys, counts, strict=True)}
        out |= {"states_possible": 2**spec.size, "states_seen": len(frames), "states": frames}
    return out


def _count(y: np.ndarray) -> dict[str, Any]:
    c = np.rint(np.asarray(y)).astype(np.int64).ravel()
    values, counts = np.unique(c, return_counts=True)
    return {
        "kind": "histogram",
        "histogram": {str(v): int(n) for v, n in zip(values, counts, strict=True)},
        "mean": float(c.mean()) if c.size else 0.0,
        "frames_nonzero": int((c > 0).sum()),
    }


def _quantiles(v: np.ndarray) -> dict[str, float] | None:
    if v.size == 0:
        return None
    values = np.quantile(v, QUANTILES)
    return {f"q{round(q * 100):02d}": float(x) for q, x in zip(QUANTILES, values, strict=True)}


def _regression(spec: LabelSpec, y: np.ndarray) -> dict[str, Any]:
    v = np.asarray(y, np.float64).ravel()
    threshold = spec.zero_below_true if spec.zero_below_true is not None else 0.0
    above = v[v >= threshold] if spec.zero_below_true is not None else v[v != 0.0]
    return {
        "kind": "values",
        "unit": spec.unit,
        "quantiles": _quantiles(v),
        "active_threshold": threshold,
        "frames_active": int(above.size),
        "active_quantiles": _quantiles(above),
    }


def label_coverage(labels: Mapping[str, np.ndarray], specs: Sequence[LabelSpec]) -> dict[str, Any]:
    """Coverage of one split's samples: ``{"frames": n, "labels": {name: {...}}}`` (module doc).

    A REGRESSION label's *active* frames are those at or above its
    ``zero_below_true`` (moving traffic), or non-zero without one.
    """
    out: dict[str, Any] = {"frames": 0, "labels": {}}
    for s in specs:
        y = np.asarray(labels[s.name])
        out["frames"] = len(y)
        if s.kind is LabelKind.BINARY:
            out["labels"][s.name] = _binary(s, y)
        elif s.kind is LabelKind.COUNT:
            out["labels"][s.name] = _count(y)
        else:
            out["labels"][s.name] = _regression(s, y)
    return out


def _missing(name: str, split: Mapping[str, Any], train: Mapping[str, Any] | None) -> list[str]:
    """What ``split`` misses of label ``name``: against the label space, and against ``train``."""
    lab, ref = split["labels"][name], (train or {"labels": {}})["labels"].get(name)
    out = []
    if lab["kind"] == "states" and "states" in lab:
        seen, possible = lab["states_seen"], lab["states_possible"]
        if seen < possible:
            out.append(f"{name}: {seen} of the {possible} states")
        if ref is not None:
            lack = sorted(set(ref["states"]) - set(lab["states"]))
            if lack:
                out.append(f"{name}: lacks {len(lack)} state(s) training has ({', '.join(lack)})")
    elif lab["kind"] == "histogram":
        if lab["frames_nonzero"] == 0:
            out.append(f"{name}: zero in every frame")
        if ref is not None:
            lack = sorted(set(ref["histogram"]) - set(lab["histogram"]), key=int)
            if lack:
                out.append(f"{name}: lacks value(s) training has ({', '.join(lack)})")
    elif lab["frames_active"] == 0:
        out.append(
            f"{name}: no frame at or above {lab['active_threshold']:g} {lab['unit']}".rstrip()
        )
    return out


def coverage_warnings(splits: Mapping[str, Mapping[str, Any]], train: str = "train") -> list[str]:
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
        for label in cov["labels"]:
            out += [f"{name}: {m}" for m in _missing(label, cov, None if name == train else ref)]
    return out


def study_coverage(splits: Mapping[str, TrainingData], train: str = "train") -> dict[str, Any]:
    """Coverage of every split's samples and its warnings (also logged).

    Samples are what a model sees: a temporal split's labels at the last
    frame of each window.

    Returns:
        ``{"splits": {name: label_coverage}, "warnings": [str]}``.
    """
    cov = {
        name: label_coverage({k: v[d.history - 1 :] for k, v in d.labels.items()}, d.label_specs)
        for name, d in splits.items()
    }
    warnings = coverage_warnings(cov, train)
    for w in warnings:
        log.warning("label coverage: %s", w)
    return {"splits": cov, "warnings": warnings}


def _summary(lab: Mapping[str, Any]) -> str:
    """One table cell describing a label's coverage."""
    if lab["kind"] == "states":
        on = ", ".join(
            f"{e} {f:.2f}" for e, f in zip(lab["elements"], lab["on_fraction"], strict=True)
        )
        seen = f"{lab['states_seen']}/{lab['states_possible']} states; " if "states" in lab else ""
        return f"{seen}fraction on: {on}"
    if lab["kind"] == "histogram":
        hist = " ".join(f"{k}:{n}" for k, n in lab["histogram"].items())
        return f"mean {lab['mean']:.2f}/frame; > 0 in {lab['frames_nonzero']} frames; {hist}"
    q = lab["active_quantiles"]
    spread = "" if q is None else f"; q10/q50/q90 {q['q10']:.1f}/{q['q50']:.1f}/{q['q90']:.1f}"
    return f"{lab['frames_active']} frames >= {lab['active_threshold']:g} {lab['unit']}{spread}"


def coverage_table(coverage: Mapping[str, Any]) -> str:
    """Markdown: one row per split and label (:func:`study_coverage`'s output), then warnings."""
    lines = [
        "## Label coverage per split",
        "",
        "| split | frames | label | coverage |",
        "|---|---:|---|---|",
    ]
    for name, cov in coverage["splits"].items():
        for label, lab in cov["labels"].items():
            lines.append(f"| {name} | {cov['frames']} | {label} | {_summary(lab)} |")
    lines.append("")
    lines += [f"Warning: {w}." for w in coverage["warnings"]] or ["Every split covers its labels."]
    return "\n".join(lines)
