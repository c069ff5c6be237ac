"""The paper's protocol: a camera per task, beside one joint camera for every label."""

from __future__ import annotations

import pytest
from support import two_task_episode

from mincam_render.analysis.mask_structure import view_and_label_map
from mincam_render.core.labels import label_tasks
from mincam_render.core.seeds import stream_seed
from mincam_render.learn import train as tr
from mincam_render.scenes.registry import load_family
from mincam_render.studies.comparison.config import ComparisonConfig, Design, Protocol
from mincam_render.studies.comparison.runs import (
    Splits,
    comparison_tasks,
    task_splits,
    train_runs,
)
from mincam_render.studies.comparison.study import combined_cameras, task_comparison


def test_a_task_is_a_headline_group_or_a_label_of_its_own():
    workspace = label_tasks(load_family("workspace", seed=0, num_frames=30).labels)
    assert workspace == {
        "people_count": ("people_count",),
        "zones": ("zones",),
        "door_open": ("door_open",),
    }
    traffic = label_tasks(load_family("traffic", seed=0, num_frames=30).labels)
    assert traffic["mean speed"] == ("speed_left_mph", "speed_right_mph")
    assert list(traffic) == ["mean speed", "count_left", "count_right"]


def test_task_labels_follow_the_protocol():
    tasks = {"count": ("count",), "side": ("bright_left",)}
    designs = (Design(pixels=2), Design(grid=(2, 2)))
    assert ComparisonConfig(designs=designs).task_labels(tasks) == tasks
    only = ComparisonConfig(designs=designs, tasks=("count",))
    assert only.task_labels(tasks) == {"count": ("count",)}
    joint = ComparisonConfig(designs=designs, protocol="joint")
    assert joint.task_labels(tasks) == {"joint": ("count", "bright_left")}
    with pytest.raises(ValueError, match=r"tasks \['door'\]"):
        ComparisonConfig(designs=designs, tasks=("door",)).task_labels(tasks)
    with pytest.raises(ValueError, match="joint camera trains every label"):
        ComparisonConfig(designs=designs, protocol=Protocol.JOINT, tasks=("count",))
    with pytest.raises(ValueError, match="allowed"):
        ComparisonConfig(designs=designs, protocol="each")


def test_runs_of_a_task_are_named_and_seeded_by_it():
    tasks = {"count": ("count",), "side": ("bright_left",)}
    designs = (Design(pixels=2), Design(grid=(2, 2)))
    per_task = comparison_tasks(ComparisonConfig(designs=designs, seeds=2), tasks)
    names = [t.name for t in per_task]
    assert names[:4] == [
        "count/mincam-2px-seed0", "count/mincam-2px-seed1",
        "count/baseline-2x2-seed0", "count/baseline-2x2-seed1",
    ]  # fmt: skip
    assert per_task[0].config.seed == stream_seed(0, "train/count/mincam-2px", 0)
    assert per_task[4].labels == ("bright_left",)
    # a joint camera (and a camera for every label) keeps the names and seeds it always had
    joint = comparison_tasks(ComparisonConfig(designs=designs, protocol="joint"), tasks)
    assert [t.name for t in joint][:2] == ["mincam-2px-seed0", "mincam-2px-seed1"]
    assert joint[0].config.seed == stream_seed(0, "train/mincam-2px", 0)
    assert joint[0].labels == ()


@pytest.fixture(scope="module")
def two_task_splits():
    return Splits(
        train=two_task_episode(240, 0),
        val={"val-0": two_task_episode(80, 1), "val-1": two_task_episode(80, 2)},
        tests={"test-0": two_task_episode(80, 3), "test-1": two_task_episode(80, 4)},
    )


def test_task_splits_keep_only_the_tasks_labels(two_task_splits):
    count = task_splits(two_task_splits, ("count",))
    assert [s.name for s in count.train.label_specs] == ["count"]
    assert all(list(v.labels) == ["count"] for v in count.val.values())
    assert all(list(v.labels) == ["count"] for v in count.tests.values())
    assert task_splits(two_task_splits, ()).train is two_task_splits.train
    with pytest.raises(ValueError, match="need one or more of"):
        two_task_splits.train.with_labels(["zones"])


def test_per_task_cameras_train_and_compare_each_task_on_its_own(two_task_splits, tmp_path):
    designs = (Design(pixels=2), Design(grid=(2, 2)))
    recipe = tr.TrainConfig(max_steps=40, batch_size=16, eval_every=20)
    cfg = ComparisonConfig(designs=designs, seeds=2, train=recipe)
    runs = train_runs(cfg, two_task_splits, tmp_path, progress=False)
    assert list(runs) == ["count", "bright_left"]
    run = runs["count"]["mincam-2px"][0]
    assert run.run_dir == str(tmp_path / "runs" / "count" / "mincam-2px-seed0")
    assert list(run.episodes["test-0"].labels) == ["count"]
    assert run.validation_episodes is not None
    assert list(run.validation_episodes) == ["val-0", "val-1"]
    assert list(run.validation_episodes["val-1"].labels) == ["count"]
    side = runs["bright_left"]["baseline-2x2"][1]
    assert list(side.episodes["test-1"].labels) == ["bright_left"]
    blocks = {}
    for t, by_design in runs.items():
        task = task_splits(two_task_splits, (t,))
        blocks[t] = task_comparison(cfg, by_design, task, view_and_label_map(task.train))
    assert blocks["count"].error_name == "count RMSE"
    assert blocks["bright_left"].error_name == "bright_left error rate"
    assert set(blocks["count"].labels) == {"count"}
    combined = combined_cameras(cfg, blocks)
    assert combined["mincam-2px"].pixels == 4  # two tasks, two freeform pixels each
    assert combined["baseline-2x2"].pixels == 4  # one sensor read by two heads
    assert combined["mincam-2px"].tasks["count"] == blocks["count"].designs["mincam-2px"].error
    # a joint camera learns both labels at once
    joint = train_runs(
        ComparisonConfig(designs=designs, seeds=1, train=recipe, protocol="joint"),
        two_task_splits,
        tmp_path / "joint",
        progress=False,
    )
    assert list(joint) == ["joint"]
    labels = joint["joint"]["mincam-2px"][0].episodes["test-0"].labels
    assert list(labels) == ["count", "bright_left"]
