"""The commands that read a run: every kind they take works, the others are one line.

``export-masks``, ``prune`` and ``report robustness`` on minimalist runs trained
nominally, with a temporal-convolution head, robustly, with the privacy term and
with a head of another width; a run of signed pixels (pruning refuses it);
a baseline run refused by each; unfinished runs refused unless allowed (then
marked); exports that replace their folder whole; names kept inside ``--out``;
a run resumed through another spelling of its paths.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main

TINY = ["--frames", "40", "--shard-frames", "8", "--detectors", "2", "--mask-res", "8"]
TINY += ["--spp", "2", "--no-progress", "--workers", "0"]
QUICK = ["--steps", "20", "--eval-every", "10", "--batch-size", "4"]
#: kind -> the train options that make it
KINDS = {
    "mincam": [],
    "baseline": ["--baseline", "2x2"],
    "tcn": ["--head", "tcn"],
    "robust": ["--robust"],
    "privacy": ["--privacy-weight", "1"],
    "head-24": ["--head-hidden", "24"],
    "signed": ["--signed-pixels"],
}
MINCAM_KINDS = [k for k in KINDS if k not in ("baseline", "signed")]


def _invoke(args: list[str]):
    return CliRunner().invoke(main, [str(a) for a in args])


def _ok(args: list[str]):
    res = _invoke(args)
    assert res.exit_code == 0, (res.output, res.exception)
    return res


def _refused(args: list[str], expect: str, out: Path) -> None:
    res = _invoke(args)
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert res.exit_code == 2 and "Traceback" not in res.output, (res.output, res.exception)
    assert len(errors) == 1 and expect in errors[0], res.output
    assert not out.exists() or not any(out.iterdir())


@pytest.fixture(scope="module")
def cli_runs(tmp_path_factory, variant):
    """``{"dataset": its folder, kind: run folder, "unfinished": a killed run's folder}``."""
    root = tmp_path_factory.mktemp("readers")
    out = {"dataset": root / "ds"}
    _ok(["render", "patches", *TINY, "--seed", "3", "--out", out["dataset"]])
    for kind, options in KINDS.items():
        out[kind] = root / kind
        _ok(["train", out["dataset"], *QUICK, *options, "--out", out[kind]])
    out["unfinished"] = root / "unfinished"
    shutil.copytree(out["mincam"], out["unfinished"])
    (out["unfinished"] / "metrics.json").unlink()  # killed after its last checkpoint
    return out


def _reader(command: str, run: Path, ds: Path, out: Path) -> list:
    return {
        "export-masks": ["export-masks", run, "--task", "t", "--no-pdf", "--out", out],
        "prune": ["prune", ds, *QUICK, "--run", run, "--out", out],
        "report robustness": [
            "report",
            "robustness",
            run,
            "--data",
            ds,
            "--draws",
            "2",
            "--levels",
            "0,1",
            "--out",
            out,
        ],  # fmt: skip
    }[command]


READERS = ["export-masks", "prune", "report robustness"]


@pytest.mark.parametrize("kind", MINCAM_KINDS)
@pytest.mark.parametrize("command", READERS)
def test_every_minimalist_run_is_read_by_every_reader(cli_runs, kind, command, tmp_path):
    res = _ok(_reader(command, cli_runs[kind], cli_runs["dataset"], tmp_path / "out"))
    assert "Traceback" not in res.output
    written = {p.name for p in (tmp_path / "out").rglob("*") if p.is_file()}
    expected = {
        "export-masks": {"mask_00.png", "mask_01.png", "masks.exr", "masks.json"},
        "prune": {"prune.json", "prune.png"},
        "report robustness": {"robustness.html", "robustness.png", "robustness.json"},
    }[command]
    assert expected <= written


def test_a_signed_run_exports_its_pairs_reports_robustness_and_is_not_pruned(cli_runs, tmp_path):
    run = json.loads((cli_runs["signed"] / "run.json").read_text())
    assert run["model"]["signed"] and run["model"]["detectors"] == [0, 1]
    _ok(_reader("export-masks", cli_runs["signed"], cli_runs["dataset"], tmp_path / "m"))
    sidecar = json.loads((tmp_path / "m" / "t" / "masks.json").read_text())
    assert sidecar["signed_pairs"] == [[0, 1]]
    _ok(_reader("report robustness", cli_runs["signed"], cli_runs["dataset"], tmp_path / "r"))
    assert any((tmp_path / "r").rglob("robustness.json"))
    out = tmp_path / "p"
    _refused(_reader("prune", cli_runs["signed"], cli_runs["dataset"], out), "signed pairs", out)
    prune_signed = [
        *_reader("prune", cli_runs["mincam"], cli_runs["dataset"], out),
        "--signed-pixels",
    ]
    _refused(prune_signed, "--signed-pixels: prune keeps the run's pixels", out)


@pytest.mark.parametrize("command", READERS)
def test_a_baseline_run_is_refused_by_every_reader_in_one_line(cli_runs, command, tmp_path):
    out = tmp_path / "out"
    _refused(
        _reader(command, cli_runs["baseline"], cli_runs["dataset"], out), "is a baseline run", out
    )


@pytest.mark.parametrize("command", READERS)
def test_an_unfinished_run_is_refused_by_every_reader_unless_allowed(cli_runs, command, tmp_path):
    out = tmp_path / "out"
    args = _reader(command, cli_runs["unfinished"], cli_runs["dataset"], out)
    _refused(args, "training did not finish (unfinished: step 20 of 20", out)
    res = _ok([*args, "--allow-unfinished"])
    if command == "export-masks":
        sidecar = json.loads((out / "t" / "masks.json").read_text())
        assert sidecar["provenance"]["training"] == "unfinished: step 20 of 20"
        assert (
            "UNFINISHED RUN (unfinished: step 20 of 20)"
            in (out / "t" / "print_sheet.svg").read_text()
        )
        assert "marked unfinished" in res.output
    elif command == "prune":
        records = json.loads((out / "prune.json").read_text())
        assert {r["run_training"] for r in records} == {"unfinished: step 20 of 20"}
    else:
        designs = json.loads((out / "robustness.json").read_text())
        assert designs[0]["name"] == "unfinished (unfinished)"


def test_an_export_replaces_its_folder_whole_and_refuses_a_folder_of_other_files(
    cli_runs, tmp_path
):
    one = tmp_path / "one"
    _ok(["train", cli_runs["dataset"], *QUICK, "--pixels", "1", "--out", one])
    out = tmp_path / "masks"
    _ok(["export-masks", cli_runs["mincam"], "--task", "t", "--out", out])
    _ok(["export-masks", one, "--task", "t", "--out", out])
    sidecar = json.loads((out / "t" / "masks.json").read_text())
    listed = {*sidecar["files"]["png"], "masks.exr", "print_sheet.svg", "print_sheet.pdf"}
    assert {p.name for p in (out / "t").iterdir()} == listed | {"masks.json"}
    assert sidecar["files"]["png"] == ["mask_00.png"]  # no stale mask_01.png beside it
    assert [p.name for p in out.iterdir()] == ["t"]  # no hidden sibling left
    (out / "t" / "notes.txt").write_text("mine")
    res = _invoke(["export-masks", cli_runs["mincam"], "--task", "t", "--out", out])
    assert res.exit_code == 2 and "notes.txt" in res.output
    assert json.loads((out / "t" / "masks.json").read_text()) == sidecar


@pytest.mark.parametrize("task", ["../../escaped", "a/b", "..", ".hidden", ""])
def test_a_task_name_cannot_leave_out(cli_runs, tmp_path, task):
    out = tmp_path / "out"
    _refused(["export-masks", cli_runs["mincam"], "--task", task, "--out", out], "--task", out)
    assert [p.name for p in tmp_path.iterdir()] == []


def test_a_run_resumes_through_another_spelling_or_place_of_its_paths(
    cli_runs, tmp_path, monkeypatch
):
    ds = tmp_path / "ds"
    shutil.copytree(cli_runs["dataset"], ds)
    monkeypatch.chdir(tmp_path)
    _ok(["train", "ds", *QUICK, "--out", "run"])  # relative paths, as typed
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    _ok(["train", ds, *QUICK, "--out", tmp_path / "run"])  # absolute paths
    ds.rename(tmp_path / "moved")
    _ok(["train", tmp_path / "moved", *QUICK, "--out", "../run"])  # the data moved
    other = tmp_path / "other"
    _ok(["render", "patches", *TINY, "--seed", "4", "--out", other])
    res = _invoke(["train", other, *QUICK, "--out", tmp_path / "run"])
    assert res.exit_code == 2 and "was trained with another data" in res.output
