r"""Designs that survive the workshop: nominal against robust training under perturbations.

For one task (``--task``: workspace people count, lighting per-light state on
``scenes/lighting_toggling.toml``, or traffic speed per direction) and an
8-pixel minimalist camera, on independent episodes at the main job's default
sizes (``ComparisonConfig()``: 2 training episodes of 1,200 frames, 1 validation
episode of 600, 3 test episodes of 600, 2 fps; traffic: :data:`TASKS`), trains ``--seeds`` nominal designs and as many robust-trained
ones (``TrainConfig.perturbation = PerturbationModel()``, one built camera per
batch, early stopping on the loss under ``robust_validation_draws`` fixed built
cameras), same recipe otherwise. Then, for every run, the error increase under
each perturbation alone (camera pose included) and all at once at 0, 0.5, 1, 1.5
and 2 x the default ranges, ``--draws`` built cameras per level (the same draws
for every run) (:func:`mincam_render.studies.robustness.versus.compare_kinds`);
runs of one kind are pooled (intervals resample training seeds and draws), and
tolerances for a <= 10 % increase are derived.

Writes the task's entry of ``benchmarks/results/robustness.json`` (other tasks'
entries are kept: machine, git revision, sizes, per-design curves with CIs,
tolerances, specs, per-run nominal errors, the done-when verdict),
``robustness_<task>.png``, and the HTML report into ``WORK/report``. With
``--keep-masks DIR``, the best robust run's masks (lowest loss under the fixed
built cameras of robust validation, each run its own) go to
``DIR/<task>/robust-mincam-8px`` (default entry only) in
the format of ``masks/``, their sidecar holding the robust design's error as
designed and under the default mix, its specs and the verdict.

Everything resumes: episodes, runs and per-run curves (``robustness.json`` in
each run directory) found on disk are kept.

Usage (from a clean tree; the episodes are those `mincam-render pipeline` renders):
    python benchmarks/bench_robustness.py --task workspace --work /work/robust/workspace \
        [--seeds 3] [--draws 20] [--test-episodes 3] [--workers 2] [--keep-masks masks]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import shutil
import sys
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).parent))
from provenance import machine, write_result  # noqa: E402

from mincam_render.core.package_data import shipped_path  # noqa: E402
from mincam_render.learn import train as tr  # noqa: E402
from mincam_render.learn.train_config import GAIN_AUGMENTATION_20  # noqa: E402
from mincam_render.studies.comparison.config import ComparisonConfig, Protocol  # noqa: E402
from mincam_render.studies.comparison.study import render_episodes  # noqa: E402
from mincam_render.studies.robustness import write_report  # noqa: E402
from mincam_render.studies.robustness.config import RobustnessConfig  # noqa: E402
from mincam_render.studies.robustness.versus import (  # noqa: E402
    KINDS,
    PIXELS,
    compare_kinds,
    config_json,
    keep_robust_masks,
    summary,
)

RESULTS = Path(__file__).parent / "results"
#: ``ComparisonConfig`` fields of each task (the main job's sizes otherwise).
#: Lighting uses the toggling room of ``study_lighting`` so that each test episode
#: visits most of the 32 light states. Traffic is temporal: 30 fps (a window of
#: 30 frames is 1 s), one training episode of 4 minutes, validation and test
#: episodes of 1 minute each.
#: Every task as measured: one camera for every label, one validation episode,
#: the +-20 % gain augmentation and 3,000 steps at most (the comparison's and the
#: recipe's defaults changed since).
AS_MEASURED: dict[str, Any] = {
    "protocol": Protocol.JOINT,
    "val_episodes": 1,
    "train": tr.TrainConfig(max_steps=3000, gain_range=GAIN_AUGMENTATION_20),
}
TASKS: dict[str, dict[str, Any]] = {
    "workspace": {"family": "workspace"},
    "lighting": {"family": str(shipped_path("lighting_toggling.toml"))},
    "traffic": {
        "family": "traffic",
        "fps": 30.0,
        "train_episodes": 1,
        "train_frames": 7200,
        "val_frames": 1800,
        "test_frames": 1800,
    },
}


def task_entry(
    cfg: ComparisonConfig,
    args: argparse.Namespace,
    designs: dict,
    records: dict,
    text: str,
    trivial: float,
) -> dict[str, Any]:
    """The task's block of ``robustness.json``: sizes, recipe, pooled designs, runs, verdict."""
    sizes = {
        "family": cfg.family,
        "pixels": PIXELS,
        "fps": cfg.fps,
        "train_episodes": cfg.train_episodes,
        "train_frames": cfg.train_frames,
        "val_frames": cfg.val_frames,
        "test_episodes": cfg.test_episodes,
        "test_frames": cfg.test_frames,
        "seeds": args.seeds,
        "draws": args.draws,
        "note": "modest sizes (the main job's defaults)",
    }
    return {
        "machine": machine(),
        "sizes": sizes,
        "train_config": dataclasses.asdict(cfg.train),
        "designs": {k: summary(d) for k, d in designs.items()},
        "runs": {
            k: [{"run": r.name, "nominal_error": r.nominal_error} for r in records[k]]
            for k in KINDS
        },
        "trivial_error": trivial,
        "verdict": text,
    }


def merged_result(out: Path, task: str, entry: dict, rcfg: RobustnessConfig) -> dict[str, Any]:
    """``out``'s results with ``task``'s entry replaced (other tasks kept if measured alike).

    An entry whose figures equal the old one's (re-read from the same runs, e.g.
    to keep masks) keeps the old machine block: the machine that measured them.
    """
    tasks: dict[str, Any] = {}
    if out.is_file():
        old = json.loads(out.read_text())
        if old.get("robustness_config") == config_json(rcfg):
            tasks = old.get("tasks", {})
    before = tasks.get(task, {})
    if before.get("designs") == json.loads(json.dumps(entry["designs"], default=str)):
        entry = entry | {"machine": before["machine"]}
    return {
        "benchmark": "bench_robustness",
        "robustness_config": dataclasses.asdict(rcfg),
        "tasks": tasks | {task: entry},
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", choices=sorted(TASKS), default="workspace")
    ap.add_argument("--work", type=Path, required=True, help="episodes, runs and report go here")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--test-episodes", type=int, default=3, help="independent test episodes (default 3)"
    )
    ap.add_argument(
        "--max-steps", type=int, default=None, help="training budget (default: the main job's)"
    )
    ap.add_argument(
        "--entry", default=None, help="name of the results entry (default: the task's name)"
    )
    ap.add_argument("--out", type=Path, default=RESULTS / "robustness.json")
    ap.add_argument(
        "--keep-masks",
        type=Path,
        default=None,
        help="also keep the best robust design's masks in KEEP_MASKS/<task>/robust-mincam-8px",
    )
    args = ap.parse_args()
    if args.keep_masks is not None and args.entry is not None:
        ap.error("--keep-masks keeps the default entry's design; drop --entry")
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    cfg = ComparisonConfig(**TASKS[args.task], **AS_MEASURED, test_episodes=args.test_episodes)
    if args.max_steps is not None:
        cfg = dataclasses.replace(
            cfg, train=dataclasses.replace(cfg.train, max_steps=args.max_steps)
        )
    entry_name = args.entry or args.task
    episodes = render_episodes(cfg, args.work, workers=args.workers, progress=False)
    runs_dir = args.work / ("runs" if args.entry is None else f"runs-{args.entry}")
    rcfg = RobustnessConfig(draws=args.draws)
    res = compare_kinds(cfg, episodes, runs_dir, rcfg, seeds=args.seeds, name=entry_name,
                        report=print)  # fmt: skip
    designs, text = res.designs, res.verdict
    print(text)
    for d in designs.values():
        print(f"{d.name}: nominal error {d.nominal_error:.4f}")
        for c in d.curves.values():
            print(f"  {c.spec}")
    paths = write_report(list(designs.values()), args.work / "report", notes=[text])
    entry = task_entry(cfg, args, designs, res.records, text, res.trivial)
    if args.keep_masks is not None:
        out = args.keep_masks / args.task / f"robust-mincam-{PIXELS}px"
        keep_robust_masks(res.runs["robust"], episodes, entry, args.task, out)
        entry["masks"] = str(out)
    write_result(args.out, merged_result(args.out, entry_name, entry, rcfg))
    png = args.out.with_name(f"{args.out.stem}_{entry_name}.png")
    shutil.copyfile(paths["png"], png)
    print(f"wrote {png.name} and {paths['html']}")


if __name__ == "__main__":
    main()
