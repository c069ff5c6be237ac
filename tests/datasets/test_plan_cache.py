"""Fidelity plans: measured once per description on the planning episode, kept, verified."""

from __future__ import annotations

import dataclasses
import json
import logging

import pytest

from mincam_render.data import dataset as ds
from mincam_render.data import plan_cache
from mincam_render.data.render_job import (
    RenderRequest,
    _describe_family,
    package_versions,
    plan_render,
    render_dataset,
)
from mincam_render.render.backend import VARIANTS, Backend
from mincam_render.scenes.registry import load_family

#: Planned automatically (no spp, depth or dtype given): the plans are what is cached,
#: so these tests render their own datasets, not conftest's ``tiny_patches``.
AUTO = RenderRequest(
    family="patches",
    num_frames=16,
    seed=3,
    overrides={"camera": {"detectors": 2, "mask_resolution": 8}},
    shard_frames=8,
)


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(plan_cache.CACHE_ENV, str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_episodes_of_one_description_share_the_plan_a_fresh_measurement_gives(
    tmp_path, own_cache, variant
):
    first = render_dataset(AUTO, tmp_path / "a", workers=0)
    assert len(list(own_cache.glob("*.json"))) == 1
    other_seed = dataclasses.replace(AUTO, seed=11, shard_frames=4)
    second = render_dataset(other_seed, tmp_path / "b", workers=0)
    a, b = ds.read_manifest(first.path), ds.read_manifest(second.path)
    assert a["fidelity"] == b["fidelity"] and a["job"]["render"] == b["job"]["render"]
    assert a["fidelity"]["planning_episode"] == {"seed": plan_cache.PLAN_SEED, "frames": 16}
    # the kept plan is exactly the plan measured afresh for the other seed
    fresh = plan_render(other_seed, use_cache=False)
    assert fresh["fidelity"] == b["fidelity"]
    assert fresh["job"]["render"] == b["job"]["render"]
    assert len(list(own_cache.glob("*.json"))) == 1  # nothing more was kept


def test_other_frame_counts_and_targets_are_planned_apart(variant):
    _, description, _ = _describe_family(AUTO)
    family_name = "patches"
    renderer = {"variant": variant, "mitsuba": "3.9.1", "drjit": "1.5.0"}

    planning = {"error_scale": "frame", "target_error": 0.01, "difference_seeds": "window"}

    def key(request):
        return plan_cache.plan_key(
            plan_cache.plan_fields(request.identity(description), family_name, renderer, planning)
        )

    assert key(AUTO) == key(dataclasses.replace(AUTO, seed=9, splits=(0.5, 0.25, 0.25)))
    assert key(AUTO) != key(dataclasses.replace(AUTO, num_frames=17))
    assert key(AUTO) != key(dataclasses.replace(AUTO, target_error=0.02))
    assert key(AUTO) != key(dataclasses.replace(AUTO, spp=4))


def test_the_resolved_targets_are_part_of_the_plan_key():
    # a family's task-checked target can change without its description
    # changing: the plan key holds what the planner resolved, not the request's None
    renderer = {"variant": "llvm_ad_mono", "mitsuba": "3.9.1", "drjit": "1.5.0"}
    identity = {"family": "workspace", "num_frames": 100, "seed": 4}
    planning = {"error_scale": "signal", "target_error": 0.5, "difference_seeds": "window"}
    keys = {
        plan_cache.plan_key(plan_cache.plan_fields(identity, "workspace", renderer, changed))
        for changed in (
            planning,
            planning | {"target_error": 1.0},
            planning | {"error_scale": "frame"},
            planning | {"difference_seeds": "frame"},
        )
    }
    assert len(keys) == 4
    # the planning of format-4 plans adds no field: their keys stay valid
    total = {"error_scale": "frame", "target_error": 0.01, "difference_seeds": "window"}
    assert "planning" not in plan_cache.plan_fields(identity, "workspace", renderer, total)
    assert load_family("lighting", seed=0, num_frames=2).total_error_scale == "mean"
    assert load_family("workspace", seed=0, num_frames=2).total_error_scale == "frame"


def test_a_plan_key_says_which_variant_it_holds():
    identity = {"family": "workspace", "num_frames": 100, "seed": 4}
    planning = {"error_scale": "frame", "target_error": 0.01, "difference_seeds": "window"}

    def fields(variant):
        renderer = {"variant": variant, "mitsuba": "3.9.1", "drjit": "1.5.0"}
        return plan_cache.plan_fields(identity, "workspace", renderer, planning)

    cpu, gpu = fields("llvm_ad_mono"), fields("cuda_ad_mono")
    assert plan_cache.plan_variant(cpu) == "llvm_ad_mono"
    assert plan_cache.plan_variant(gpu) == "cuda_ad_mono"
    assert plan_cache.plan_key(cpu) != plan_cache.plan_key(gpu)


def test_a_plan_of_another_variant_is_measured_again_and_said(own_cache, caplog):
    identity = {"family": "workspace", "num_frames": 100, "seed": 4}
    planning = {"error_scale": "frame", "target_error": 0.01, "difference_seeds": "window"}
    renderer = {"variant": "llvm_ad_mono", "mitsuba": "3.9.1", "drjit": "1.5.0"}
    cpu = plan_cache.plan_fields(identity, "workspace", renderer, planning)
    gpu = {**cpu, "renderer": {**renderer, "variant": "cuda_ad_mono"}}
    kept = plan_cache.store_plan(cpu, {"settings": {}, "decisions": {}}, 1.0)
    with caplog.at_level(logging.INFO, logger="mincam_render.data.plan_cache"):
        assert plan_cache.find_plan(gpu) is None
        assert plan_cache.find_plan(cpu) is not None
    assert plan_cache.other_variant_plans(gpu) == [("llvm_ad_mono", kept)]
    assert "plans are measured per variant: planning again for cuda_ad_mono" in caplog.text


def test_a_plan_on_frame_steps_is_kept_apart_from_one_on_frames():
    # plans measured against the frames' signal keep their keys; the same
    # targets measured against frame steps are another plan (their signal
    # figures and a signal-scale spp mean something else)
    identity = {"family": "traffic", "num_frames": 1800, "seed": 0}
    renderer = {"variant": "llvm_ad_mono", "mitsuba": "3.9.1", "drjit": "1.5.0"}
    planning = {"error_scale": "frame", "target_error": 0.01, "difference_seeds": "window"}
    frames = plan_cache.plan_fields(identity, "traffic", renderer, planning)
    steps = plan_cache.plan_fields(
        identity, "traffic", renderer, {**planning, "label_signal": "frame-steps"}
    )
    assert "planning" not in frames  # the keys of plans kept before the source was a field
    assert steps["planning"]["label_signal"] == "frame-steps"
    assert plan_cache.plan_key(frames) != plan_cache.plan_key(steps)


@pytest.mark.parametrize(("family", "source"), [("traffic", "frame-steps"), ("workspace", None)])
def test_a_plans_key_names_its_label_signal_where_it_is_newer_than_the_keys(family, source):
    from mincam_render.data.render_job.planning import resolved_planning

    planning = resolved_planning(family, RenderRequest(family=family, num_frames=100))
    assert planning.get("label_signal") == source


def test_requests_without_the_later_fields_keep_their_format_4_identity():
    # datasets rendered before error_scale, signal_target_error, difference_seeds
    # and samples_factor existed resume: those fields stay out while None
    identity = AUTO.identity({})
    later = {"error_scale", "signal_target_error", "difference_seeds", "samples_factor"}
    assert not later & set(identity)
    given = dataclasses.replace(AUTO, error_scale="signal", difference_seeds="frame").identity({})
    assert given["error_scale"] == "signal" and given["difference_seeds"] == "frame"


def test_a_damaged_kept_plan_is_ignored_and_measured_again(tmp_path, own_cache, variant, caplog):
    render_dataset(AUTO, tmp_path / "a", workers=0)
    (path,) = own_cache.glob("*.json")
    good = json.loads(path.read_text())
    path.write_text(path.read_text()[:-40])  # truncated
    with caplog.at_level(logging.WARNING):
        again = render_dataset(AUTO, tmp_path / "b", workers=0)
    assert "ignoring the plan" in caplog.text and path.name in caplog.text
    assert ds.read_manifest(again.path)["fidelity"] == good["decisions"]
    assert json.loads(path.read_text())["decisions"] == good["decisions"]  # written anew


def test_a_plan_whose_fields_were_edited_is_refused(tmp_path, own_cache, variant, caplog):
    render_dataset(AUTO, tmp_path / "a", workers=0)
    (path,) = own_cache.glob("*.json")
    body = json.loads(path.read_text())
    body["fields"]["target_error"] = 0.5
    path.write_text(json.dumps(body))
    with caplog.at_level(logging.WARNING):
        render_dataset(AUTO, tmp_path / "b", workers=0)
    assert "do not hash to its name" in caplog.text


@pytest.mark.parametrize(
    "path", sorted(plan_cache.shipped_dir().glob("*.json")), ids=lambda p: p.stem[:12]
)
def test_shipped_plans_match_the_shipped_descriptions_and_this_renderer(path, variant):
    body = json.loads(path.read_text())
    fields = body["fields"]
    assert plan_cache.plan_key(fields) == path.stem
    assert fields["planner_version"] == plan_cache.PLANNER_VERSION, "re-ship: scripts/ship_plans.py"
    family = load_family(fields["family_name"], seed=0, num_frames=fields["num_frames"])
    # a plain render of the shipped description, or an episode of the main job's default
    from mincam_render.studies.comparison.study import ComparisonConfig, episode_requests

    requests = [RenderRequest(family=fields["family_name"], num_frames=fields["num_frames"])]
    requests += [
        r
        for r in episode_requests(ComparisonConfig()).values()
        if (r.family, r.num_frames) == (fields["family_name"], fields["num_frames"])
    ]
    descriptions = [_describe_family(r)[1] for r in requests]
    assert fields["description"] in descriptions, "scenes/*.toml changed: re-ship the plan"
    assert family.name == fields["family_name"]
    versions = package_versions()
    # shipped for the backend every host has; a GPU host measures its own (plan_cache)
    assert fields["renderer"] == {
        "variant": VARIANTS[Backend.LLVM],
        "mitsuba": versions["mitsuba"],
        "drjit": versions["drjit"],
    }


def test_a_shipped_plan_is_used_before_the_cache(tmp_path, own_cache, monkeypatch, variant):
    monkeypatch.setattr(plan_cache, "shipped_dir", lambda: tmp_path / "shipped")
    shipped = plan_render(AUTO, ship=True)
    assert len(list((tmp_path / "shipped").glob("*.json"))) == 1
    assert not own_cache.exists()  # shipping measures afresh and keeps nothing else
    summary = render_dataset(dataclasses.replace(AUTO, seed=8), tmp_path / "ds", workers=0)
    assert ds.read_manifest(summary.path)["fidelity"] == shipped["fidelity"]
    assert not own_cache.exists()  # found among the shipped plans
