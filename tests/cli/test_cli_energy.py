"""``mincam-render report energy``: a small day end to end, and bad input in one line (exit 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from support import REPO

from mincam_render.cli.main import main

#: A small day: 3 pixel counts, daylight every 2 h, a few samples (seconds, not minutes).
SMALL = """
max_pixels = 3
[schedule]
step_min = 120.0
[render]
spp = 16
batches = 2
max_depth = 2
"""


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("energy")
    (tmp / "energy.toml").write_text(SMALL)
    out = tmp / "out"
    res = CliRunner().invoke(
        main,
        [
            "report",
            "energy",
            "--family",
            "workspace",
            "--config",
            str(tmp / "energy.toml"),
            "--out",
            str(out),
        ],
    )
    return res, out


def test_small_day_writes_json_html_png(variant, small_run):
    res, out = small_run
    assert res.exit_code == 0, res.output
    assert "lx on the panel" in res.output
    result = json.loads((out / "energy.json").read_text())
    fam = result["families"]["workspace"]
    assert len(fam["hours"]) == 12 and len(fam["sustainable_fps"]) == 3
    trace = fam["storage_trace"]
    assert abs(trace["balance_j"]) <= 1e-9 * trace["harvested_j"]
    # more pixels never run longer nor faster
    hours = [fam["hours_at_fps"][str(k)] for k in range(1, 4)]
    assert all(a >= b for a, b in zip(hours, hours[1:], strict=False))
    fps = np.array([fam["sustainable_fps"][str(k)] for k in range(1, 4)])
    assert np.all(np.diff(fps, axis=0) <= 0)
    # daylight through the window at noon, nothing at midnight with the lights off
    assert fam["lux"][6] > 10 * max(fam["lux"][0], 1e-9)
    assert result["config"]["render"]["spp"] == 16
    assert (out / "energy.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "Self-powered budget" in (out / "energy.html").read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--family", "nowhere"], "nowhere"),
        (["--family", "patches"], "indoor"),
        (["--spp", "0"], "spp"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(tmp_path, args, message):
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["report", "energy", *args, "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("[panel]\narea_m2 = -0.01\n", "panel.area_m2"),
        ("[panel]\nefficiency = 1.5\n", "panel.efficiency"),
        ("[storage]\nbrownout_voltage_v = 3.6\n", "brownout_voltage_v"),
    ],
)
def test_bad_description_exits_2_naming_the_field(tmp_path, text, field):
    path = tmp_path / "energy.toml"
    path.write_text(text)
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["report", "energy", "--config", str(path), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert field in res.output and len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def _shape(obj):
    """A JSON document's keys and kinds: pixel-count keys and list items folded into one."""
    if isinstance(obj, dict):
        keys = sorted(obj, key=lambda k: (not k.isdigit(), k))
        if keys and all(k.isdigit() for k in keys):
            return {"<pixels>": _shape(obj[keys[0]])}
        return {k: _shape(v) for k, v in obj.items()}
    if isinstance(obj, list):
        kinds = [_shape(v) for v in obj if v is not None]
        return [kinds[0]] if kinds else []
    return "number" if isinstance(obj, int | float) and not isinstance(obj, bool) else type(obj)


def test_energy_json_reads_back_and_keeps_the_kept_schema(variant, small_run, tmp_path):
    """``energy.json`` is the whole result (read back, it writes the same file), and has the
    schema of the kept ``benchmarks/results/energy.json``, written before the study's shape."""
    from mincam_render.studies.energy import EnergyResult, write_report

    _, out = small_run
    written = json.loads((out / "energy.json").read_text())
    result = EnergyResult.from_json(written)
    assert EnergyResult.from_json(result.as_json()) == result
    paths = write_report(result, tmp_path)
    assert json.loads(Path(paths["json"]).read_text()) == written
    # the report is every file of the run but the rendered light it keeps to resume
    assert {Path(p).name for p in paths.values()} | {"panel_light"} == {
        p.name for p in out.iterdir()
    }
    kept = json.loads((REPO / "benchmarks/results/energy.json").read_text())["result"]
    assert EnergyResult.from_json(kept).as_json() == kept
    assert _shape(written["config"]) == _shape(kept["config"])
    assert _shape(written["threshold"]) == _shape(kept["threshold"])
    assert _shape(written["families"]["workspace"]) == _shape(kept["families"]["workspace"])
    # a match from the paper's table (no study table given here; lighting's in the kept run)
    assert kept["comparisons"]["lighting"]["match"]["source"].startswith("paper")
    assert _shape(written["comparisons"]["workspace"]) == _shape(kept["comparisons"]["lighting"])
