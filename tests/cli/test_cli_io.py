import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main
from mincam_render.data.exr import read_transport_exr, write_transport_exr
from mincam_render.data.render_job import RenderRequest
from mincam_render.learn.train_config import TrainConfig
from mincam_render.optics.perturbation import PerturbationModel
from mincam_render.studies.comparison.config import ComparisonConfig
from mincam_render.studies.fidelity import FidelityBenchConfig
from mincam_render.studies.privacy.config import AttackConfig
from mincam_render.studies.robustness.config import RobustnessConfig


def test_exr_round_trip_is_exact(tmp_path, rng):
    t = rng.uniform(0, 1e-7, size=(3, 5, 7)).astype(np.float32)
    meta = {"spp": 16, "camera": {"mask_size_m": 0.016}}
    write_transport_exr(tmp_path / "t.exr", t, meta)
    back, meta_back = read_transport_exr(tmp_path / "t.exr")
    np.testing.assert_array_equal(back, t)
    assert meta_back == meta
    assert not list(tmp_path.glob("*.partial*"))


def test_cli_transport_writes_exr_png_and_config(variant, tmp_path):
    out = tmp_path / "run"
    res = CliRunner().invoke(
        main,
        [
            "transport",
            "--out",
            str(out),
            "--grid",
            "1x2",
            "--mask-res",
            "8",
            "--spp",
            "4",
            "--seed",
            "0",
        ],
    )
    assert res.exit_code == 0, res.output
    t, meta = read_transport_exr(out / "transport.exr")
    assert t.shape == (2, 8, 8) and np.all(np.isfinite(t)) and t.sum() > 0
    config = json.loads((out / "config.json").read_text())
    assert config["seed"] == 0 and config["camera"]["mask_resolution"] == [8, 8]
    assert meta["spp"] == 4
    png = (out / "transport.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--grid", "4by6"], "ROWSxCOLS"),
        (["--position", "1,2"], "x,y,z"),
        (["--spp", "0"], "spp"),
        (["--pitch-mm", "5"], "layout"),
        (["--look-at", "0,0,0"], "look_at"),
    ],
)
def test_cli_bad_arguments_fail_with_one_clear_line_and_no_output(variant, tmp_path, args, message):
    out = tmp_path / "run"
    res = CliRunner().invoke(main, ["transport", "--out", str(out), *args])
    assert res.exit_code != 0
    assert message in res.output
    assert "Traceback" not in res.output
    assert not out.exists()


def test_cli_missing_scene_file(variant, tmp_path):
    res = CliRunner().invoke(
        main, ["transport", str(tmp_path / "nope.xml"), "--out", str(tmp_path / "o")]
    )
    assert res.exit_code != 0 and "does not exist" in res.output


def test_cli_preview_writes_a_png(variant, tmp_path):
    res = CliRunner().invoke(
        main,
        [
            "preview",
            "patches",
            "--out",
            str(tmp_path),
            "--frames",
            "2",
            "--spp",
            "2",
            "--duration-s",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    png = (tmp_path / "preview_patches.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10000


def test_cli_preview_unknown_family(variant, tmp_path):
    res = CliRunner().invoke(main, ["preview", "nosuch", "--out", str(tmp_path / "p")])
    assert res.exit_code != 0 and "not found" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "p").exists()


def test_cli_pipeline_tests_on_independent_episodes_with_intervals_and_resumes(
    variant, tmp_path, monkeypatch
):
    from mincam_render.data.dataset import open_dataset, sha256_file
    from mincam_render.data.render_job import package_versions

    out = tmp_path / "main"
    args = [
        "pipeline", "--family", "patches", "--train-frames", "60", "--val-frames", "30",
        "--test-frames", "30", "--test-episodes", "2", "--seeds", "2", "--steps", "30",
        "--workers", "0", "--spp", "2", "--pixels", "2", "--baseline-grid", "2x2",
        "--out", str(out),
    ]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert "verdict:" in res.output and "trivial" in res.output
    metrics = json.loads((out / "metrics.json").read_text())
    # independent episodes: one dataset each, each its own scene seed, all complete
    eps = metrics["episodes"]
    assert sorted(eps) == ["test-0", "test-1", "train-0", "train-1", "val-0", "val-1", "val-2"]
    assert len({e["dataset"] for e in eps.values()}) == 7
    seeds = {open_dataset(out / "episodes" / k).manifest["request"]["seed"] for k in eps}
    assert len(seeds) == 7
    for k in eps:
        assert open_dataset(out / "episodes" / k).verify() == []
    designs = metrics["designs"]
    assert designs["mincam-2px"]["model"]["pixels"] == 2
    assert designs["baseline-2x2"]["model"]["grid"] == [2, 2]
    for d in designs.values():
        lo, hi = d["error"]["ci95"]
        assert lo <= d["error"]["mean"] <= hi and len(d["error_per_seed"]) == 2
        assert np.mean(d["error_per_seed"]) == pytest.approx(d["error"]["mean"])
        assert len(d["convergence"]) == 2 and isinstance(d["converged"], bool)
    assert metrics["trivial"]["error"]["mean"] > 0
    # the figures name the code and packages that produced them
    assert metrics["versions"] == package_versions()
    (label,) = metrics["labels"]  # patches: the count, with every design and the trivial
    for name, figure in metrics["labels"][label]["configs"].items():
        source = metrics["trivial"] if name == "trivial" else designs[name]
        assert figure == source["error"]  # the primary label is the task's error
    assert metrics["verdict"] in res.output
    # paired differences on the same test episodes: the two cameras, then each against trivial
    paired = metrics["paired"]
    assert list(paired) == [
        "mincam-2px - baseline-2x2", "mincam-2px - trivial", "baseline-2x2 - trivial"
    ]  # fmt: skip
    for key, p in paired.items():
        a, b = key.split(" - ")
        lo, hi = p["ci95"]
        assert lo <= p["mean"] <= hi and p["statement"] in res.output
        errors = {n: designs[n] for n in designs} | {"trivial": metrics["trivial"]}
        assert p["mean"] == pytest.approx(errors[a]["error"]["mean"] - errors[b]["error"]["mean"])
    assert (out / "comparison.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    sidecar = json.loads((out / "masks" / "patches" / "mincam-2px" / "masks.json").read_text())
    assert sidecar["masks"] == 2 and len(sidecar["files"]["png"]) == 2
    assert sidecar["provenance"]["test_error_over_seeds"] == designs["mincam-2px"]["error"]
    prov = sidecar["provenance"]
    assert prov["episodes"]["train-0"]["manifest_sha256"] == sha256_file(
        out / "episodes" / "train-0" / "manifest.json"
    )
    assert prov["versions"]["git_revision"]
    # a second run finds every episode and run on disk and reports the same figures
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    redone = json.loads((out / "metrics.json").read_text())["designs"]
    for kind, d in designs.items():
        for key in ("error", "error_per_seed", "convergence", "steps"):
            assert redone[kind][key] == d[key]
    assert metrics["not_of_this_comparison"] == {}  # the folders hold only its own
    # --out spelled another way (relative, from its parent) and another design: the
    # finished runs resume by their data's content; metrics.json names what is not its own
    monkeypatch.chdir(tmp_path)
    other = [*args[:-6], "--pixels", "1", "--baseline-grid", "2x2", "--out", "main"]
    third = CliRunner().invoke(main, other)
    assert third.exit_code == 0, third.output
    result = json.loads((out / "metrics.json").read_text())
    assert result["designs"]["baseline-2x2"]["steps"] == designs["baseline-2x2"]["steps"]
    left = result["not_of_this_comparison"]
    assert left["masks"] == ["mincam-2px"]
    assert left["runs"] == ["mincam-2px-seed0", "mincam-2px-seed1"]
    assert "episodes" not in left and "earlier comparison" in left["note"]


def test_cli_study_reads_shared_episodes_without_rendering_them_again(variant, tmp_path):
    from mincam_render.data.dataset import sha256_file

    shared = tmp_path / "episodes"
    args = [
        "study", "--family", "patches", "--train-frames", "40", "--val-frames", "30",
        "--val-episodes", "1", "--test-frames", "30", "--test-episodes", "1", "--seeds", "1",
        "--steps", "20", "--workers", "0", "--spp", "1", "--pixels", "2",
        "--baseline-grids", "2x2", "--reference-pixels", "2", "--episodes-dir", str(shared),
    ]  # fmt: skip
    first = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "a")])
    assert first.exit_code == 0, first.output
    assert sorted(p.name for p in shared.iterdir() if p.is_dir()) == [
        "test-0", "train-0", "train-1", "val-0"
    ]  # fmt: skip
    assert not (tmp_path / "a" / "episodes").exists()
    logs = {p: p.read_text() for p in shared.glob("*/render_log.jsonl")}
    assert len(logs) == 4
    second = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "b")])
    assert second.exit_code == 0, second.output
    for path, before in logs.items():  # the second study rendered no shard of them
        added = path.read_text().removeprefix(before).splitlines()
        ends = [json.loads(e) for e in added if '"end"' in e]
        assert ends and all(e["rendered"] == [] for e in ends), added
    a, b = (json.loads((tmp_path / o / "metrics.json").read_text()) for o in "ab")
    assert a["episodes"] == b["episodes"]
    assert a["episodes"]["train-0"]["manifest_sha256"] == sha256_file(
        shared / "train-0" / "manifest.json"
    )
    assert b["designs"]["mincam-2px"]["error"] == a["designs"]["mincam-2px"]["error"]
    # the same directory with episodes of another request is refused, not mixed
    other = CliRunner().invoke(main, [*args[:-2], "--episodes-dir", str(shared), "--seed", "7",
                                      "--out", str(tmp_path / "c")])  # fmt: skip
    assert other.exit_code != 0 and "Traceback" not in other.output


def test_cli_train_refuses_more_pixels_than_rendered_detectors(variant, tmp_path):
    args = ["train", "--family", "patches", "--frames", "40", "--spp", "1", "--steps", "5",
            "--pixels", "8", "--out", str(tmp_path / "t")]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code != 0 and "Traceback" not in res.output
    assert "pixels = 8: the data has only 4 rendered detectors" in res.output


def test_cli_prune_writes_its_own_files_only(variant, tmp_path):
    """Regression: prune left sweep.json and sweep.md (rows with 0 steps, 0 s) behind."""
    tiny = ["--family", "patches", "--frames", "40", "--spp", "1", "--steps", "4"]
    tiny += ["--eval-every", "2", "--batch-size", "4"]
    run = tmp_path / "run"
    res = CliRunner().invoke(main, ["train", *tiny, "--out", str(run)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "prune"
    res = CliRunner().invoke(main, ["prune", *tiny, "--run", str(run), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["prune.json", "prune.png"]
    records = json.loads((out / "prune.json").read_text())
    assert [r["pixels"] for r in records] == sorted((r["pixels"] for r in records), reverse=True)


def test_robust_options_are_the_perturbation_record_with_its_defaults():
    """--mask-shift-mm and the rest fill PerturbationModel's record (mm, deg, %, cm)."""
    params = main.commands["train"].make_context("train", []).params
    record = PerturbationModel().to_record()
    filled = {name: value for name, value in params.items() if name in record}
    assert filled == record
    assert PerturbationModel.from_record(filled) == PerturbationModel()


@pytest.mark.parametrize(
    ("names", "args", "config", "count"),
    [
        (("render",), ["patches", "--out", "o", "--frames", "5"], RenderRequest, 22),
        (("train",), [], TrainConfig, 14),
        (("sweep",), [], TrainConfig, 13),
        (("prune",), ["--run", "r"], TrainConfig, 13),
        (("report", "robustness"), ["r"], RobustnessConfig, 4),
        (("report", "privacy"), [], AttackConfig, 2),
        (("bench", "fidelity"), ["patches"], FidelityBenchConfig, 6),
        (("pipeline",), [], ComparisonConfig, 15),
        (("study",), ["--out", "o"], ComparisonConfig, 15),
    ],
)
def test_options_named_like_a_dataclass_fields_default_to_the_fields_defaults(
    names, args, config, count
):
    """One source of truth: an option filling a field is named like it and takes its default."""
    command = main
    for name in names:
        command = command.commands[name]
    params = command.make_context(names[-1], list(args)).params
    fields = {f.name: f for f in dataclasses.fields(config)}
    filled = {name: value for name, value in params.items() if name in fields}
    assert len(filled) == count, sorted(filled)
    no_default = dataclasses.MISSING
    required = {
        name: value
        for name, value in filled.items()
        if fields[name].default is no_default and fields[name].default_factory is no_default
    }
    for name, value in filled.items():
        if name in required or value == {}:  # --set: nothing to override
            continue
        assert config(**required, **{name: value}) == config(**required), name


def test_sim2real_options_are_the_config_fields_with_their_defaults():
    """`report sim2real`'s literal defaults (importing the study loads scipy) are the config's."""
    from mincam_render.studies.sim2real import Sim2RealConfig

    command = main.commands["report"].commands["sim2real"]
    params = command.make_context("sim2real", ["--surrogate", "patches"]).params
    fields = {f.name for f in dataclasses.fields(Sim2RealConfig)}
    filled = {name: value for name, value in params.items() if name in fields}
    assert sorted(filled) == ["seed", "spp", "steps", "surrogate_family", "surrogate_frames"]
    assert Sim2RealConfig(**filled) == Sim2RealConfig(surrogate_family="patches")
