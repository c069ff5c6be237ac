"""A comparison's training runs in this process, in local workers and as Ray tasks: same runs."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from mincam_render.cli.main import main
from mincam_render.data import run_dispatch
from mincam_render.data.run_dispatch import TrainingError, check_executor, run_files
from mincam_render.learn.train_config import TrainConfig
from mincam_render.studies.comparison.runs import (
    ComparisonRun,
    comparison_tasks,
    relocate_run,
    train_design_run,
    train_runs,
)
from mincam_render.studies.comparison.study import (
    ComparisonConfig,
    Design,
    comparison_splits,
    render_episodes,
)

QUICK = {"spp": 2, "max_depth": 0, "shared_render": False, "differential": False}
#: 2 designs x 2 seeds; the ablation (masks without the detector model, then a head
#: with it, in a nested run) is the design whose run.json names another run's path
CFG = ComparisonConfig(
    family="patches",
    train_episodes=1,
    train_frames=40,
    val_frames=30,
    test_frames=30,
    test_episodes=2,
    seeds=2,
    designs=(Design(pixels=2, sensor_model=False), Design(grid=(2, 2))),
    train=TrainConfig(max_steps=20, eval_every=10),
    fidelity=QUICK,
)
#: What must not depend on where a run trained (its wall times do).
SAME = ("model", "steps", "best_step", "best_val_loss", "stopped_early", "test", "episodes")


@pytest.fixture(scope="module")
def rendered_splits(tmp_path_factory, variant):
    data = render_episodes(CFG, tmp_path_factory.mktemp("episodes"), workers=0, progress=False)
    return comparison_splits(data)


@pytest.fixture(scope="module")
def sequential(rendered_splits, tmp_path_factory):
    """``(out, runs)``: every run trained in this process, as comparisons always did."""
    out = tmp_path_factory.mktemp("sequential")
    return out, _one_task(train_runs(CFG, rendered_splits, out, progress=False))


def _one_task(runs: dict) -> dict:
    """``{design: [runs]}`` of a comparison of a single-task family (patches)."""
    (by_design,) = runs.values()
    return by_design


def _figures(runs: dict) -> dict:
    """Each run's figures and validation curve (and its masks' run's), without times and paths."""

    def of(typed: ComparisonRun) -> dict:
        run = typed.as_json()
        curve = [(h["step"], h["train_loss"], h["val_loss"]) for h in run["history"]]
        masks = run.get("mask_run", {})
        return (
            {k: run[k] for k in SAME}
            | {"curve": curve}
            | {k: v for k, v in masks.items() if k not in ("run_dir", "train_wall_time_s")}
        )

    return {name: [of(r) for r in rs] for name, rs in runs.items()}


def _layout(out: Path) -> dict[str, bytes | None]:
    """The files below ``out/runs``: run.json contents with ``out`` cut; others by name only."""
    files = {}
    for p in sorted((out / "runs").rglob("*")):
        if p.is_file():
            rel = p.relative_to(out).as_posix()
            if p.name.startswith("events.out.tfevents"):
                rel = rel.rsplit("/", 1)[0] + "/events"  # named after host, pid and time
            files[rel] = p.read_bytes().replace(str(out).encode(), b"OUT") if (
                p.name == "run.json") else None  # fmt: skip
    return files


def test_local_workers_train_every_run_like_this_process(rendered_splits, sequential, tmp_path):
    """Worker processes train on their own copy of the splits, 1 torch thread each here."""
    out, runs = sequential
    pooled = _one_task(train_runs(CFG, rendered_splits, tmp_path, train_workers=2, progress=False))
    assert _figures(pooled) == _figures(runs)  # bit for bit
    assert _layout(tmp_path) == _layout(out)
    head = pooled["mincam-2px-nosensor"][0]
    assert head.run_dir == str(tmp_path / "runs" / "mincam-2px-nosensor-seed0" / "head-with-sensor")


def test_a_ray_task_trains_elsewhere_and_the_driver_writes_the_run_where_this_process_does(
    rendered_splits, sequential, tmp_path
):
    """What a Ray task and the driver do, without Ray: no file system shared but the bytes."""
    out, runs = sequential
    task = comparison_tasks(CFG)[0]  # the ablation: its head's run.json names its masks' run
    assert task.name == "mincam-2px-nosensor-seed0"
    returned = run_dispatch._ray_train(train_design_run, rendered_splits, task, {})
    worker_runs = returned.worker_runs
    assert not Path(worker_runs).exists()  # the task's directory is gone with the task
    assert any(worker_runs.encode() in data for data in returned.files.values())
    written = run_dispatch._write_run(tmp_path / "runs", task, returned, relocate=relocate_run)
    assert _figures({"d": [written]}) == _figures({"d": [runs["mincam-2px-nosensor"][0]]})
    run = tmp_path / "runs" / task.name
    assert written.run_dir == str(run / "head-with-sensor")
    assert written.mask_run is not None and written.mask_run.run_dir == str(run)
    assert json.loads((run / "head-with-sensor" / "run.json").read_text())[
        "frozen_masks_from"] == str(run)  # fmt: skip
    mine = {k: v for k, v in _layout(tmp_path).items() if task.name in k}
    assert mine == {k: v for k, v in _layout(out).items() if task.name in k}
    assert not any(worker_runs.encode() in p.read_bytes() for p in run.rglob("*") if p.is_file())


def test_finished_runs_are_read_back_and_a_killed_one_resumes_from_its_shipped_checkpoint(
    rendered_splits, sequential, tmp_path, monkeypatch
):
    out, runs = sequential
    shutil.copytree(out / "runs", tmp_path / "runs")
    unfinished = tmp_path / "runs" / "baseline-2x2-seed1"
    (unfinished / "metrics.json").unlink()  # killed after its last checkpoint
    dispatched = []

    def pool(workers, train, tasks, splits, runs_dir, done):  # where the workers would start
        dispatched.extend(t.name for t in tasks)
        for t in tasks:  # what a Ray task does with the run's files
            returned = run_dispatch._ray_train(train, splits, t, run_files(runs_dir / t.name))
            done(t, run_dispatch._write_run(runs_dir, t, returned, relocate=relocate_run))

    monkeypatch.setattr(run_dispatch, "_on_pool", pool)
    again = _one_task(train_runs(CFG, rendered_splits, tmp_path, train_workers=2, progress=False))
    assert dispatched == ["baseline-2x2-seed1"]
    assert _figures(again) == _figures(runs)
    # resumed at its end, not trained again: training would have saved new checkpoints
    # (they record the training time); the task shipped the old one back
    name = "baseline-2x2-seed1/checkpoint.pt"
    assert (unfinished.parent / name).read_bytes() == (out / "runs" / name).read_bytes()


def test_ray_tasks_train_every_run_like_this_process(rendered_splits, sequential, tmp_path):
    """16 s on 2 loaded cores (a local Ray cluster started, the package shipped to it)."""
    pytest.importorskip("ray")
    out, runs = sequential
    on_ray = _one_task(
        train_runs(CFG, rendered_splits, tmp_path, ray_address="local", progress=False)
    )
    assert _figures(on_ray) == _figures(runs)
    assert _layout(tmp_path) == _layout(out)


def _workers_of(pid: int) -> list[int]:
    """Spawned multiprocessing children of process ``pid`` (not its resource tracker)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes()
        except (OSError, ValueError):
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid and b"spawn_main" in cmdline:
            found.append(int(entry.name))
    return found


#: Steps of the runs a worker is killed in: long enough to be killed in the middle.
STEPS = 400


@pytest.mark.slow
def test_a_killed_worker_names_its_run_keeps_finished_runs_and_the_rerun_resumes(
    rendered_splits, tmp_path
):
    """About 60 s: seed 0 trained first, then seed 1 on 2 workers, one of them killed."""
    import dataclasses

    long = dataclasses.replace(
        CFG, train=TrainConfig(max_steps=STEPS, eval_every=10, patience=1000)
    )
    first = dataclasses.replace(long, seeds=1)
    _one_task(train_runs(first, rendered_splits, tmp_path, progress=False))
    # a finished run read back rewrites its run.json and metrics.json (same contents);
    # its checkpoint is written only by training
    kept = {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").rglob("checkpoint.pt")}
    failure: list[BaseException] = []

    def run() -> None:
        try:
            _one_task(train_runs(long, rendered_splits, tmp_path, train_workers=2, progress=False))
        except BaseException as err:  # the main thread checks it
            failure.append(err)

    thread = threading.Thread(target=run)
    thread.start()
    deadline = time.monotonic() + 120
    while not any((tmp_path / "runs").glob("*-seed1/checkpoint.pt")):
        assert time.monotonic() < deadline and thread.is_alive(), failure
        time.sleep(0.1)
    os.kill(_workers_of(os.getpid())[0], signal.SIGKILL)
    thread.join(timeout=120)
    (err,) = failure
    assert isinstance(err, TrainingError)
    assert "exit code -9) while running task" in str(err) and "-seed1" in str(err)
    assert "finished runs are kept" in str(err) and "\n" not in str(err)
    assert {p: p.stat().st_mtime_ns for p in kept} == kept  # seed 0 not trained again
    again = _one_task(train_runs(long, rendered_splits, tmp_path, train_workers=2, progress=False))
    assert {p: p.stat().st_mtime_ns for p in kept} == kept  # read back, not trained again
    assert all(r.metrics.steps == STEPS for rs in again.values() for r in rs)


def test_bad_executor_values_are_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="train_workers = 0: allowed an integer >= 1"):
        check_executor(0, None)
    with pytest.raises(ValueError, match="give one of them"):
        check_executor(2, "local")
    with pytest.raises(ValueError, match="give an address"):
        check_executor(1, " ")
    base = ["pipeline", "--family", "patches", "--out", str(tmp_path / "p")]
    for args, message in [
        (["--train-workers", "0"], "--train-workers"),
        (["--train-workers", "2", "--ray", "local"], "give one of them"),
        (["--ray", ""], "give an address"),
    ]:
        res = CliRunner().invoke(main, [*base, *args])
        assert res.exit_code == 2 and message in res.output, res.output
        assert "Traceback" not in res.output
    assert not (tmp_path / "p").exists()


def test_ray_without_the_extra_is_one_line_naming_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    args = ["study", "--family", "patches", "--pixels", "1,2", "--reference-pixels", "2",
            "--ray", "local", "--out", str(tmp_path / "s")]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    (line,) = [ln for ln in res.output.splitlines() if ln.startswith("Error:")]
    assert "mincam_render[ray]" in line
    assert not (tmp_path / "s").exists()


def test_every_run_has_the_seed_it_has_in_this_process():
    tasks = comparison_tasks(CFG)
    assert [t.name for t in tasks] == [
        "mincam-2px-nosensor-seed0", "mincam-2px-nosensor-seed1",
        "baseline-2x2-seed0", "baseline-2x2-seed1",
    ]  # fmt: skip
    assert len({t.config.seed for t in tasks}) == 4
