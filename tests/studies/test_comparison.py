"""Comparisons of designs: design names, episode seeds, reduction factor, study table, CLI."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from mincam_render.analysis.coverage import StudyCoverage
from mincam_render.analysis.statistics import Interval
from mincam_render.cli.main import main
from mincam_render.learn import train as tr
from mincam_render.learn.evaluation import Evaluation, Headline, LabelMetrics
from mincam_render.learn.train import run_masks
from mincam_render.learn.train_config import HeadKind
from mincam_render.studies.comparison.config import Protocol
from mincam_render.studies.comparison.records import (
    Convergence,
    DesignRecord,
    LabelFigures,
    TrivialFigures,
    training_state,
)
from mincam_render.studies.comparison.report import label_table, plot_comparison, study_table
from mincam_render.studies.comparison.result import ComparisonResult, StudySummary, TaskComparison
from mincam_render.studies.comparison.study import (
    ComparisonConfig,
    Design,
    episode_requests,
    keep_run_masks,
    label_intervals,
    reduction_factor,
    reference_verdicts,
    study_summary,
)


def _design(pixels, mean, lo, hi, grid=None):
    kind = "baseline" if grid else "mincam"  # the kind is read from here, never from the name
    model = {"kind": kind, "pixels": pixels, **({"grid": list(grid)} if grid else {})}
    done = Convergence(converged=True, improvement=0.0, steps=100, stopped_early=True)
    return DesignRecord(
        model=model, error=Interval(mean, lo, hi), episode_errors=None, error_per_seed=(mean,),
        val_error_per_seed=None, validation=None, convergence=(done,),
        train_wall_time_s=(1.0,), steps=(100,), runs=("run",), structure=None,
    )  # fmt: skip


def _block(designs=None, *, error_name="count RMSE", trivial=None, labels=None):
    designs = designs or {
        "mincam-4px": _design(4, 1.0, 0.9, 1.1),
        "baseline-2x2": _design(4, 2.0, 1.8, 2.2, (2, 2)),
        "baseline-4x4": _design(16, 1.3, 1.05, 1.5, (4, 4)),  # overlaps 4 px
        "baseline-8x8": _design(64, 0.8, 0.7, 0.85, (8, 8)),
    }
    trivial = trivial or TrivialFigures(
        error=Interval(3.0, 2.9, 3.1), episode_errors=None, episodes={}
    )
    return TaskComparison(error_name=error_name, designs=designs, trivial=trivial, verdict="x",
                          versus_trivial={}, paired={}, labels=labels or {})  # fmt: skip


def _result(block=None, *, study=None, element_names=None):
    """A comparison of one task (``block``) named ``toy``."""
    block = block or _block()
    return ComparisonResult(
        family="toy", protocol=Protocol.PER_TASK, config={"seed": 0}, episodes={},
        labels=block.labels, tasks={"toy": block}, combined={},
        element_names=element_names or {}, coverage=StudyCoverage(splits={}, warnings=()),
        figure="comparison.png", versions={}, study=study,
    )  # fmt: skip


def _study(rf):
    return StudySummary(reduction_factor=rf, configurations={}, reference_verdicts=())


def test_reduction_factor_is_the_smallest_baseline_whose_interval_reaches_the_reference():
    rf = reduction_factor(_block(), "mincam-4px")
    assert rf.baseline == "4x4" and rf.factor == 16 / 4
    assert rf.largest_tried_factor == 64 / 4


def test_reduction_factor_without_a_match_says_it_exceeds_the_largest_tried():
    block = _block()
    designs = dict(block.designs, **{"mincam-4px": _design(4, 0.3, 0.2, 0.4)})
    block = dataclasses.replace(block, designs=designs)
    rf = reduction_factor(block, "mincam-4px")
    assert rf.factor is None and rf.largest_tried_factor == 16
    assert "above 16x" in study_table(_result(block, study=_study(rf)))
    with pytest.raises(ValueError, match="not in the study"):
        reduction_factor(block, "mincam-3px")


def test_reduction_factor_compares_with_baselines_of_the_references_head():
    block = _block()
    tcn = _design(4, 1.0, 0.9, 1.1, (2, 2))
    tcn = dataclasses.replace(tcn, model={**tcn.model, "head": "tcn"})
    # would match at 1x, but is another head
    block = dataclasses.replace(block, designs={**block.designs, "baseline-2x2-tcn": tcn})
    assert reduction_factor(block, "mincam-4px").baseline == "4x4"


@pytest.mark.parametrize("heads", ["lstm", "mlp,mlp", ","])
def test_cli_study_refuses_unknown_or_repeated_heads(tmp_path, heads):
    args = ["study", "--family", "patches", "--heads", heads, "--out", str(tmp_path / "s")]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2 and "--heads" in res.output, res.output
    assert not (tmp_path / "s").exists()


def test_study_table_lists_every_design_and_the_trivial_predictor():
    block = _block()
    table = study_table(_result(block, study=_study(reduction_factor(block, "mincam-4px"))))
    for name in block.designs:
        assert f"| {name} |" in table
    assert "| trivial predictor | 0 | 3.000 [2.900, 3.100]" in table
    assert "4x (matches baseline 4x4)" in table


def test_designs_are_named_and_validated():
    assert Design(pixels=8).name == "mincam-8px"
    assert Design(pixels=8, sensor_model=False).name == "mincam-8px-nosensor"
    assert Design(grid=(4, 6)).name == "baseline-4x6"
    assert Design(pixels=8, head="tcn").name == "mincam-8px-tcn"
    assert Design(grid=(8, 14), head=HeadKind.TCN).name == "baseline-8x14-tcn"
    assert Design(pixels=8, sensor_model=False, head="tcn").name == "mincam-8px-nosensor-tcn"
    with pytest.raises(ValueError, match="lstm"):
        Design(pixels=8, head="lstm")
    with pytest.raises(ValueError, match="exactly one"):
        Design(pixels=4, grid=(2, 2))
    with pytest.raises(ValueError, match="each once"):
        ComparisonConfig(designs=(Design(pixels=2), Design(pixels=2)))
    with pytest.raises(ValueError, match="at least one"):
        ComparisonConfig(designs=())


def test_episodes_have_their_own_seeds_splits_and_balanced_shards():
    reqs = episode_requests(ComparisonConfig(test_episodes=3))
    assert sorted(reqs) == [
        "test-0", "test-1", "test-2", "train-0", "train-1", "val-0", "val-1", "val-2"
    ]  # fmt: skip
    assert len({r.seed for r in reqs.values()}) == 8
    # a validation episode is the same whatever the number of them
    assert episode_requests(ComparisonConfig(val_episodes=1))["val-0"] == reqs["val-0"]
    assert reqs["train-0"].splits == (1.0, 0.0, 0.0) and reqs["test-2"].splits == (0.0, 0.0, 1.0)
    assert reqs["train-1"].num_frames == 1200 and reqs["train-1"].shard_frames == 300
    # another root seed: other episodes
    other = episode_requests(ComparisonConfig(seed=1))
    assert not {r.seed for r in reqs.values()} & {r.seed for r in other.values()}


def test_episodes_carry_the_overrides_and_the_frame_rate():
    cfg = ComparisonConfig(overrides={"camera": {"detectors": 16}}, fps=3.0)
    for req in episode_requests(cfg).values():
        assert req.overrides == {"camera": {"detectors": 16}, "fps": 3.0}
    assert episode_requests(ComparisonConfig())["val-0"].overrides == {"fps": 2.0}
    with pytest.raises(ValueError, match="as fps, not as an override"):
        ComparisonConfig(overrides={"fps": 30.0})


def test_episodes_render_the_mask_resolution_the_finest_baseline_needs():
    designs = (Design(pixels=2), Design(grid=(64, 64)))
    reqs = episode_requests(ComparisonConfig(designs=designs, mask_res=64))
    assert {r.mask_res for r in reqs.values()} == {64}
    assert {r.mask_res for r in episode_requests(ComparisonConfig()).values()} == {None}
    with pytest.raises(ValueError, match="64x64 baseline needs at least 64 texels"):
        ComparisonConfig(designs=designs, mask_res=32)
    with pytest.raises(ValueError, match="mask_res = 0: allowed an integer"):
        ComparisonConfig(mask_res=0)


@pytest.mark.parametrize(
    "args",
    [["--detectors", "2"], ["--set", "camera.detectors=2"]],
)
def test_cli_study_default_pixels_follow_the_detector_override(args, tmp_path):
    """The narrow description has no [camera] table: the override still sets 2 detectors."""
    from mincam_render.core.package_data import shipped_path

    narrow = str(shipped_path("patches_narrow.toml"))
    cmd = ["study", "--family", narrow, *args, "--out", str(tmp_path)]
    res = CliRunner().invoke(main, cmd)
    assert res.exit_code == 2
    assert "4 is not among --pixels [1, 2]" in res.output
    assert not any(tmp_path.iterdir())  # refused before anything was written


def test_cli_study_sweeps_designs_with_the_ablation_and_writes_the_table(variant, tmp_path):
    out = tmp_path / "study"
    args = [
        "study", "--family", "patches", "--train-frames", "60", "--val-frames", "30",
        "--test-frames", "30", "--test-episodes", "2", "--seeds", "2", "--steps", "20",
        "--workers", "0", "--spp", "2", "--pixels", "1,2", "--baseline-grids", "1x1,2x2",
        "--ablation", "--reference-pixels", "2", "--out", str(out),
    ]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    metrics = json.loads((out / "metrics.json").read_text())
    names = {"mincam-1px", "mincam-2px", "mincam-1px-nosensor", "mincam-2px-nosensor"}
    assert set(metrics["designs"]) == names | {"baseline-1x1", "baseline-2x2"}
    assert metrics["reduction_factor"]["reference"] == "mincam-2px"
    summary = metrics["configurations"]["mincam-2px"]
    assert summary["rmse_mean"] == metrics["designs"]["mincam-2px"]["error"]["mean"]
    assert summary["seeds"] == 2 and isinstance(summary["converged"], bool)
    table = (out / "study.md").read_text()
    assert all(f"| {n} |" in table for n in metrics["designs"])
    # each verdict of the reference against a baseline is followed by its paired difference
    verdicts = metrics["reference_verdicts"]
    assert len(verdicts) == 4 and verdicts[1].startswith(
        "paired difference mincam-2px - baseline-1x1"
    )
    assert all(line in table for line in verdicts)
    for n in names:  # every minimalist design keeps its masks, and what they look at
        assert (out / "masks" / "patches" / n / "masks.json").is_file()
        assert (out / "masks" / "patches" / n / "looks_at.png").is_file()
        structure = metrics["designs"][n]["structure"]
        assert len(structure["tv_per_texel"]) == int(n.split("-")[1][0]) and structure["labels"]
    assert metrics["designs"]["baseline-2x2"]["structure"] is None
    for run in metrics["designs"]["mincam-2px-nosensor"]["runs"]:  # supplement A
        tested, masks = json.loads((Path(run) / "run.json").read_text()), Path(run).parent
        assert tested["model"]["sensor_model"] and tested["frozen_masks_from"] == str(masks)
        assert not json.loads((masks / "run.json").read_text())["model"]["sensor_model"]
        np.testing.assert_array_equal(run_masks(run)[0], run_masks(masks)[0])


def test_kept_run_masks_equal_the_runs_and_carry_their_figures(tmp_path):
    from PIL import Image
    from support import linear_task

    train, val = linear_task(80).split((0.7, 0.3))
    cfg = tr.TrainConfig(max_steps=5, batch_size=16, eval_every=5)
    tr.train_run(train, val, None, tmp_path / "run", pixels=2, config=cfg)
    figures = {"chosen_by": "the only run", "test_error_over_seeds": {"mean": 1.5}}
    files = keep_run_masks(tmp_path / "run", tmp_path / "kept", "linear", figures)
    assert files.png == tuple(tmp_path / "kept" / f"mask_0{k}.png" for k in range(2))
    side = json.loads(Path(files.json).read_text())
    prov = side["provenance"]
    assert prov["chosen_by"] == "the only run" and prov["test_error_over_seeds"]["mean"] == 1.5
    assert prov["run"] == str(tmp_path / "run") and prov["versions"]["torch"]
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert prov["detectors"] == run["model"]["detectors"] and prov["config"] == run["config"]
    assert side["task"] == "linear" and side["masks"] == 2
    m = run_masks(tmp_path / "run")[0]
    png = np.asarray(Image.open(tmp_path / "kept" / side["files"]["png"][1]), np.float64)
    np.testing.assert_allclose(png / 65535.0, m[1], atol=1 / 65535)


def test_baselines_are_told_by_their_model_kind_not_their_name():
    block = _block()
    block = _block({f"design-{i}": d for i, d in enumerate(block.designs.values())})
    assert reduction_factor(block, "design-0").baseline == "4x4"
    assert len(reference_verdicts(block.designs, "design-0")) == 3


def test_reference_verdicts_and_training_states():
    v = reference_verdicts(_block().designs, "mincam-4px")
    assert v[0].startswith("mincam-4px beats baseline-2x2")
    assert v[1].startswith("no verdict") and v[2].startswith("baseline-8x8 beats mincam-4px")

    def state(converged, stopped_early):
        return Convergence(converged=converged, improvement=0.1, steps=10,
                           stopped_early=stopped_early)  # fmt: skip

    done, early, spent = state(True, True), state(False, True), state(False, False)
    assert training_state([done, done]) == "converged"
    assert training_state([done, early]) == "early-stopped, not converged"
    assert training_state([early, spent]) == "budget-limited"


def test_cli_study_refuses_a_reference_outside_the_pixel_counts(tmp_path):
    args = ["study", "--family", "patches", "--pixels", "1,2", "--reference-pixels", "4",
            "--out", str(tmp_path / "s")]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2 and "--reference-pixels" in res.output
    assert "Traceback" not in res.output and not (tmp_path / "s").exists()


def _evaluation(labels, error, error_name, headline_labels, samples):
    headline = Headline(error=error, error_name=error_name, name=headline_labels[0],
                        labels=tuple(headline_labels), pooling="mean")  # fmt: skip
    return Evaluation(loss=0.0, samples=samples, labels=labels, headline=headline)


def _episode(count_rmse, door_acc, samples):
    labels = {
        "count": LabelMetrics(unit="people", median_filter_frames=1, rmse=count_rmse),
        "door": LabelMetrics(unit="", median_filter_frames=1, accuracy=door_acc,
                             accuracy_per_element=(door_acc,)),
    }  # fmt: skip
    return _evaluation(labels, count_rmse, "count RMSE", ["count"], samples)


def test_label_intervals_pool_each_label_over_frames():
    """RMSE pools as a frame-weighted root mean square, accuracy as a frame-weighted mean."""
    runs = [
        {"a": _episode(1.0, 0.8, 100), "b": _episode(2.0, 0.6, 300)},
        {"a": _episode(3.0, 1.0, 100), "b": _episode(1.0, 0.4, 300)},
    ]
    trivial = [{"a": _episode(2.0, 0.5, 100), "b": _episode(2.0, 0.5, 300)}]
    out = label_intervals({"mincam-2px": runs, "trivial": trivial}, seed=0)
    rms = [(0.25 * 1.0 + 0.75 * 4.0) ** 0.5, (0.25 * 9.0 + 0.75 * 1.0) ** 0.5]
    count = out["count"]
    assert count.metric == "rmse" and count.unit == "people"
    assert count.configs["mincam-2px"].mean == pytest.approx(sum(rms) / 2, rel=1e-12)
    assert count.configs["trivial"] == Interval(2.0, 2.0, 2.0)
    assert count.as_json()["configs"]["trivial"] == {"mean": 2.0, "ci95": [2.0, 2.0]}
    door = out["door"].configs["mincam-2px"]
    assert out["door"].metric == "accuracy" and out["door"].elements is None
    assert door.mean == pytest.approx((0.25 * 0.8 + 0.75 * 0.6 + 0.25 * 1.0 + 0.75 * 0.4) / 2)
    assert door.low <= door.mean <= door.high


def test_comparison_figure_has_a_panel_per_label_on_axes_from_zero(tmp_path, monkeypatch):
    import matplotlib.figure

    labels = label_intervals(
        {
            "mincam-4px": [{"a": _episode(1.97, 0.9, 10)}],
            "trivial": [{"a": _episode(2.03, 0.5, 10)}],
        },
        seed=0,
    )
    block = _block(labels=labels)
    seen = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: seen.append(fig))
    plot_comparison(block, _result(block), tmp_path / "c.png")
    (fig,) = seen
    axes = {ax.get_title(): ax for ax in fig.axes}
    assert axes["count"].get_ylim()[0] == 0.0 and axes["count"].get_ylim()[1] >= 2.03
    assert axes["door"].get_ylim() == (0.0, 1.0)
    assert [t.get_text() for t in axes["door"].get_xticklabels()] == ["mincam-4px", "trivial"]
    assert min(ax.get_ylim()[0] for ax in fig.axes) == 0.0  # the error-vs-pixels panel too


def _lighting_episode(per_light, samples):
    acc = sum(per_light) / len(per_light)
    lights = LabelMetrics(unit="", median_filter_frames=1, accuracy=acc,
                          accuracy_per_element=tuple(per_light))  # fmt: skip
    return _evaluation({"lights": lights}, 1.0 - acc, "lights error rate", ["lights"], samples)


def _lighting_result():
    runs = [{"a": _lighting_episode([1.0, 0.5], 100), "b": _lighting_episode([0.8, 0.7], 300)}]
    trivial = {"a": _lighting_episode([0.5, 0.5], 100), "b": _lighting_episode([0.5, 0.5], 300)}
    labels = label_intervals({"mincam-2px": runs, "trivial": [trivial]}, seed=0)
    block = _block(
        {"mincam-2px": _design(2, 0.2, 0.15, 0.25)},
        error_name="lights error rate",
        trivial=TrivialFigures(
            error=Interval(0.5, 0.5, 0.5), episode_errors=None, episodes=trivial
        ),  # fmt: skip
        labels=labels,
    )
    block = dataclasses.replace(block, verdict=None)
    return _result(block, element_names={"lights": ("lamp", "bank")})


def test_per_light_accuracy_is_pooled_per_element_and_tabled_with_light_names():
    res = _lighting_result()
    elements = res.labels["lights"].elements
    assert elements is not None
    assert elements["0"]["mincam-2px"].mean == pytest.approx(0.25 * 1.0 + 0.75 * 0.8)
    assert elements["1"]["mincam-2px"].mean == pytest.approx(0.25 * 0.5 + 0.75 * 0.7)
    table = label_table(res.headline, res.labels, res.element_names)
    assert "| design | lights accuracy | lights: lamp | lights: bank |" in table
    assert "| trivial | 0.500 [0.500, 0.500] | 0.500 [0.500, 0.500] |" in table


def test_study_summary_gives_accuracy_for_error_rates_and_rmse_in_the_headline_unit():
    res = _lighting_result()
    acc = study_summary(res.headline, res.labels)["mincam-2px"].as_json()
    assert acc["accuracy_mean"] == pytest.approx(0.8)
    assert acc["accuracy_ci95"] == pytest.approx([0.75, 0.85])
    both = ["speed_left_mph", "speed_right_mph"]
    speed = LabelMetrics(unit="mph", median_filter_frames=1, rmse=1.0)
    episode = _evaluation({n: speed for n in both}, 1.0, "mean speed RMSE", both, 10)
    trivial = TrivialFigures(error=Interval(3.0, 2.9, 3.1), episode_errors=None,
                             episodes={"t": episode})  # fmt: skip
    block = _block(error_name="mean speed RMSE", trivial=trivial)
    labels = {n: LabelFigures(metric="rmse", unit="mph", configs={}) for n in both}
    row = study_summary(block, labels)["mincam-4px"].as_json()
    assert row["rmse_mph_mean"] == row["rmse_mean"] == 1.0 and row["rmse_mph_ci95"] == [0.9, 1.1]


def test_lighting_figure_shows_accuracy_against_pixels_and_a_panel_per_light(tmp_path, monkeypatch):
    import matplotlib.figure

    seen = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: seen.append(fig))
    res = _lighting_result()
    plot_comparison(res.headline, res, tmp_path / "c.png")
    (fig,) = seen
    top = fig.axes[0]
    assert top.get_ylabel() == "test lights accuracy"
    assert top.lines[0].get_ydata()[0] == pytest.approx(0.5)  # the trivial line at 1 - 0.5
    titles = [ax.get_title() for ax in fig.axes[1:]]
    assert titles == ["lights", "lights: lamp", "lights: bank"]


def test_designs_read_back_from_a_results_config_with_their_kinds():
    from mincam_render.learn.train_config import MaskReference
    from mincam_render.studies.comparison.config import Design, designs_by_name

    designs = (Design(pixels=8, privacy_weight=1.0), Design(grid=(4, 4), head=HeadKind.TCN),
               Design(pixels=2, reference=MaskReference.PCA, tuned=True))  # fmt: skip
    # as a result's config holds them: json.dumps(asdict(...), default=str)
    records = json.loads(json.dumps([dataclasses.asdict(d) for d in designs], default=str))
    assert records[1]["head"] == "HeadKind.TCN"
    back = designs_by_name(records)
    assert list(back.values()) == list(designs)
    assert [d.is_mincam for d in back.values()] == [True, False, True]
    assert Design.from_json({"pixels": 1, "grid": None, "head": "tcn"}).head is HeadKind.TCN
    with pytest.raises(ValueError, match="HeadKind = 'lstm': allowed 'mlp', 'tcn'"):
        Design.from_json({"pixels": 1, "grid": None, "head": "lstm"})
