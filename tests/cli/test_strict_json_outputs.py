"""Every JSON file the main commands write parses with a strict parser (no NaN, no Infinity).

Regression: ``metrics.json`` held bare ``NaN`` (the trivial predictor's loss, an
undecided convergence), which JavaScript's ``JSON.parse``, ``jq`` and most
languages refuse.
"""

from __future__ import annotations

from click.testing import CliRunner

from mincam_render.cli.main import main
from mincam_render.core import strict_json

TINY = ["--frames", "40", "--shard-frames", "8", "--detectors", "2", "--mask-res", "8"]
TINY += ["--spp", "2", "--no-progress", "--workers", "0"]
QUICK = ["--steps", "10", "--eval-every", "5", "--batch-size", "4"]
#: Episodes so short that a run has no evaluation by half its steps (an undecided
#: convergence) beside the trivial predictor (no training loss): the NaNs of old.
PIPELINE = [
    "pipeline", "--family", "patches", "--train-frames", "30", "--val-frames", "30",
    "--test-frames", "30", "--train-episodes", "1", "--seeds", "1", "--steps", "5",
    "--workers", "0", "--spp", "2", "--pixels", "1", "--baseline-grid", "1x1",
    "--detectors", "2", "--mask-res", "8",
]  # fmt: skip


def _run(args: list) -> None:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, (res.output, res.exception)


def test_every_json_the_main_commands_write_is_strict_json(tmp_path, variant):
    ds, run = tmp_path / "ds", tmp_path / "run"
    _run(["render", "patches", *TINY, "--out", ds])
    _run(["train", ds, *QUICK, "--out", run])
    _run(["sweep", ds, *QUICK, "--pixels", "1", "--baselines", "1x1", "--out", tmp_path / "sw"])
    _run(["prune", ds, *QUICK, "--run", run, "--out", tmp_path / "prune"])
    _run(["export-masks", run, "--task", "t", "--no-pdf", "--out", tmp_path / "masks"])
    _run(["report", "robustness", run, "--data", ds, "--draws", "2", "--levels", "0,1",
          "--out", tmp_path / "robustness"])  # fmt: skip
    _run([*PIPELINE, "--out", tmp_path / "pipeline"])
    written = sorted(p for p in tmp_path.rglob("*") if p.suffix in (".json", ".jsonl"))
    folders = {p.relative_to(tmp_path).parts[0] for p in written}
    assert folders == {"ds", "run", "sw", "prune", "masks", "robustness", "pipeline"}
    for path in written:
        lines = path.read_text().splitlines() if path.suffix == ".jsonl" else [path.read_text()]
        for line in lines:
            strict_json.loads(line)  # raises on NaN or Infinity, naming neither silently
    metrics = strict_json.loads((tmp_path / "pipeline" / "metrics.json").read_text())
    trivial = next(iter(metrics["trivial"]["episodes"].values()))
    assert trivial["loss"] is None and "no training loss" in trivial["loss_null_reason"]
