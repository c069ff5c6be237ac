"""The design-protocol bench refuses a bad request in one usage line, before any work."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_design_protocol.py"


@pytest.mark.parametrize(
    ("args", "expect"),
    [
        (["--recipes", "head-1024"], "recipes ['head-1024']: give each of"),
        (["--recipes", "tv-0.3,tv-0.3"], "at most once"),
        (["--samples-factor", "1e5"], "--samples-factor 100000.0: need a multiple in (0, 1e4]"),
        (["--recipe-episodes", "0"], "training episodes"),
    ],
)
def test_a_bad_request_is_one_usage_error_and_nothing_is_written(args, expect, tmp_path):
    work, out = tmp_path / "work", tmp_path / "protocol.json"
    cmd = [sys.executable, str(BENCH), "--task", "patches", "--work", str(work), "--out", str(out)]
    res = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=300)
    errors = [line for line in res.stderr.splitlines() if "error:" in line]
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert len(errors) == 1 and expect in errors[0], res.stderr
    assert not work.exists() and not out.exists()


def test_every_task_of_the_bench_is_a_valid_protocol(monkeypatch):
    import importlib.util

    from mincam_render.studies.design_protocol import DesignProtocolConfig

    monkeypatch.syspath_prepend(str(BENCH.parent))
    spec = importlib.util.spec_from_file_location("bench_design_protocol", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    for name, task in bench.TASKS.items():
        cfg = DesignProtocolConfig(**task)
        assert cfg.task, name
        assert {f.design for f in cfg.floors} <= {d.name for d in cfg.ladder_designs}
    traffic = DesignProtocolConfig(**bench.TASKS["traffic"])
    assert traffic.episodes.fps == 30.0 and traffic.references == (bench.MaskReference.PCA,)
