"""One restore path for every kind of run: round trips, the readers, unfinished runs."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from support import RUN_CONFIG, RUN_KINDS, linear_task, run_splits

from mincam_render.cli.train import write_masks
from mincam_render.learn import train as tr
from mincam_render.learn.prune import _pruned_camera
from mincam_render.learn.runs import _frozen_mask_camera, data_identity, describe_run
from mincam_render.studies.robustness.config import RobustnessConfig
from mincam_render.studies.robustness.study import robustness_curves

CFG = RUN_CONFIG
KINDS = RUN_KINDS
MINCAM_KINDS = [k for k in KINDS if not k.startswith("baseline")]
#: what pruning takes: single pixels (a signed pair is refused)
SINGLE_PIXEL_KINDS = [k for k in MINCAM_KINDS if k != "signed"]
_splits = run_splits


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_kind_of_run_restores_to_the_camera_it_tested(runs_of_each_kind, kind):
    run_dir, metrics, test = runs_of_each_kind[kind]
    run = tr.open_run(run_dir)
    assert run.finished and run.training == "finished" and run.step == CFG.max_steps
    model = tr.restore_model(run, test)
    assert not model.training and not hasattr(model, "adversary")
    assert tr.evaluate(model, test).error == pytest.approx(metrics.test.error)


@pytest.mark.parametrize("kind", SINGLE_PIXEL_KINDS)
def test_every_minimalist_run_exports_prunes_and_takes_perturbations(runs_of_each_kind, kind):
    run_dir, _, test = runs_of_each_kind[kind]
    run = tr.open_run(run_dir)
    m, camera = tr.masks_of(run)
    assert m.shape == (2, *camera.mask_resolution) and np.all((m > 0) & (m < 1))
    model = tr.restore_mincam(run, test, "prune")
    np.testing.assert_array_equal(tr.run_masks(run_dir)[0], m)
    records = tr.greedy_prune(model, test, test, None, replace(CFG, max_steps=4, eval_every=2))
    assert [r.pixels for r in records] == [2, 1]
    cfg = RobustnessConfig(levels=(0.0, 1.0), draws=2)
    curves = robustness_curves(model, {"test": test}, cfg, name=kind)
    assert curves.nominal_error > 0 and "mix" in curves.curves


@pytest.mark.parametrize("kind", ["head-24", "baseline-head-24"])
def test_a_head_of_another_width_is_recorded_and_restored_at_that_width(runs_of_each_kind, kind):
    run_dir, _, test = runs_of_each_kind[kind]
    run = tr.open_run(run_dir)
    assert run.record["model"]["hidden"] == 24 and run.record["config"]["head_hidden"] == 24
    assert tr.restore_model(run, test).head.out.in_features == 24
    # the paper's width is left out of run.json: runs from before the option resume
    paper = tr.open_run(runs_of_each_kind[{"head-24": "mincam"}.get(kind, "baseline")][0])
    assert "hidden" not in paper.record["model"] and "head_hidden" not in paper.record["config"]


def test_a_linear_bottleneck_is_recorded_and_restored(runs_of_each_kind):
    run_dir, metrics, test = runs_of_each_kind["baseline-linear-2"]
    run = tr.open_run(run_dir)
    assert run.record["model"]["bottleneck"] == 2 and run.record["config"]["head_bottleneck"] == 2
    model = tr.restore_model(run, test)
    assert model.head.bottleneck == 2 and model.head.first_layer.weight.shape == (2, 4)
    assert tr.evaluate(model, test).error == pytest.approx(metrics.test.error)
    # no bottleneck is left out of run.json: runs from before the option resume
    paper = tr.open_run(runs_of_each_kind["baseline"][0])
    assert "bottleneck" not in paper.record["model"]
    assert "head_bottleneck" not in paper.record["config"]


def test_a_signed_run_is_recorded_restored_exported_and_refused_by_pruning(
    runs_of_each_kind, tmp_path
):
    run_dir, metrics, test = runs_of_each_kind["signed"]
    run = tr.open_run(run_dir)
    assert run.record["model"]["signed"] is True and run.record["config"]["signed_pixels"]
    assert run.record["model"]["detectors"] == [0, 1]
    model = tr.restore_model(run, test)
    assert model.signed and model.num_pixels == 2 and model.head.in_features == 1
    assert tr.evaluate(model, test).error == pytest.approx(metrics.test.error)
    for kind, pairs in (("signed", [[0, 1]]), ("mincam", None)):
        folder = tmp_path / kind
        files = write_masks(tr.open_run(runs_of_each_kind[kind][0]), folder, "t", pdf=False)
        sidecar = json.loads((folder / files.json).read_text())
        assert sidecar["signed_pairs"] == pairs and sidecar["masks"] == 2
        assert ("signed pairs" in (folder / files.svg).read_text()) == (pairs is not None)
    with pytest.raises(ValueError, match="signed pairs"):
        tr.greedy_prune(tr.restore_mincam(run, test, "prune"), test, test, None, CFG)
    # the masks frozen under a fresh head stay a signed pair
    frozen = _frozen_mask_camera(test, run_dir, True, CFG)
    assert frozen.signed and frozen.head.in_features == 1
    # unsigned runs leave both keys out of run.json: runs from before the option resume
    paper = tr.open_run(runs_of_each_kind["mincam"][0])
    assert "signed" not in paper.record["model"]
    assert "signed_pixels" not in paper.record["config"]


def test_pruned_and_frozen_mask_cameras_keep_the_head_they_are_given(runs_of_each_kind):
    run_dir, _, test = runs_of_each_kind["head-24"]
    pruned = _pruned_camera(tr.restore_mincam(tr.open_run(run_dir), test, "prune"), test, [0], CFG)
    assert pruned.head.out.in_features == 24 and pruned.num_pixels == 1
    wide_tcn = replace(CFG, head=tr.HeadKind.TCN, head_hidden=40)
    frozen = _frozen_mask_camera(test, runs_of_each_kind["mincam"][0], True, wide_tcn)
    assert isinstance(frozen.head, tr.TemporalConvHead) and frozen.head.out.in_features == 40
    assert not frozen.logits.requires_grad


def test_a_baseline_run_is_refused_in_one_line_by_what_needs_masks(runs_of_each_kind):
    run_dir, _, test = runs_of_each_kind["baseline"]
    run = tr.open_run(run_dir)
    for use, call in {
        "prune": lambda: tr.restore_mincam(run, test, "prune"),
        "exporting masks": lambda: tr.masks_of(run),
    }.items():
        with pytest.raises(ValueError, match=f"is a baseline run: {use} takes minimalist") as err:
            call()
        assert "\n" not in str(err.value)


def test_restore_refuses_data_of_another_history_or_resolution(runs_of_each_kind):
    run_dir, _, test = runs_of_each_kind["temporal"]
    with pytest.raises(ValueError, match="windows of 12 frames; the data gives 1"):
        tr.restore_model(tr.open_run(run_dir), linear_task(40, res=4))
    with pytest.raises(ValueError, match="masks of"):
        tr.restore_model(tr.open_run(runs_of_each_kind["mincam"][0]), linear_task(40, res=4))


def test_a_checkpoint_that_does_not_fit_run_json_is_one_line(runs_of_each_kind, tmp_path):
    run_dir, _, test = runs_of_each_kind["mincam"]
    run = tr.open_run(run_dir)
    record = json.loads(json.dumps(run.record))
    record["model"]["head"] = "tcn"  # run.json edited: the weights are an MLP's
    edited = replace(run, record=record)
    with pytest.raises(ValueError, match="checkpoint.pt does not fit the camera run.json"):
        tr.restore_model(edited, test)


def _killed_run(run_dir, steps: int):
    """What a training killed after ``steps`` leaves: run.json and a checkpoint, no metrics."""
    train, val, test = _splits(False)
    model = tr.build_mincam(train, 2)
    tr.train_model(model, train, val, CFG, out_dir=run_dir, stop_after_steps=steps)
    (run_dir / "run.json").write_text(json.dumps(describe_run(model, train, val, test, CFG, False)))
    return train, val, test


def test_an_unfinished_run_is_refused_unless_allowed_and_then_says_how_far_it_got(
    variant, tmp_path
):
    train, val, test = _killed_run(tmp_path, 10)
    assert not tr.run_finished(tmp_path)
    with pytest.raises(tr.UnfinishedRunError, match="step 10 of 20.*--allow-unfinished"):
        tr.open_run(tmp_path)
    run = tr.open_run(tmp_path, allow_unfinished=True)
    assert not run.finished and run.training == "unfinished: step 10 of 20"
    tr.restore_model(run, test)
    tr.train_run(train, val, test, tmp_path, pixels=2, config=CFG)  # the same command again
    assert tr.open_run(tmp_path).finished


def test_a_training_started_afresh_leaves_nothing_of_the_one_before(variant, tmp_path):
    train, val, test = _splits(False)
    tr.train_run(train, val, test, tmp_path, pixels=2, config=CFG)
    old_events = sorted(tmp_path.glob("events.out.tfevents.*"))
    tr.train_run(train, val, test, tmp_path, pixels=1, config=CFG, resume=False)
    events = sorted(tmp_path.glob("events.out.tfevents.*"))
    assert len(old_events) == len(events) == 1 and events != old_events
    history = (tmp_path / "history.jsonl").read_text().splitlines()
    assert [json.loads(line)["step"] for line in history] == [10, 20]
    assert tr.open_run(tmp_path).record["model"]["pixels"] == 1


def test_a_run_is_unfinished_while_it_trains_again_from_the_start(variant, tmp_path):
    train, val, test = _splits(False)
    tr.train_run(train, val, test, tmp_path, pixels=2, config=CFG)
    (tmp_path / "checkpoint.pt").unlink()  # a user deletes the checkpoint to start again
    finished_while_training = []
    tr.train_run(
        train, val, test, tmp_path, pixels=2, config=CFG,
        on_progress=lambda steps: finished_while_training.append(tr.run_finished(tmp_path)),
    )  # fmt: skip
    assert finished_while_training == [False, False] and tr.run_finished(tmp_path)


def test_data_are_identified_by_their_manifest_not_by_their_path():
    a = {"train": {"dataset": "runs/ds", "manifest_sha256": "aa", "split": "train"}}
    moved = {"train": {"dataset": "/elsewhere/ds", "manifest_sha256": "aa", "split": "train"}}
    other = {"train": {"dataset": "runs/ds", "manifest_sha256": "bb", "split": "train"}}
    assert data_identity(a) == data_identity(moved) != data_identity(other)
    episodes = {"train": {"episodes": [a["train"], other["train"]]}}
    assert data_identity(episodes) == {"train": {"episodes": [
        {"manifest_sha256": "aa", "split": "train"}, {"manifest_sha256": "bb", "split": "train"}
    ]}}  # fmt: skip
    # runs written before sources carried a hash compare by path, the hash left out
    legacy = {"train": {"dataset": "runs/ds", "split": "train"}}
    assert data_identity(a, by_content=False) == legacy
    in_memory = {"train": {"family": "patches", "seed": 0}}
    assert data_identity(in_memory) == in_memory
