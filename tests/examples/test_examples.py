"""The worked examples of docs/your_own_task.md, end to end at a tiny size.

- ``examples/table_objects``: a declarative ``family = "mitsuba"`` description of a
  plain Mitsuba scene (objects on a desk, a desk lamp);
- ``examples/parking_family``: a Python family in its own package, found through
  the ``mincam_render.families`` entry point once installed, or as
  ``module:Class`` from a description when only importable.

Each renders, runs ``pipeline`` (a minimalist camera against a baseline, with
intervals) and exports the minimalist camera's printable masks.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples"
#: what a build leaves in a package's folder (setuptools: build/, an .egg-info with the
#: entry point), never copied: a test's family is found only the way the test means
NOT_SOURCE = shutil.ignore_patterns("build", "*.egg-info", "__pycache__")
#: the pipeline at a tiny size: 2 detectors, 1 spp, 30-frame episodes, 10 steps
TINY = [
    "--detectors", "2", "--pixels", "2", "--baseline-grid", "2x2", "--spp", "1",
    "--train-episodes", "1", "--train-frames", "30", "--val-frames", "30",
    "--test-frames", "30", "--test-episodes", "2", "--seeds", "2", "--steps", "10",
    "--workers", "0",
]  # fmt: skip


def _invoke(*args: str) -> str:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res.output


def _check_comparison(out: Path) -> None:
    """Both designs tested with intervals over seeds and episodes, and the trivial predictor."""
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["designs"]) == {"mincam-2px", "baseline-2x2"}
    for design in metrics["designs"].values():
        lo, hi = design["error"]["ci95"]
        assert lo <= design["error"]["mean"] <= hi and len(design["error_per_seed"]) == 2
    assert "mincam-2px - baseline-2x2" in metrics["paired"]
    assert metrics["trivial"]["error"]["mean"] >= 0


def _check_masks(run: Path, out: Path, task: str) -> None:
    _invoke("export-masks", run, "--task", task, "--out", out)
    sidecar = json.loads((out / task / "masks.json").read_text())
    assert sidecar["masks"] == 2 and len(sidecar["files"]["png"]) == 2
    for name in ("print_sheet.svg", "print_sheet.pdf", "masks.exr"):
        assert (out / task / name).stat().st_size > 0


def test_the_declarative_example_renders_compares_and_exports(tmp_path, variant):
    task = EXAMPLES / "table_objects" / "table.toml"
    _invoke("render", task, "--frames", "6", "--shard-frames", "3", "--spp", "2",
            "--detectors", "2", "--workers", "0", "--out", tmp_path / "ds")  # fmt: skip
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert manifest["complete"] and manifest["family"]["name"] == "mitsuba"
    assert [s["name"] for s in manifest["label_specs"]] == ["objects", "lamp"]
    output = _invoke("pipeline", "--family", task, *TINY, "--out", tmp_path / "main")
    assert "trivial" in output
    _check_comparison(tmp_path / "main")
    _check_masks(
        tmp_path / "main" / "runs" / "objects" / "mincam-2px-seed0", tmp_path / "masks", "objects"
    )


@pytest.fixture(scope="module")
def parking_installed(tmp_path_factory):
    """examples/parking_family installed (not editable) into a folder put on sys.path."""
    work = tmp_path_factory.mktemp("parking")
    # built from a copy: setuptools leaves build/ and an .egg-info in the folder it builds
    source = shutil.copytree(EXAMPLES / "parking_family", work / "source",
                             ignore=NOT_SOURCE)  # fmt: skip
    site = work / "site"
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q", "install"]
    run = subprocess.run(
        [*pip, "--no-deps", "--no-build-isolation", "--target", str(site), str(source)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    sys.path.insert(0, str(site))
    yield site
    sys.path.remove(str(site))
    for name in [m for m in sys.modules if m.startswith("parking_family")]:
        del sys.modules[name]


def test_an_installed_family_is_found_by_its_entry_point(parking_installed, tmp_path, variant):
    _invoke("render", "parking", "--frames", "6", "--spp", "1", "--detectors", "2",
            "--workers", "0", "--out", tmp_path / "ds")  # fmt: skip
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert manifest["job"]["family"]["name"] == "parking"  # workers find it by name
    assert manifest["label_specs"][0]["element_names"] == [f"space {k}" for k in range(1, 5)]
    description = EXAMPLES / "parking_family" / "parking.toml"
    _invoke("pipeline", "--family", description, *TINY, "--out", tmp_path / "main")
    _check_comparison(tmp_path / "main")
    _check_masks(
        tmp_path / "main" / "runs" / "taken" / "mincam-2px-seed0", tmp_path / "masks", "taken"
    )


def test_a_description_names_the_family_class_of_an_uninstalled_package(tmp_path, variant):
    """No entry point: ``family = "parking_family.family:ParkingFamily"``, on PYTHONPATH only."""
    task = tmp_path / "parking.toml"
    text = (EXAMPLES / "parking_family" / "parking.toml").read_text()
    task.write_text(
        text.replace('family = "parking"', 'family = "parking_family.family:ParkingFamily"')
    )
    # a copy without what `pip install examples/parking_family` leaves in the folder
    source = shutil.copytree(EXAMPLES / "parking_family", tmp_path / "source",
                             ignore=NOT_SOURCE)  # fmt: skip
    env = dict(os.environ, PYTHONPATH=str(source))
    cli = [sys.executable, "-m", "mincam_render.cli.main"]
    for args in (
        ["pipeline", "--family", str(task), *TINY, "--out", "main"],
        ["export-masks", "main/runs/taken/mincam-2px-seed0", "--task", "taken", "--out", "masks"],
    ):
        run = subprocess.run([*cli, *args], cwd=tmp_path, env=env, capture_output=True,
                             text=True, check=False)  # fmt: skip
        assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    manifest = json.loads(
        (tmp_path / "main" / "episodes" / "train-0" / "manifest.json").read_text()
    )
    assert manifest["job"]["family"]["name"] == "parking_family.family:ParkingFamily"
    _check_comparison(tmp_path / "main")
    assert (tmp_path / "masks" / "taken" / "print_sheet.svg").is_file()


def test_a_bad_description_stops_the_pipeline_before_anything_is_written(tmp_path, variant):
    text = (EXAMPLES / "table_objects" / "table.toml").read_text()
    xml = EXAMPLES / "table_objects" / "table.xml"
    task = tmp_path / "task.toml"
    task.write_text(text.replace('scene = "table.xml"', f'scene = "{xml}"')
                    .replace('id = "mug"', 'id = "cup"'))  # fmt: skip
    res = CliRunner().invoke(main, ["pipeline", "--family", str(task), *TINY,
                                    "--out", str(tmp_path / "main")])  # fmt: skip
    assert res.exit_code == 2
    (line,) = res.output.strip().splitlines()
    assert "movers[3].id = 'cup': no shape with this id in table.xml" in line
    assert not (tmp_path / "main").exists()
