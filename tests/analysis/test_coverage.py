"""Label coverage of splits: states, counts and values per split, and what a split misses."""

from __future__ import annotations

import numpy as np
import pytest

from mincam_render.analysis.coverage import (
    HistogramCoverage,
    StateCoverage,
    StudyCoverage,
    ValueCoverage,
    coverage_table,
    coverage_warnings,
    label_coverage,
    study_coverage,
)
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.learn import train as tr
from mincam_render.optics.camera import FreeformCamera

LIGHTS = LabelSpec(
    name="lights", kind=LabelKind.BINARY, size=5, element_names=("a", "b", "c", "d", "e")
)
SPEED = LabelSpec(name="speed_left_mph", kind=LabelKind.REGRESSION, unit="mph", zero_below_true=3.0)
COUNT = LabelSpec(name="count_left", kind=LabelKind.COUNT)


def _states(*rows: str, repeat: int = 1) -> np.ndarray:
    return np.repeat(np.array([[int(c) for c in r] for r in rows], np.float32), repeat, axis=0)


def test_binary_coverage_counts_frames_per_joint_state():
    cov = label_coverage({"lights": _states("10000", "10000", "11111", "00000")}, (LIGHTS,))
    lab = cov.labels["lights"]
    assert cov.frames == 4 and isinstance(lab, StateCoverage)
    assert lab.states == {"00000": 1, "10000": 2, "11111": 1}
    assert lab.states_seen == 3 and lab.states_possible == 32
    assert lab.on_fraction == pytest.approx([0.75, 0.25, 0.25, 0.25, 0.25])


def test_count_and_speed_coverage_closed_forms():
    speed = np.arange(101, dtype=np.float32)[:, None]  # 0 .. 100 mph
    count = np.array([0, 0, 1, 2, 2] * 20 + [3], np.float32)[:, None]
    cov = label_coverage({"speed_left_mph": speed, "count_left": count}, (SPEED, COUNT))
    s, c = cov.labels["speed_left_mph"], cov.labels["count_left"]
    assert isinstance(s, ValueCoverage) and isinstance(c, HistogramCoverage)
    assert s.quantiles is not None and s.quantiles["q50"] == pytest.approx(50.0)
    assert s.frames_active == 98  # 3 .. 100 mph
    assert s.active_quantiles is not None
    assert s.active_quantiles["q00"] == 3.0 and s.active_quantiles["q100"] == 100.0
    assert c.histogram == {"0": 40, "1": 20, "2": 40, "3": 1}
    assert c.mean == pytest.approx((20 * 1 + 40 * 2 + 3) / 101) and c.frames_nonzero == 61


def test_warnings_name_what_a_split_misses_of_training_and_of_the_label_space():
    train = label_coverage(
        {
            "lights": _states("10000", "01000", "11111"),
            "speed_left_mph": np.array([[0.0], [20.0], [30.0]]),
            "count_left": np.array([[0.0], [1.0], [2.0]]),
        },
        (LIGHTS, SPEED, COUNT),
    )
    test = label_coverage(
        {
            "lights": _states("10000", "10000", "11111"),
            "speed_left_mph": np.array([[0.0], [1.0], [2.0]]),  # no left traffic moving
            "count_left": np.zeros((3, 1)),
        },
        (LIGHTS, SPEED, COUNT),
    )
    warnings = coverage_warnings({"train": train, "test-0": test})
    assert "train: lights: 3 of the 32 states" in warnings
    assert "test-0: lights: lacks 1 state(s) training has (01000)" in warnings
    assert "test-0: speed_left_mph: no frame at or above 3 mph" in warnings
    assert "test-0: count_left: zero in every frame" in warnings
    assert "test-0: count_left: lacks value(s) training has (1, 2)" in warnings
    assert not [w for w in warnings if w.startswith("train: count") or "train: speed" in w]


def test_study_coverage_describes_the_samples_of_temporal_splits_and_tables_them():
    n = 40
    lights = _states("10000", "00001", repeat=n // 2)
    data = tr.TrainingData(
        transport=np.zeros((n, 1, 2, 2), np.float32),
        labels={"lights": lights},
        label_specs=(LIGHTS,),
        camera=FreeformCamera(mask_resolution=(2, 2)),
        fps=30.0,
        history=30,
    )
    cov = study_coverage({"train": data})
    # 11 samples, each labelled at its window's last frame: frames 29 .. 39, all "00001"
    train = cov.splits["train"]
    assert train.frames == 11
    lights = train.labels["lights"]
    assert isinstance(lights, StateCoverage) and lights.states == {"00001": 11}
    table = coverage_table(cov)
    assert "| train | 11 | lights | 1/32 states" in table
    assert "Warning: train: lights: 1 of the 32 states." in table


def test_coverage_json_keeps_its_keys_and_reads_back():
    """``metrics.json``'s ``coverage``: the keys and order of the dicts it was written as."""
    lights = _states("10000", "01000", "11111")
    speed, count = np.array([[0.0], [20.0], [30.0]]), np.array([[0.0], [1.0], [2.0]])
    labels = {"lights": lights, "speed_left_mph": speed, "count_left": count}
    split = label_coverage(labels, (LIGHTS, SPEED, COUNT))
    cov = StudyCoverage(splits={"train": split}, warnings=("a",))
    record = cov.as_json()
    assert list(record) == ["splits", "warnings"]
    train = record["splits"]["train"]
    assert list(train) == ["frames", "labels"] and train["frames"] == 3
    assert list(train["labels"]["lights"]) == [
        "kind", "elements", "on_fraction", "states_possible", "states_seen", "states",
    ]  # fmt: skip
    assert train["labels"]["lights"]["states"] == {"01000": 1, "10000": 1, "11111": 1}
    assert list(train["labels"]["count_left"]) == ["kind", "histogram", "mean", "frames_nonzero"]
    assert list(train["labels"]["speed_left_mph"]) == [
        "kind", "unit", "quantiles", "active_threshold", "frames_active", "active_quantiles",
    ]  # fmt: skip
    assert StudyCoverage.from_json(record) == cov
    assert StudyCoverage.from_json(record).as_json() == record
