"""A comparison's typed result writes the files the dicts it replaced wrote, byte for byte.

``tests/data/comparison/`` was written by the comparison before it had typed
results (commit 177a9c7): a study of two tasks (the linear count and
``bright_left``, :func:`support.two_task_episode`), three designs and two
seeds, from fabricated runs (``runs.json``: each run's record as
``train_design_run`` returned it, its metrics those of noisy predictions), a
fixed mask structure, kept masks, a stray run left in the runs folder and a
run whose convergence is undecided. ``metrics.json`` is the study's
``metrics.json``, ``study.md`` its table.
"""

from __future__ import annotations

import dataclasses
import json

import pytest
from support import REPO, two_task_episode

from mincam_render.analysis.coverage import study_coverage
from mincam_render.analysis.mask_structure import MaskStructure, view_and_label_map
from mincam_render.core import strict_json
from mincam_render.core.labels import label_tasks
from mincam_render.learn import train as tr
from mincam_render.studies.comparison import study
from mincam_render.studies.comparison.config import ComparisonConfig, Design
from mincam_render.studies.comparison.records import (
    DesignRecord,
    EpisodeRecord,
    FolderOthers,
    KeptMasks,
    TrivialFigures,
)
from mincam_render.studies.comparison.report import study_table
from mincam_render.studies.comparison.result import ComparisonResult, TaskComparison
from mincam_render.studies.comparison.runs import ComparisonRun, Splits, task_splits

KEPT = REPO / "tests" / "data" / "comparison"


@pytest.fixture(scope="module")
def kept() -> str:
    return (KEPT / "metrics.json").read_text()


def test_metrics_json_reads_back_and_writes_the_same_bytes(kept):
    result = ComparisonResult.from_json(json.loads(kept))
    assert strict_json.dumps(result.as_json()) + "\n" == kept
    assert result.study is not None and result.study.reduction_factor.reference == "mincam-2px"
    assert list(result.tasks) == ["count", "bright_left"]
    assert result.not_of_this_comparison == FolderOthers({"runs": ("stray",)})


def test_every_block_reads_back_into_its_record(kept):
    data = json.loads(kept)
    block = data["tasks"]["count"]
    assert TaskComparison.from_json(block).as_json() == block
    for record in block["designs"].values():
        assert DesignRecord.from_json(record).as_json() == record
    assert TrivialFigures.from_json(block["trivial"]).as_json() == block["trivial"]
    for record in data["episodes"].values():
        assert EpisodeRecord.from_json(record).as_json() == record
    for record in data["masks"].values():
        masks = KeptMasks.from_json(record)
        assert masks.as_json() == record and KeptMasks.from_json(masks.as_json()) == masks
    mincam = DesignRecord.from_json(block["designs"]["mincam-2px"])
    assert isinstance(mincam.structure, MaskStructure) and mincam.state == "budget-limited"
    undecided = DesignRecord.from_json(block["designs"]["baseline-2x2"]).convergence[1]
    assert undecided.improvement is None and undecided.improvement_null_reason


def test_the_study_table_is_the_kept_markdown(kept):
    result = ComparisonResult.from_json(json.loads(kept))
    assert study_table(result) + "\n" == (KEPT / "study.md").read_text()


def test_run_records_read_back():
    runs = json.loads((KEPT / "runs.json").read_text())
    for by_design in runs.values():
        for records in by_design.values():
            for record in records:
                assert ComparisonRun.from_json(record).as_json() == record


def test_the_kept_runs_give_the_kept_figures(kept, monkeypatch, tmp_path):
    """The figures computed again from the kept runs, with today's code, are the kept ones."""
    structure = MaskStructure(tv_per_texel=(0.125, 0.25), at_limits=(0.5, 0.0),
                              label_weight=(1.5, 0.75), label_alignment=(0.25, -0.5),
                              labels=())  # fmt: skip
    monkeypatch.setattr(study, "run_structure",
                        lambda run_dir, view_map, labels: dataclasses.replace(
                            structure, labels=tuple(labels)))  # fmt: skip
    splits = Splits(
        train=two_task_episode(240, 0),
        val={"val-0": two_task_episode(80, 1), "val-1": two_task_episode(80, 2)},
        tests={"test-0": two_task_episode(80, 3), "test-1": two_task_episode(80, 4)},
    )
    designs = (Design(pixels=2), Design(grid=(2, 2)), Design(grid=(4, 4)))
    cfg = ComparisonConfig(designs=designs, seeds=2, train=tr.TrainConfig(max_steps=40))
    runs = {
        task: {n: [ComparisonRun.from_json(r) for r in rs] for n, rs in by_design.items()}
        for task, by_design in json.loads((KEPT / "runs.json").read_text()).items()
    }
    tasks = cfg.task_labels(label_tasks(splits.train.label_specs))
    blocks = {}
    for task, by_design in runs.items():
        data = task_splits(splits, tasks[task])
        blocks[task] = study.task_comparison(cfg, by_design, data, view_and_label_map(data.train))
    expected = ComparisonResult.from_json(json.loads(kept))
    (tmp_path / "runs" / "stray").mkdir(parents=True)
    result = ComparisonResult(
        family="synthetic",
        protocol=cfg.protocol,
        config=json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        episodes=expected.episodes,
        labels={label: lab for b in blocks.values() for label, lab in b.labels.items()},
        tasks=blocks,
        combined=study.combined_cameras(cfg, blocks),
        element_names={s.name: tuple(s.element_names) for s in splits.train.label_specs},
        coverage=study_coverage({"train": splits.train, **splits.val, **splits.tests}),
        figure=expected.figure,
        versions=expected.versions,
        masks=expected.masks,
        not_of_this_comparison=study.others_in_folders({"runs": (tmp_path / "runs", {"count"})}),
    )
    result = study.summarise_study(result, "mincam-2px")
    assert strict_json.dumps(result.as_json()) + "\n" == kept


@pytest.mark.parametrize(
    "kept_study", sorted(p.name for p in (REPO / "benchmarks" / "results").glob("study_*.json"))
)
def test_kept_studies_read_back_to_their_reference_verdicts(kept_study):
    """Every kept study's designs read back (older ones lack later fields) to its verdicts."""
    data = json.loads((REPO / "benchmarks" / "results" / kept_study).read_text())
    designs = {n: DesignRecord.from_json(d) for n, d in data["designs"].items()}
    reference, seed = data["reduction_factor"]["reference"], int(data["config"].get("seed", 0))
    assert study.reference_verdicts(designs, reference, seed) == data["reference_verdicts"]
