r"""Fidelity in task units: a plan judged by the task figure, its error by the label signal.

Usage::

    python benchmarks/bench_task_fidelity.py --work /data/fidelity \
        [--sections render,check,plans] [--levels 1x,0.25x,4x,16x] [--lock /tmp/mincam-cpu.lock]
        [--one-x /data/episodes/ws8] [--families workspace,lighting,patches,traffic]

``check`` (workspace): the plan's episodes (2 training episodes of 1,200 frames at
2 fps, 4 validation and 3 test episodes of 600 frames, the people count) at every
level of :data:`LEVELS` (samples of frames and backgrounds times a factor, path
depth 16; per-window or per-frame seeds of ``X - C``), count-only cameras
(mincam 2 and 8 px, baselines 8x8 and 32x32, 3 seeds, no gain augmentation)
trained *and* tested at each level; every level against the reference (16x):
accepted when every design's test RMSE moves by less than a quarter of its 95 %
half-width; each level's render error against the label signal on the test
episodes and its autocorrelation at lags of one frame and one window.
``render`` renders the levels' episodes first (``WORK/ws-<level>``, one episode
per acquisition of ``--lock``; the plan's own episodes are copied from
``--one-x`` when given). ``plans``: each family's plan measured by the planner
(every figure relative to the total and to the label signal).

Writes ``benchmarks/results/task_fidelity.json`` (per family: label-signal RMS,
render noise at the plan for random masks and the finest box pixel, their
ratio, the chosen target, the noise's autocorrelation, the check per design
and level, verdicts; a ``machine`` block), ``task_fidelity_workspace.md`` and
``task_fidelity_workspace.png`` (measurement error and task error against
render seconds per frame). Training runs are kept in ``WORK/runs`` (resumable).
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import json
import logging
import shutil
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from provenance import machine, write_result

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mincam_render.render.differential import DifferenceSeeds  # noqa: E402
from mincam_render.studies.task_fidelity import (  # noqa: E402
    SampleLevel,
    TaskFidelityConfig,
    render_level,
    run,
    write_report,
)

RESULTS = Path(__file__).parent / "results"
SCENES = Path(__file__).resolve().parents[1] / "scenes"
#: ``(name, samples factor, path depth (None: the plan's), seeds)`` of each level.
LEVELS = (
    ("1x", 1.0, None, DifferenceSeeds.WINDOW),
    ("0.0625x", 0.0625, 16, DifferenceSeeds.WINDOW),
    ("0.25x", 0.25, 16, DifferenceSeeds.WINDOW),
    ("4x", 4.0, 16, DifferenceSeeds.WINDOW),
    ("16x", 16.0, 16, DifferenceSeeds.WINDOW),
    ("1x-frame-seeds", 1.0, None, DifferenceSeeds.FRAME),
    ("0.25x-frame-seeds", 0.25, 16, DifferenceSeeds.FRAME),
)
#: The plan each family is measured with for ``plans``: its study's episode length.
PLAN_REQUESTS: dict[str, dict[str, Any]] = {
    "workspace": {"family": "workspace", "num_frames": 1200, "overrides": {"fps": 2.0}},
    "lighting": {"family": str(SCENES / "lighting_toggling.toml"), "num_frames": 3600},
    "patches": {
        "family": "patches",
        "num_frames": 3000,
        "overrides": {"camera": {"detectors": 16}},
    },
    "traffic": {"family": "traffic", "num_frames": 1800},
}


def config(work: Path, names: list[str]) -> TaskFidelityConfig:
    """The workspace check over the named levels (``1x`` always), episodes under ``work``."""
    levels = []
    for name, factor, depth, seeds in LEVELS:
        if name != "1x" and name not in names:
            continue
        levels.append(
            SampleLevel(
                name=name,
                factor=factor,
                episodes=work / f"ws-{name}",
                max_depth=depth,
                difference_seeds=seeds,
                planned=name == "1x",
            )
        )
    kept = [lv.name for lv in levels]
    reference = "16x" if "16x" in kept else "4x"
    second = "4x" if reference == "16x" and "4x" in kept else None
    return TaskFidelityConfig(levels=tuple(levels), reference=reference, second_reference=second)


@contextlib.contextmanager
def holding(lock: Path | None) -> Iterator[None]:
    """Hold an exclusive lock on ``lock`` (a machine's CPUs) while inside; nothing if None."""
    if lock is None:
        yield
        return
    with open(lock, "w") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def render(cfg: TaskFidelityConfig, one_x: Path | None, lock: Path | None) -> None:
    """Copy the plan's episodes from ``one_x`` (if given), render every other level."""
    for level in cfg.levels:
        if level.planned and one_x is not None:
            for name in ("train", "val", "test"):
                for src in sorted(one_x.glob(f"{name}-*")):
                    dst = level.episodes / src.name
                    if src.is_dir() and not dst.exists():
                        shutil.copytree(src, dst)
        render_level(cfg, level, hold=lambda: holding(lock))


def summary(result: dict[str, Any], cfg: TaskFidelityConfig) -> dict[str, Any]:
    """The done-when figures of the check: signal, noise at the plan, ratio, lags, verdicts."""
    plan = next(lv for lv in result["levels"] if lv["level"] == cfg.plan.name)
    noise = plan["noise"]
    chosen = result["chosen"]
    chosen_noise = next((lv["noise"] for lv in result["levels"] if lv["level"] == chosen), None)
    kinds = {"random_masks": "random_masks", "finest_box": "box_1"}
    return {
        "label_signal_rms_w": {k: noise["signal_rms_w"][v] for k, v in kinds.items()},
        "render_noise_rms_at_plan_w": {k: noise["error_rms_w"][v] for k, v in kinds.items()},
        "noise_over_signal_at_plan": {
            k: noise["error_rms_w"][v] / noise["signal_rms_w"][v] for k, v in kinds.items()
        },
        "noise_autocorrelation_at_plan": noise["autocorrelation"]["random_masks"],
        "window_frames": noise["window_frames"],
        "chosen_level": chosen,
        "chosen_signal_target_error": None
        if chosen_noise is None
        else chosen_noise["error_rms_w"]["random_masks"]
        / chosen_noise["signal_rms_w"]["random_masks"],
        "task_check": {
            lv["level"]: {
                d: {"error": f["error"], "ci95": f["ci95"]} for d, f in lv["designs"].items()
            }
            for lv in result["levels"]
        },
        "verdicts": result["verdicts"],
    }


def plans(families: list[str], lock: Path | None) -> dict[str, Any]:
    """Each family's plan, measured afresh, with its figures in both metrics."""
    from mincam_render.data.render_job import RenderRequest, plan_render

    out = {}
    for name in families:
        with holding(lock):
            manifest = plan_render(RenderRequest(**PLAN_REQUESTS[name]), use_cache=False)
        decisions = manifest["fidelity"]
        out[name] = {
            "request": PLAN_REQUESTS[name],
            "settings": manifest["job"]["render"],
            "achieved": decisions.get("achieved"),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="episodes and runs (resumable)")
    ap.add_argument("--sections", default="render,check,plans")
    ap.add_argument("--levels", default=",".join(name for name, *_ in LEVELS))
    ap.add_argument("--one-x", type=Path, default=None, help="the plan's rendered episodes")
    ap.add_argument("--lock", type=Path, default=None, help="a CPU lock held per episode")
    ap.add_argument("--families", default=",".join(PLAN_REQUESTS))
    ap.add_argument("--train-workers", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "task_fidelity.json")
    args = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    cfg = config(args.work, args.levels.split(","))
    merged = json.loads(args.out.read_text()) if args.out.is_file() else {}
    if "render" in sections:
        render(cfg, args.one_x, args.lock)
    if "check" in sections:
        result = run(cfg, args.work / "runs", train_workers=args.train_workers,
                     hold=lambda: holding(args.lock), progress=True)  # fmt: skip
        paths = write_report(result, args.out.parent, stem=f"{args.out.stem}_workspace")
        print(paths["md"].read_text())
        entry = result.as_json()
        merged.setdefault("workspace", {})
        merged["workspace"] |= {"check": entry, **summary(entry, cfg)}
    if "plans" in sections:
        for name, record in plans(args.families.split(","), args.lock).items():
            merged.setdefault(name, {})["plan"] = record
    merged["machine"] = machine()
    merged["command"] = " ".join(["python", *sys.argv])
    write_result(args.out, merged)


if __name__ == "__main__":
    main()
