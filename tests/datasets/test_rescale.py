"""An episode's request at other samples, and the check that two renders share a scene."""

from __future__ import annotations

import dataclasses
import json
import shutil

import pytest
from support import TINY_DIFFERENTIAL, TINY_PATCHES

from mincam_render.data.dataset import read_manifest, write_manifest
from mincam_render.data.render_job import render_dataset
from mincam_render.data.render_job.rescale import (
    FULL_PATH_DEPTH,
    rescaled_request,
    resolved_request,
    same_scene,
    scaled_samples,
)
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.render.fidelity import Fidelity


@pytest.mark.parametrize(
    ("samples", "factor", "expected"), [(24, 4, 96), (195, 0.25, 49), (20, 0.0625, 1)]
)
def test_scaled_samples_round_and_stay_positive(samples, factor, expected):
    assert scaled_samples(samples, factor) == expected


def test_a_differential_plan_scales_frames_and_backgrounds(differential_dataset):
    plan = read_manifest(differential_dataset)["job"]["render"]
    out = rescaled_request(TINY_DIFFERENTIAL, differential_dataset, 4)
    assert out.fidelity is Fidelity.FULL
    assert (out.spp, out.background_spp) == (4 * plan["spp"], 4 * plan["background"]["spp"])
    assert out.max_depth == FULL_PATH_DEPTH and out.differential
    assert out.difference_seeds == TINY_DIFFERENTIAL.difference_seeds  # per window
    framed = rescaled_request(
        TINY_DIFFERENTIAL, differential_dataset, 0.5, max_depth=None,
        difference_seeds=DifferenceSeeds.FRAME,
    )  # fmt: skip
    assert framed.max_depth == plan["max_depth"]
    assert framed.difference_seeds is DifferenceSeeds.FRAME
    scene = ("family", "num_frames", "seed", "overrides", "splits", "shard_frames")
    assert all(getattr(out, f) == getattr(TINY_DIFFERENTIAL, f) for f in scene)


def test_a_direct_plan_keeps_its_request_background_fields(tiny_patches):
    out = rescaled_request(TINY_PATCHES, tiny_patches, 2, difference_seeds=DifferenceSeeds.FRAME)
    assert out.spp == 2 * TINY_PATCHES.spp and not out.differential
    assert out.background_spp == TINY_PATCHES.background_spp
    assert out.difference_seeds == TINY_PATCHES.difference_seeds  # no differences to seed


def test_a_render_at_other_samples_is_the_same_scene(differential_dataset, tmp_path):
    request = rescaled_request(TINY_DIFFERENTIAL, differential_dataset, 2, max_depth=3)
    render_dataset(request, tmp_path / "2x", workers=0)
    same_scene(differential_dataset, tmp_path / "2x")  # no error
    other = dataclasses.replace(request, seed=request.seed + 1)
    render_dataset(other, tmp_path / "other", workers=0)
    with pytest.raises(ValueError, match=r"not a render of the scene.*\['seed'\]"):
        same_scene(differential_dataset, tmp_path / "other")


def test_another_family_missing_or_unfinished_renders_are_refused(
    differential_dataset, tiny_patches, tmp_path
):
    with pytest.raises(ValueError, match="description"):
        same_scene(differential_dataset, tiny_patches)
    with pytest.raises(ValueError, match="no dataset there"):
        same_scene(differential_dataset, tmp_path / "nothing")
    cut = shutil.copytree(differential_dataset, tmp_path / "cut")
    write_manifest(cut, {**read_manifest(cut), "complete": False})
    with pytest.raises(ValueError, match="unfinished"):
        same_scene(differential_dataset, cut)


def test_a_samples_factor_renders_the_checks_level_of_that_factor(differential_dataset, tmp_path):
    asked = dataclasses.replace(TINY_DIFFERENTIAL, samples_factor=2)  # at its own depth, 3
    resolved = resolved_request(asked)
    depth = TINY_DIFFERENTIAL.max_depth
    assert resolved == rescaled_request(TINY_DIFFERENTIAL, differential_dataset, 2, max_depth=depth)
    assert resolved_request(TINY_DIFFERENTIAL) is TINY_DIFFERENTIAL  # no factor: as asked
    render_dataset(asked, tmp_path / "2x", workers=0)
    job = read_manifest(tmp_path / "2x")["job"]["render"]
    plan = read_manifest(differential_dataset)["job"]["render"]
    assert (job["spp"], job["background"]["spp"]) == (
        2 * plan["spp"],
        2 * plan["background"]["spp"],
    )
    assert job["max_depth"] == depth
    # the check's own request of that level finds the dataset finished: the same identity
    again = render_dataset(resolved, tmp_path / "2x", workers=0)
    assert again.shards_rendered == [] and again.shards_kept == [0, 1, 2]
    # the render log says how each run was asked (the manifest holds the settings)
    log = (tmp_path / "2x" / "render_log.jsonl").read_text().splitlines()
    starts = [e for e in map(json.loads, log) if e["event"] == "start"]
    assert [e["samples_factor"] for e in starts] == [2.0, None]
    framed = resolved_request(
        dataclasses.replace(asked, difference_seeds=DifferenceSeeds.FRAME)
    )  # a per-frame seed asked for is kept
    assert framed.difference_seeds is DifferenceSeeds.FRAME
    # the 2x dataset again at 2x (a study's retest): its plan's samples doubled, once
    twice = rescaled_request(asked, tmp_path / "2x", 2, max_depth=depth)
    assert (twice.spp, twice.samples_factor) == (4 * plan["spp"], None)


@pytest.mark.parametrize("factor", [0, -2, float("nan"), 1e5])
def test_a_samples_factor_must_be_positive_and_finite(factor):
    with pytest.raises(ValueError, match="samples_factor"):
        dataclasses.replace(TINY_DIFFERENTIAL, samples_factor=factor)


def test_a_factor_renders_at_full_depth_unless_the_request_names_one(monkeypatch):
    from mincam_render.data.render_job import planning

    plan = {"spp": 3, "max_depth": 5, "shared_render": False, "dtype": "float16",
            "background": {"spp": 10, "shared_difference": True}}  # fmt: skip
    monkeypatch.setattr(planning, "plan_render", lambda r, **kw: {"job": {"render": plan}})
    unnamed = dataclasses.replace(TINY_DIFFERENTIAL, max_depth=None, samples_factor=4)
    out = resolved_request(unnamed)
    assert (out.spp, out.background_spp, out.max_depth) == (12, 40, FULL_PATH_DEPTH)
    assert out.samples_factor is None and out.fidelity is Fidelity.FULL
    assert resolved_request(dataclasses.replace(unnamed, max_depth=7)).max_depth == 7


def test_planning_refuses_an_unresolved_samples_factor():
    from mincam_render.data.render_job.planning import plan_render

    with pytest.raises(ValueError, match="resolved_request"):
        plan_render(dataclasses.replace(TINY_DIFFERENTIAL, samples_factor=2))
