"""``mincam-render report energy``: a small day end to end, and bad input in one line (exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

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
