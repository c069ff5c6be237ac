"""The design-protocol study end to end on tiny patches episodes, and its configuration."""

from __future__ import annotations

import json
import re

import pytest

from mincam_render.data.dataset import read_manifest
from mincam_render.learn.train_config import TrainConfig
from mincam_render.studies.comparison.config import ComparisonConfig, Design
from mincam_render.studies.comparison.figures import DesignFigure
from mincam_render.studies.design_protocol import (
    DesignProtocolConfig,
    Floor,
    FloorVerdict,
    RecipeVariant,
    recipes_named,
    run,
    write_report,
)
from mincam_render.studies.design_protocol.study import (
    LadderPoint,
    RecipeRow,
    chosen_recipes,
    floor_checks,
    retest_requests,
)

QUICK = {"spp": 2, "max_depth": 0, "shared_render": False, "differential": False}
CFG = DesignProtocolConfig(
    episodes=ComparisonConfig(
        family="patches",
        train_frames=40,
        val_episodes=2,
        val_frames=30,
        test_episodes=2,
        test_frames=30,
        seeds=2,
        train=TrainConfig(max_steps=20, eval_every=10, gain_range=(1.0, 1.0)),
        fidelity=QUICK,
    ),
    task="count",
    ladder=(1, 2),
    ladder_designs=(Design(pixels=2), Design(grid=(2, 2))),
    recipe_episodes=2,
    recipes=(
        RecipeVariant(name="base"),
        RecipeVariant(name="tv", changes={"mask_tv_weight": 0.1}, minimalist_only=True),
        RecipeVariant(
            name="linear", changes={"head_bottleneck": 1}, baselines_only=True, diagnostic=True
        ),
        RecipeVariant(
            name="signed", changes={"signed_pixels": True}, minimalist_only=True, diagnostic=True
        ),
    ),
    reference_episodes=1,
    reference_pixels=(2,),
    protocol_episodes=1,
    restarts=2,
    floors=(Floor(design="mincam-2px", baseline="baseline-2x2", margin=0.05),),
    floor_test_factors=(0.5, 2),
)


@pytest.fixture(scope="module")
def study(tmp_path_factory, variant):
    out = tmp_path_factory.mktemp("protocol")
    sections = ("protocol", "recipes", "ladder", "references", "restarts")
    return out, run(CFG, out, sections=sections)


def test_every_section_reports_the_designs_it_ran(study):
    out, result = study
    assert result.error_name == "count RMSE"
    assert [p.episodes for p in result.ladder] == [1, 2]
    assert [p.frames for p in result.ladder] == [40, 80]
    assert all(p.render_s > 0 for p in result.ladder)
    assert [(d.design, d.episodes) for d in result.doublings] == [
        ("mincam-2px", (1, 2)),
        ("baseline-2x2", (1, 2)),
    ]
    assert [r.variant for r in result.recipes] == ["base", "tv", "linear", "signed"]
    assert set(result.recipes[1].designs) == {"mincam-2px"}  # a mask prior: masks only
    assert set(result.recipes[2].designs) == {"baseline-2x2"}  # a diagnostic of box cameras
    assert set(result.recipes[3].designs) == {"mincam-2px"}  # 2 signed pixels: 4 photodiodes
    signed = json.loads(next((out / "recipes" / "signed").rglob("run.json")).read_text())
    assert signed["model"]["signed"] and signed["model"]["detectors"] == [0, 1, 2, 3]
    assert result.chosen_recipe["mincam-2px"] in ("base", "tv")  # never a diagnostic
    assert result.recipes[0].versus_base["mincam-2px"].mean == 0.0
    assert set(result.chosen_recipe) == {"mincam-2px", "baseline-2x2"}
    assert result.chosen_recipe["baseline-2x2"] == "base"
    (ref,) = result.references
    assert sorted(ref.designs) == sorted(
        ["mincam-2px"]
        + [f"mincam-2px-{r}{t}" for r in ("pca", "pls", "distilled") for t in ("", "-tuned")]
    )
    assert "mincam-2px" not in ref.versus_end_to_end
    # the base recipe on 2 episodes is the ladder's point: its runs count once
    assert result.selection is not None and result.selection.runs == 2 * (2 + 2 + 1 + 1 + 1)
    labels = [r.label for r in result.protocol]
    assert labels == ["count"]
    (restarts,) = result.restarts  # the minimalist design, 2 seeds x 2 restarts
    assert restarts.design == "mincam-2px" and restarts.restarts == 2
    picks = restarts.chosen.runs
    assert picks[0] in (0, 1) and picks[1] in (2, 3)
    assert len(restarts.plain.per_seed) == 2 and restarts.train_s_per_camera[1] > 0
    # the plain seeds are the ladder point's runs, copied, not trained again
    assert restarts.plain.per_seed == result.ladder[-1].designs["mincam-2px"].per_seed
    for i in range(2):
        ladder, again = (out / f / "runs" / f"mincam-2px-seed{i}" / "metrics.json"
                         for f in ("ladder/episodes-2", "restarts/episodes-2"))  # fmt: skip
        assert again.read_bytes() == ladder.read_bytes()  # the same training wall time too


def test_the_figures_are_the_comparisons_on_disk(study):
    out, result = study
    metrics = json.loads((out / "ladder" / "episodes-2" / "metrics.json").read_text())
    design = metrics["designs"]["mincam-2px"]
    fig = result.ladder[1].designs["mincam-2px"]
    assert fig.error == design["error"]["mean"] and list(fig.ci95) == design["error"]["ci95"]
    val = design["validation"]
    assert fig.val_error == val["error"]["mean"] and list(fig.val_ci95) == val["error"]["ci95"]
    assert fig.val().error.shape == (2, 2)  # seeds x validation episodes
    assert len(fig.val_per_seed) == 2
    # every section shares the validation and test episodes: the trivial predictor's
    # test error depends on the training set only through its mean label
    assert {e for e in metrics["episodes"] if not e.startswith("train")} == {
        "val-0", "val-1", "test-0", "test-1"
    }  # fmt: skip


def test_the_base_recipe_on_a_ladder_point_is_that_point(study):
    out, result = study
    assert result.recipes[0].designs == result.ladder[1].designs
    assert not (out / "recipes" / "base").exists()
    assert (out / "recipes" / "tv" / "metrics.json").is_file()  # a variant: its own runs


def test_floors_are_paired_on_the_largest_training_set(study):
    _, result = study
    check, *retested = result.floors
    assert [c.test_factor for c in (check, *retested)] == [1.0, 0.5, 2]
    assert list(result.retested) == ["0.5x", "2x"]
    last = result.ladder[-1]
    assert check.episodes == 2 and check.floor.margin == 0.05
    a, b = last.designs["mincam-2px"].errors(), last.designs["baseline-2x2"].errors()
    assert check.paired.mean == pytest.approx(a.point() - b.point(), abs=1e-12)  # the last point's
    low, high = check.paired.ci95
    expected = (
        FloorVerdict.MET if high < 0.05 else FloorVerdict.MISSED if low >= 0.05
        else FloorVerdict.UNDECIDED
    )  # fmt: skip
    assert check.verdict is expected


def test_the_references_train_with_the_reference_recipe_in_their_own_folder(study, tmp_path):
    import dataclasses

    from mincam_render.learn.train_config import MaskReference
    from mincam_render.studies.design_protocol.report import markdown

    out, base = study
    block = RecipeVariant(name="block-2", changes={"mask_block": 2}, minimalist_only=True)
    cfg = dataclasses.replace(
        CFG, references=(MaskReference.PCA,), reference_recipe=block, floor_test_factors=()
    )
    result = run(cfg, tmp_path, episodes_dir=out / "episodes", sections=("references",))
    (ref,) = result.references
    assert ref.recipe == "block-2" and base.references[0].recipe == "base"
    assert sorted(ref.designs) == ["mincam-2px", "mincam-2px-pca", "mincam-2px-pca-tuned"]
    runs = tmp_path / "references" / "2px-block-2" / "runs"
    for name in ("mincam-2px-seed0", "mincam-2px-pca-tuned-seed1"):
        assert json.loads((runs / name / "run.json").read_text())["model"]["mask_block"] == 2
    assert not (tmp_path / "references" / "2px").exists()
    assert "### 2 px (block-2 recipe)" in markdown(result)


def test_retest_factors_count_from_the_plan_when_the_episodes_render_at_a_multiple(tmp_path):
    import dataclasses

    at_2x = dataclasses.replace(CFG.episodes, fidelity={**QUICK, "samples_factor": 2})
    cfg = dataclasses.replace(CFG, episodes=at_2x, floor_test_factors=(8,))
    assert cfg.episodes_factor == 2.0 and CFG.episodes_factor == 1.0
    plain, scaled = retest_requests(CFG, tmp_path, 8), retest_requests(cfg, tmp_path, 8)
    assert list(scaled) == ["test-0", "test-1"] == list(plain)
    for name, request in scaled.items():  # 8 x the plan's 2 spp, whatever the episodes' own
        assert request.spp == plain[name].spp == 16
        assert request.max_depth == 16 and request.samples_factor is None
        assert request.seed == plain[name].seed


def test_floors_are_read_again_by_the_same_runs_on_tests_with_more_samples(study):
    out, result = study
    again = json.loads((out / "ladder" / "episodes-2-tests-2x" / "metrics.json").read_text())
    plan = json.loads((out / "ladder" / "episodes-2" / "metrics.json").read_text())
    for name in ("val-0", "train-1"):  # trained and validated where the ladder was
        assert again["episodes"][name] == plan["episodes"][name]
    for name in ("test-0", "test-1"):  # same scenes, rendered again with twice the samples
        source = again["episodes"][name]["dataset"]
        assert source == str(out / "tests-2x" / name)
        seed = read_manifest(out / "episodes" / name)["request"]["seed"]
        manifest = read_manifest(source)
        assert manifest["request"]["seed"] == seed
        assert manifest["job"]["render"]["max_depth"] == 16
    for design in ("mincam-2px", "baseline-2x2"):
        old, new = plan["designs"][design], again["designs"][design]
        assert new["steps"] == old["steps"]  # the same runs (copied), not trained again
        assert new["error"]["mean"] != old["error"]["mean"]  # tested on other renders
    assert (
        result.retested["2x"].designs["mincam-2px"].error
        == again["designs"]["mincam-2px"]["error"]["mean"]
    )
    *_, retested = result.floors
    assert retested.paired.mean == pytest.approx(
        again["designs"]["mincam-2px"]["error"]["mean"]
        - again["designs"]["baseline-2x2"]["error"]["mean"], abs=1e-9
    )  # fmt: skip


def test_an_oracle_of_a_family_without_a_background_is_refused_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="oracle: family 'patches' renders no background"):
        run(CFG, tmp_path / "out", sections=("ladder", "oracle"))
    assert not (tmp_path / "out").exists()


def test_floors_on_re_rendered_tests_need_the_ladder(tmp_path):
    with pytest.raises(ValueError, match="run 'ladder'"):
        run(CFG, tmp_path / "study", sections=("recipes",))
    assert not (tmp_path / "study").exists()  # refused before anything is written


def _figure(name: str, errors: list[list[float]]) -> DesignFigure:
    flat = [e for seed in errors for e in seed]
    return DesignFigure(
        design=name, pixels=2, error=sum(flat) / len(flat), ci95=(0.0, 1.0),
        per_seed=tuple(sum(s) / len(s) for s in errors), state="converged",
        steps=(1,) * len(errors), train_s_per_run=1.0,
        episode_errors={"error": errors, "frames": [100.0] * len(errors[0]), "pooling": "mean"},
    )  # fmt: skip


def _point(design: list[list[float]], baseline: list[list[float]]) -> LadderPoint:
    """A ladder point of mincam-2px and baseline-8x8 with these per-seed, per-episode errors."""
    figures = {"mincam-2px": _figure("mincam-2px", design),
               "baseline-8x8": _figure("baseline-8x8", baseline)}  # fmt: skip
    return LadderPoint(episodes=4, frames=400, render_s=1.0, trivial=2.0, designs=figures)


@pytest.mark.parametrize(
    ("shift", "margin", "verdict"),
    [
        (-0.2, 0.0, FloorVerdict.MET),  # lower on every episode
        (+0.2, 0.0, FloorVerdict.MISSED),  # higher on every episode
        (+0.2, 0.3, FloorVerdict.MET),  # higher, but within the margin
        (+0.35, 0.3, FloorVerdict.MISSED),  # beyond the margin on every episode
    ],
)
def test_a_floor_verdict_follows_the_paired_interval(shift, margin, verdict):
    base = [[1.0, 1.4, 0.8, 1.2, 1.1, 0.9]] * 3
    design = [[e + shift for e in seed] for seed in base]
    point = _point(design, base)
    cfg = DesignProtocolConfig(
        floors=(Floor(design="mincam-2px", baseline="baseline-8x8", margin=margin),)
    )
    (check,) = floor_checks(cfg, point)
    assert check.paired.mean == pytest.approx(shift)
    assert check.verdict is verdict


def test_an_undecided_floor_holds_the_margin_in_its_interval():
    base = [[1.0, 1.4, 0.8, 1.2, 1.1, 0.9]] * 3
    noisy = [[e + d for e, d in zip(seed, (-0.5, 0.5, -0.4, 0.4, -0.3, 0.35), strict=True)]
             for seed in base]  # fmt: skip
    point = _point(noisy, base)
    cfg = DesignProtocolConfig(floors=(Floor(design="mincam-2px", baseline="baseline-8x8"),))
    (check,) = floor_checks(cfg, point)
    assert check.paired.ci95[0] < 0.0 < check.paired.ci95[1]
    assert check.verdict is FloorVerdict.UNDECIDED


def test_the_report_is_strict_json_tables_and_a_figure(study, tmp_path):
    _, result = study
    paths = write_report(result, tmp_path, stem="protocol")
    text = paths["md"].read_text()
    assert "## Learning curves" in text and "## Recipes" in text and "### 2 px" in text
    assert "## Seed spread" in text
    assert "| mincam-2px - baseline-2x2 < 0.05 | 2 | the plan's |" in text
    assert "| mincam-2px - baseline-2x2 < 0.05 | 2 | 2x samples |" in text
    assert "| 2, tested at 2x samples | 80 |  |" in text
    assert "rendered at" not in text  # the plan's episodes
    assert paths["png"].stat().st_size > 10_000
    json.dumps(result.as_json(), allow_nan=False)
    tables = [ln for ln in text.splitlines() if ln.startswith("|")]
    assert "## Recipes" in text and any("\\|" in ln for ln in tables)
    block_width = None
    for ln in text.splitlines():  # every row of a table has its header's cells
        cells = len(re.split(r"(?<!\\)\|", ln)) - 2 if ln.startswith("|") else None
        block_width = (block_width or cells) if cells is not None else None
        assert cells == block_width, ln


def test_the_report_says_at_which_samples_the_episodes_were_rendered(study):
    import dataclasses

    from mincam_render.studies.design_protocol.report import markdown

    _, result = study
    config = json.loads(json.dumps(result.config))
    config["episodes"]["fidelity"]["samples_factor"] = 4.0
    at_4x = dataclasses.replace(
        result, config=config, floors=[dataclasses.replace(result.floors[0], test_factor=4.0)]
    )
    text = markdown(at_4x)
    assert "Every episode rendered at 4x the plan's samples." in text
    assert "| mincam-2px - baseline-2x2 < 0.05 | 2 | 4x samples |" in text
    assert "the plan's |" not in text


def test_configuration_is_validated():
    with pytest.raises(ValueError, match="increasing"):
        DesignProtocolConfig(ladder=(4, 2))
    with pytest.raises(ValueError, match="first variant is the base"):
        DesignProtocolConfig(recipes=(RecipeVariant(name="x", changes={"max_steps": 5}),))
    with pytest.raises(ValueError, match="unknown TrainConfig fields"):
        RecipeVariant(name="x", changes={"gain": 1})
    with pytest.raises(ValueError, match="mask_block"):
        RecipeVariant(name="x", changes={"mask_block": 0})
    with pytest.raises(ValueError, match="two designs"):
        Floor(design="mincam-2px", baseline="mincam-2px")
    with pytest.raises(ValueError, match="margin"):
        Floor(design="mincam-2px", baseline="baseline-8x8", margin=-0.1)
    with pytest.raises(ValueError, match="both must be ladder designs"):
        DesignProtocolConfig(floors=(Floor(design="mincam-4px", baseline="baseline-8x8"),))
    floors = (Floor(design="mincam-2px", baseline="baseline-8x8"),)
    for factors in ((1,), (4, 1.0)):
        with pytest.raises(ValueError, match=r"other than the episodes' own \(1x"):
            DesignProtocolConfig(floors=floors, floor_test_factors=factors)
    at_4x = ComparisonConfig(fidelity={"samples_factor": 4})
    with pytest.raises(ValueError, match=r"other than the episodes' own \(4x"):
        DesignProtocolConfig(episodes=at_4x, floors=floors, floor_test_factors=(16, 4))
    plan_and_16x = DesignProtocolConfig(episodes=at_4x, floors=floors, floor_test_factors=(1, 16))
    assert plan_and_16x.floor_test_factors == (1.0, 16.0) and plan_and_16x.episodes_factor == 4.0
    for factors in ((4, 16, 4.0), (4, 4.0000001)):  # one name, one folder: tests-4x
        with pytest.raises(ValueError, match=r"distinct factors \(\['4x'"):
            DesignProtocolConfig(floors=floors, floor_test_factors=factors)
    with pytest.raises(ValueError, match="give floors to read"):
        DesignProtocolConfig(floor_test_factors=(4,))
    with pytest.raises(ValueError, match="need a sequence"):
        DesignProtocolConfig(floors=floors, floor_test_factors=4)
    with pytest.raises(ValueError, match="floor_test_factors"):
        DesignProtocolConfig(floors=floors, floor_test_factors=(4, -4))
    signed = recipes_named(["signed"])[-1]
    with pytest.raises(ValueError, match="reference_recipe 'signed': a diagnostic, not a recipe"):
        DesignProtocolConfig(reference_recipe=signed)
    given = DesignProtocolConfig(floors=floors, floor_test_factors=[4, 16])
    assert given.floor_test_factors == (4.0, 16.0)


def test_validation_picks_the_lowest_better_recipe_but_never_a_diagnostic():
    from types import SimpleNamespace

    from mincam_render.studies.comparison.figures import Paired

    def row(variant, val_error, lower):
        ci = (-0.2, -0.1) if lower else (-0.1, 0.1)
        paired = Paired("a", "b", sum(ci) / 2, ci, "")
        return RecipeRow(
            variant=variant,
            changes={},
            designs={"baseline-2x2": SimpleNamespace(val_error=val_error)},
            versus_base={},
            versus_base_validation={"baseline-2x2": paired},
        )

    rows = [row("base", 1.0, False), row("tv", 0.9, True), row("linear", 0.5, True)]
    assert chosen_recipes(CFG, rows)["baseline-2x2"] == "tv"  # "linear" is a diagnostic
    assert chosen_recipes(CFG, rows[:1] + rows[2:])["baseline-2x2"] == "base"
    assert chosen_recipes(CFG, rows[:2])["baseline-2x2"] == "tv"


def test_recipes_are_chosen_by_name_after_the_base():
    chosen = recipes_named(["head-512", "tv-0.3"])
    assert [r.name for r in chosen] == ["base", "head-512", "tv-0.3"]
    assert chosen[1].apply(TrainConfig()).head_hidden == 512
    assert [r.name for r in recipes_named(["base"])] == ["base"]
    for names in (["head-1024"], ["tv-0.3", "tv-0.3"]):
        with pytest.raises(ValueError, match="at most once"):
            recipes_named(names)
    with pytest.raises(ValueError, match="head_hidden"):
        RecipeVariant(name="x", changes={"head_hidden": 0})
    with pytest.raises(ValueError, match="not both"):
        RecipeVariant(name="x", minimalist_only=True, baselines_only=True)
    linear, signed = recipes_named(["linear-8", "signed"])[1:]
    assert linear.baselines_only and linear.apply(TrainConfig()).head_bottleneck == 8
    assert signed.minimalist_only and signed.apply(TrainConfig()).signed_pixels
    assert linear.diagnostic and signed.diagnostic
