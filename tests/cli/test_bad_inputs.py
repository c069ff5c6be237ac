"""The bad-input corpus (tests/data/bad_inputs/cases.toml): exit 2, one line, nothing written."""

from __future__ import annotations

import shutil
import tomllib
from pathlib import Path

import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main

CORPUS = Path(__file__).parents[1] / "data" / "bad_inputs"
CASES = tomllib.loads((CORPUS / "cases.toml").read_text())["case"]


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in root.rglob("*") if p.is_file()}


def test_the_corpus_has_at_least_25_cases():
    assert len(CASES) >= 25 and len({c["name"] for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(case, tmp_path, monkeypatch, variant):
    work = tmp_path / "corpus"
    shutil.copytree(CORPUS, work)
    monkeypatch.chdir(work)
    out = tmp_path / "out"
    before = _tree(work)
    args = [str(out) if a == "OUT" else a for a in case["args"]]
    res = CliRunner().invoke(main, args)
    errors = [line for line in res.output.splitlines() if line.startswith("Error:")]
    assert res.exit_code == 2, (res.exit_code, res.output, res.exception)
    assert "Traceback" not in res.output
    assert len(errors) == 1, res.output
    assert case["expect"] in errors[0], errors[0]
    assert not out.exists() or not any(out.iterdir()), sorted(out.rglob("*"))
    assert _tree(work) == before


def test_training_on_a_dataset_without_validation_frames_says_so(tmp_path, variant):
    """Regression: `render --splits 1,0,0` then `train` failed with a message about history."""
    runner = CliRunner()
    ds = tmp_path / "ds"
    tiny = ["--frames", "4", "--detectors", "2", "--mask-res", "4", "--spp", "1"]
    res = runner.invoke(
        main, ["render", "patches", *tiny, "--splits", "1,0,0", "--no-progress", "--out", str(ds)]
    )
    assert res.exit_code == 0, res.output
    res = runner.invoke(main, ["train", str(ds), "--steps", "2", "--out", str(tmp_path / "run")])
    assert res.exit_code == 2 and "has no val frames" in res.output and "--splits" in res.output
    assert not (tmp_path / "run").exists()
