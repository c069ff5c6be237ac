"""Robustness curves, tolerances, pooling and the report (rendered in a headless browser)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from support import chromium, linear_task, needs_chromium

from mincam_render.core import strict_json
from mincam_render.learn import train as tr
from mincam_render.studies.robustness.report import write_report
from mincam_render.studies.robustness.result import DesignCurves
from mincam_render.studies.robustness.study import (
    CURVES,
    MIX,
    RobustnessConfig,
    design_record,
    pool_curves,
    pool_episode_metrics,
    robustness_curves,
    tolerance,
)

REPO = Path(__file__).resolve().parents[2]
SMALL = RobustnessConfig(levels=(0.0, 1.0, 2.0), draws=3)


@pytest.mark.parametrize(
    ("increases", "expected", "bounded"),
    [
        ((0.0, 0.05, 0.15), 1.5, True),  # crosses 0.1 halfway between levels 1 and 2
        ((0.0, 0.2, 0.4), 0.5, True),
        ((0.0, 0.01, 0.02), 2.0, False),  # never crosses: at least the largest level
        ((0.2, 0.3, 0.4), 0.0, True),
    ],
)
def test_tolerance_interpolates_where_the_increase_crosses_the_limit(increases, expected, bounded):
    factor, within = tolerance((0.0, 1.0, 2.0), increases, 0.1)
    assert factor == pytest.approx(expected) and within is bounded


def _synthetic_record(name: str, robust: bool, slope: float, seed: int) -> DesignCurves:
    """A record whose increases grow linearly with the level (noise from ``seed``)."""
    rng = np.random.default_rng(seed)
    inc = {
        c: [[[0.0]] + [list(slope * lv + rng.normal(0, 0.01, 3)) for lv in (1.0, 2.0)]]
        for c in CURVES
    }
    return design_record(name, robust, [1.0], inc, SMALL)


def test_levels_hold_the_error_itself_from_each_runs_nominal_error():
    # run 0: nominal 2.0, increases 0.1 and 0.3; run 1: nominal 1.0, increase 0.5 and 0.5
    inc = {c: [[[0.0], [0.1, 0.3]], [[0.0], [0.5, 0.5]]] for c in CURVES}
    rec = design_record("d", True, [2.0, 1.0], inc, RobustnessConfig(levels=(0.0, 1.0), draws=2))
    lv0, lv1 = rec.curves[MIX].levels
    assert lv0.mean_error == pytest.approx(1.5)  # the mean nominal error
    assert lv1.mean_error == pytest.approx((2.2 + 2.6 + 1.5 + 1.5) / 4)
    assert lv1.ci95_error[0] <= lv1.mean_error <= lv1.ci95_error[1]


def test_a_record_reads_back_and_writes_the_same_json():
    rec = _synthetic_record("a", True, 0.2, 0)
    text = strict_json.dumps(rec.as_json())
    back = DesignCurves.from_json(json.loads(text))
    assert strict_json.dumps(back.as_json()) == text
    assert back.curves == rec.curves and back.config.levels == rec.config.levels
    summary = json.loads(strict_json.dumps(rec.as_json(increases=False)))
    assert "increases" not in summary["curves"][MIX]["levels"][1]
    assert DesignCurves.from_json(summary).as_json(increases=False) == summary
    with pytest.raises(ValueError, match="summary"):
        pool_curves([DesignCurves.from_json(summary)], "a")


def test_the_kept_benchmark_designs_read_back_to_the_same_json():
    kept = json.loads((REPO / "benchmarks" / "results" / "robustness.json").read_text())
    for task in kept["tasks"].values():
        for summary in task["designs"].values():
            again = DesignCurves.from_json(summary).as_json(increases=False)
            assert json.dumps(again) == json.dumps(summary)


def test_episode_metrics_pool_rmse_by_samples_and_rates_as_weighted_means():
    rmse = [
        {"error": 1.0, "samples": 100, "error_name": "count RMSE"},
        {"error": 3.0, "samples": 300, "error_name": "count RMSE"},
    ]
    assert pool_episode_metrics(rmse) == pytest.approx(np.sqrt((100 * 1 + 300 * 9) / 400))
    rate = [{**r, "error_name": "error rate"} for r in rmse]
    assert pool_episode_metrics(rate) == pytest.approx((100 * 1 + 300 * 3) / 400)


def test_pooled_runs_average_and_specs_name_the_physical_tolerance():
    a = _synthetic_record("a", False, 0.2, 0)
    b = _synthetic_record("b", False, 0.2, 1)
    pooled = pool_curves([a, b], "ab")
    lv = pooled.curves["mask_shift"].levels[1]
    both = (
        a.curves["mask_shift"].levels[1].increases[0]
        + b.curves["mask_shift"].levels[1].increases[0]
    )
    assert pooled.runs == 2 and lv.mean_increase == pytest.approx(np.mean(both))
    assert lv.ci95_increase[0] <= lv.mean_increase <= lv.ci95_increase[1]
    tol = pooled.curves["mask_shift"].tolerance
    assert tol.values["mask_shift_mm"] == pytest.approx(0.3 * tol.factor)
    assert f"±{0.3 * tol.factor:.2g} mm" in pooled.curves["mask_shift"].spec
    with pytest.raises(ValueError, match="different configurations"):
        other = design_record(
            "c",
            False,
            [1.0],
            {c: [[[0.0], [0.1], [0.2]]] for c in CURVES},
            RobustnessConfig(levels=(0.0, 1.0, 2.0), draws=3, seed=9),
        )
        pool_curves([a, other], "bad")


def test_curves_of_a_trained_camera_start_at_zero_and_use_common_draws(variant):
    train, val, test = linear_task(160, k=2).split((0.6, 0.2, 0.2))
    model = tr.build_mincam(train, 2, seed=1)
    tr.train_model(model, train, val, tr.TrainConfig(max_steps=60, batch_size=32, eval_every=30))
    rec = robustness_curves(model, {"t": test}, SMALL, name="m")
    again = robustness_curves(model, {"t": test}, SMALL, name="m")
    assert rec.nominal_error == pytest.approx(tr.evaluate(model, test).error)
    for c in CURVES:
        first = rec.curves[c].levels[0]
        assert first.draws == 1 and first.mean_increase == 0.0  # level 0: the design itself
        assert [lv.increases for lv in rec.curves[c].levels] == [
            lv.increases for lv in again.curves[c].levels
        ]
    # a mismatch of every detector's gain by up to 2 x 5 % moves a trained count
    assert any(abs(v) > 0 for v in rec.curves["gain_mismatch"].levels[2].increases[0])


@pytest.mark.parametrize(
    "kwargs",
    [{"levels": (0.5, 1.0)}, {"levels": (0.0, 2.0, 1.0)}, {"draws": 1}, {"allowed_increase": 0}],
)
def test_bad_robustness_configs_are_refused(kwargs):
    with pytest.raises(ValueError, match="RobustnessConfig"):
        RobustnessConfig(**kwargs)


def _report(tmp_path):
    designs = [
        _synthetic_record("nominal", False, 0.2, 0),
        _synthetic_record("robust", True, 0.03, 1),
    ]
    return write_report(designs, tmp_path / "rep", notes=["synthetic records"])


def test_report_files_and_specs(tmp_path):
    paths = _report(tmp_path)
    text = paths["html"].read_text()
    assert text.count("data:image/png;base64,") == 1
    assert "align each mask to ±" in text
    assert "Camera pose error is approximated in the mask plane" in text
    assert "Error at the default ranges" in text
    mix = json.loads(paths["json"].read_text())[0]["curves"][MIX]["levels"][1]
    assert f"{mix['mean_error']:.4g} [" in text and mix["mean_error"] > 1.0  # nominal 1
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    back = json.loads(paths["json"].read_text())
    assert [d["name"] for d in back] == ["nominal", "robust"]
    # the robust record's shallow slope allows a wider mix than the nominal one
    assert (
        back[1]["curves"][MIX]["tolerance"]["factor"]
        > back[0]["curves"][MIX]["tolerance"]["factor"]
    )


@needs_chromium
def test_report_renders_in_a_headless_browser(tmp_path):
    path = _report(tmp_path)["html"]
    proc = chromium(tmp_path, "--virtual-time-budget=5000", "--dump-dom", path.as_uri())
    loaded = re.search(r'data-figures-loaded="(\d+)"', proc.stdout)
    assert loaded and int(loaded.group(1)) == 1, proc.stderr[-2000:]
    assert "Fabrication specs" in proc.stdout
