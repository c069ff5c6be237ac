"""The paper's evaluation: post-processing, the traffic zero rule and the headline figure."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.data import dataset as ds
from mincam_render.learn import train as tr
from mincam_render.learn.evaluation import LabelMetrics, headline, metrics, zero_where_true_below
from mincam_render.optics.camera import FreeformCamera


def _speed(side: str, **kw: object) -> LabelSpec:
    return LabelSpec(
        name=f"speed_{side}_mph", kind=LabelKind.REGRESSION, unit="mph", median_filter_s=0.0, **kw
    )


RULED = {"zero_below_true": 3.0, "headline": "mean speed"}


def _data(labels: dict[str, np.ndarray], specs: tuple[LabelSpec, ...]) -> tr.TrainingData:
    n = len(next(iter(labels.values())))
    return tr.TrainingData(
        transport=np.zeros((n, 1, 2, 2), np.float32),
        labels={k: np.asarray(v, np.float32).reshape(n, -1) for k, v in labels.items()},
        label_specs=specs,
        camera=FreeformCamera(mask_resolution=(2, 2)),
        fps=30.0,
    )


def test_zero_rule_sets_predictions_to_zero_where_truth_is_slow():
    specs = (_speed("left", **RULED),)
    y = np.array([[0.0], [2.9], [3.0], [10.0]])
    post = {"speed_left_mph": np.full((4, 1), 4.0)}
    out = zero_where_true_below(post, {"speed_left_mph": y}, specs)
    np.testing.assert_array_equal(out["speed_left_mph"][:, 0], [0.0, 0.0, 4.0, 4.0])


def test_headline_pools_both_directions_as_a_root_mean_square():
    # left: no traffic in the window (truth 0), right: 10 mph; predictions 1 and 13 mph
    n = 60
    lab = {"speed_left_mph": np.zeros(n), "speed_right_mph": np.full(n, 10.0)}
    specs = (_speed("left", **RULED), _speed("right", **RULED))
    data = _data(lab, specs)
    pred = {"speed_left_mph": np.ones((n, 1)), "speed_right_mph": np.full((n, 1), 13.0)}
    res = metrics(pred, data.labels, 0.0, data)
    left, right = res.labels["speed_left_mph"], res.labels["speed_right_mph"]
    assert left.rmse == 0.0  # zeroed: truth < 3 mph everywhere
    assert left.rmse_without_zero_rule == pytest.approx(1.0)
    assert left.zero_below_true == 3.0
    assert right.rmse == pytest.approx(3.0)
    assert res.error == pytest.approx(np.sqrt((0.0**2 + 3.0**2) / 2))
    assert res.error_name == "mean speed RMSE"
    assert res.headline.labels == ("speed_left_mph", "speed_right_mph")


def test_without_headline_labels_the_first_label_is_the_figure():
    n = 40
    specs = (_speed("left"), _speed("right"))
    data = _data({"speed_left_mph": np.zeros(n), "speed_right_mph": np.zeros(n)}, specs)
    pred = {"speed_left_mph": np.full((n, 1), 2.0), "speed_right_mph": np.full((n, 1), 5.0)}
    res = metrics(pred, data.labels, 0.0, data)
    assert res.error == pytest.approx(2.0)
    assert res.error_name == "speed_left_mph RMSE"
    assert "rmse_without_zero_rule" not in res.labels["speed_left_mph"].as_json()


def test_binary_headline_is_one_minus_the_mean_accuracy_over_elements():
    spec = LabelSpec(name="lights", kind=LabelKind.BINARY, size=5, median_filter_s=0.0)
    lab = np.zeros((10, 5))
    pred = np.zeros((10, 5))
    pred[:, 0] = 1.0  # light 0 always wrong, the others right
    data = _data({"lights": lab}, (spec,))
    res = metrics({"lights": pred}, data.labels, 0.0, data)
    assert res.labels["lights"].accuracy_per_element == (0.0, 1.0, 1.0, 1.0, 1.0)
    assert res.error == pytest.approx(0.2)
    assert res.error_name == "lights error rate"


def test_lighting_median_filter_removes_flips_shorter_than_its_window():
    spec = LabelSpec(name="lights", kind=LabelKind.BINARY, size=1, median_filter_s=0.5)
    lab = np.zeros((60, 1))
    pred = np.zeros((60, 1))
    pred[20:25] = 1.0  # a 5-frame flip; at 30 fps the 0.5 s window is 15 frames
    data = _data({"lights": lab}, (spec,))
    res = metrics({"lights": pred}, data.labels, 0.0, data)
    assert res.labels["lights"].median_filter_frames == 15
    assert res.labels["lights"].accuracy == 1.0


@pytest.mark.parametrize(
    ("specs", "match"),
    [
        ((_speed("left", headline="a"), _speed("right", headline="b")), "several headlines"),
        (
            (
                _speed("left", headline="a"),
                LabelSpec(name="lights", kind=LabelKind.BINARY, headline="a"),
            ),
            "mixes",
        ),
    ],
)
def test_headline_refuses_ambiguous_groups(specs, match):
    labels = {"speed_left_mph": LabelMetrics(unit="mph", median_filter_frames=1, rmse=1.0),
              "speed_right_mph": LabelMetrics(unit="mph", median_filter_frames=1, rmse=1.0),
              "lights": LabelMetrics(unit="", median_filter_frames=1, accuracy=1.0)}  # fmt: skip
    with pytest.raises(ValueError, match=match):
        headline(labels, specs)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"kind": LabelKind.COUNT, "zero_below_true": 3.0}, "zero_below_true"),
        ({"kind": LabelKind.REGRESSION, "zero_below_true": float("nan")}, "zero_below_true"),
        ({"kind": LabelKind.REGRESSION, "size": 0}, "size"),
        ({"kind": LabelKind.REGRESSION, "median_filter_s": -1.0}, "median_filter_s"),
        ({"kind": LabelKind.BINARY, "size": 2, "element_names": ("a",)}, "element_names"),
    ],
)
def test_label_spec_refuses_bad_fields(kw, match):
    with pytest.raises(ValueError, match=match):
        LabelSpec(name="x", **kw)


def test_label_rules_round_trip_through_the_manifest_and_are_absent_when_unset():
    spec = _speed("left", **RULED)
    back = ds.label_spec_from_dict(json.loads(json.dumps(ds.label_spec_to_dict(spec))))
    assert back == spec
    plain = ds.label_spec_to_dict(_speed("left"))
    assert "zero_below_true" not in plain and "headline" not in plain
