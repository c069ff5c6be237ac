"""Figures the README and the docs quote equal the results files they come from.

A figure typed into prose drifts when its study is run again; these tests read
the JSON a sentence names and look for the same figure, rounded as quoted, in
the text. Each case is a figure a newcomer reads first.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MAIN_JOB_MASKS = REPO / "masks" / "workspace" / "main-job-mincam-8px"
DESIGN_PROTOCOL = REPO / "benchmarks" / "results" / "design_protocol.json"


def _interval(error: dict) -> str:
    """``mean [lo, hi]`` at three decimals, as the docs quote a figure."""
    lo, hi = error["ci95"]
    return f"{error['mean']:.3f} [{lo:.3f}, {hi:.3f}]"


def _read(path: Path) -> str:
    return path.read_text(encoding="utf-8")


@pytest.mark.parametrize("doc", ["README.md", "masks/README.md"])
def test_the_main_jobs_kept_people_count_figure_is_its_sidecars(doc):
    sidecar = json.loads(_read(MAIN_JOB_MASKS / "people_count" / "masks.json"))
    figure = _interval(sidecar["provenance"]["test_error_over_seeds"])
    assert figure in _read(REPO / doc), f"{doc} does not quote the kept masks' {figure}"


def test_the_readme_shows_the_kept_print_sheet_and_the_learning_curves():
    readme = _read(REPO / "README.md")
    for target in (
        "masks/workspace/main-job-mincam-8px/people_count/print_sheet.svg",
        "benchmarks/results/design_protocol_workspace.png",
    ):
        assert target in readme and (REPO / target).is_file(), target


def test_the_design_protocols_learning_curve_at_its_largest_size_is_the_jsons():
    ladder = json.loads(_read(DESIGN_PROTOCOL))["workspace"]["ladder"][-1]
    doc = _read(REPO / "docs" / "design_protocol.md")
    row = next(ln for ln in doc.splitlines() if ln.startswith(f"| {ladder['episodes']} |"))
    for name in ("mincam-2px", "mincam-8px", "baseline-8x8", "baseline-32x32"):
        d = ladder["designs"][name]
        quoted = _interval({"mean": d["error"], "ci95": d["ci95"]})
        assert quoted in row, f"docs/design_protocol.md: {name} at {ladder['episodes']} episodes"
    assert f"| {round(ladder['render_s'])} |" in row


@pytest.mark.parametrize("entry", ["workspace-10test", "lighting"])
def test_the_design_protocols_floors_are_the_jsons(entry):
    floors = json.loads(_read(DESIGN_PROTOCOL))[entry]["floors"]
    doc = _read(REPO / "docs" / "design_protocol.md")
    assert floors, f"{entry} has no floors"
    for check in floors:
        (lo, hi), mean = check["paired"]["ci95"], check["paired"]["mean"]
        quoted = f"{mean:+.3f} [{lo:+.3f}, {hi:+.3f}] | {check['verdict']} |"
        name = f"{check['floor']['design']} − {check['floor']['baseline']}"
        row = next((ln for ln in doc.splitlines() if ln.startswith(f"| {name} <")), "")
        assert quoted in row, f"docs/design_protocol.md: {entry}'s floor {name}"
