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
        (["--reference-recipe", "block-3"], "recipes ['block-3']: give each of"),
        (["--reference-recipe", "signed"], "reference_recipe 'signed': a diagnostic"),
        (["--pixels", "4,x"], "--pixels '4,x': pixel counts"),
        (["--pixels", "4,4"], "distinct counts"),
        (["--pixels", "2,4"], "floor mincam-8px against baseline-32x32: both must be ladder"),
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


def _bench(name: str, monkeypatch):
    import importlib.util

    monkeypatch.syspath_prepend(str(BENCH.parent))
    spec = importlib.util.spec_from_file_location(name, BENCH.parent / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _tasks_of(comparison) -> dict:
    from mincam_render.core.labels import label_tasks
    from mincam_render.scenes.registry import load_family

    family = load_family(comparison.family, seed=0, num_frames=30, overrides=comparison.overrides)
    return label_tasks(family.labels)


def test_every_task_of_the_bench_is_a_protocol_of_its_familys_task(monkeypatch):
    from mincam_render.studies.design_protocol import DesignProtocolConfig

    bench = _bench("bench_design_protocol", monkeypatch)
    for name, task in bench.TASKS.items():
        cfg = DesignProtocolConfig(**task)
        assert cfg.task in _tasks_of(cfg.episodes), name
    traffic = DesignProtocolConfig(**bench.TASKS["traffic"])
    assert traffic.episodes.fps == 30.0 and traffic.references == (bench.MaskReference.PCA,)


def test_every_family_of_the_fidelity_check_checks_one_of_its_tasks(monkeypatch, tmp_path):
    fidelity = _bench("bench_task_fidelity", monkeypatch)
    for family in fidelity.CHECKED:
        cfg = fidelity.config(tmp_path, ["4x"], family=family)
        tasks = cfg.comparison.tasks
        assert tasks and set(tasks) <= set(_tasks_of(cfg.comparison)), family
        assert [lv.name for lv in cfg.levels] == ["1x", "4x"] and cfg.reference == "4x"


def test_pixels_replace_the_freeform_designs_and_keep_the_box_cameras(monkeypatch):
    import argparse

    bench = _bench("bench_design_protocol", monkeypatch)
    task = bench.TASKS["patches-narrow"]
    designs = bench._with_pixels(argparse.ArgumentParser(), task, "2,4,8")
    assert [d.name for d in designs] == [
        "mincam-2px", "mincam-4px", "mincam-8px",
        "baseline-2x2", "baseline-8x8", "baseline-32x32",
    ]  # fmt: skip
    traffic = bench._with_pixels(argparse.ArgumentParser(), bench.TASKS["traffic"], "4")
    assert [d.name for d in traffic] == ["mincam-4px", "baseline-2x4", "baseline-8x14",
                                         "baseline-16x28"]  # fmt: skip
