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
for every run) (:func:`mincam_render.analysis.robustness.robustness_curves`);
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

from mincam_render.analysis.comparison import (  # noqa: E402
    episode_record,
    keep_run_masks,
    render_episodes,
    trivial_metrics,
)
from mincam_render.analysis.comparison_config import ComparisonConfig, Protocol  # noqa: E402
from mincam_render.analysis.robustness import (  # noqa: E402
    MIX,
    RobustnessConfig,
    pool_curves,
    pool_episode_metrics,
    robustness_curves,
)
from mincam_render.analysis.robustness_report import write_robustness_report  # noqa: E402
from mincam_render.core import strict_json
from mincam_render.core.package_data import shipped_path  # noqa: E402
from mincam_render.core.seeds import stream_seed  # noqa: E402
from mincam_render.learn import train as tr  # noqa: E402
from mincam_render.learn.train_config import GAIN_AUGMENTATION_20  # noqa: E402
from mincam_render.optics.perturbation import PerturbationModel  # noqa: E402

RESULTS = Path(__file__).parent / "results"
PIXELS = 8
KINDS = ("nominal", "robust")
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


def in_memory(data: tr.TrainingData) -> tr.TrainingData:
    """A test episode as float32 watts in memory: evaluated hundreds of times."""
    return dataclasses.replace(data, transport=data.frames_np(0, len(data.transport)), scales=None)


def training_split(episodes: dict) -> tr.TrainingData:
    """The training episodes as one split."""
    return tr.TrainingData.concat([d for n, d in episodes.items() if n.startswith("train")])


def as_json(config: RobustnessConfig) -> Any:
    """``config`` as it reads back from a JSON file (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def train_runs(cfg: ComparisonConfig, episodes: dict, runs_dir: Path, seeds: int) -> dict:
    """``{kind: [run directory]}``: nominal and robust runs in ``runs_dir``, one per seed."""
    train = training_split(episodes)
    tests = {n: d for n, d in episodes.items() if n.startswith("test")}
    runs: dict[str, list[Path]] = {k: [] for k in KINDS}
    for i in range(seeds):
        seed = stream_seed(cfg.seed, f"train/mincam-{PIXELS}px", i)
        for kind in KINDS:
            pert = PerturbationModel() if kind == "robust" else None
            run_dir = runs_dir / f"{kind}-seed{i}"
            m = tr.train_run(
                train,
                episodes["val-0"],
                None,
                run_dir,
                pixels=PIXELS,
                config=dataclasses.replace(cfg.train, seed=seed, perturbation=pert),
                episodes=tests,
            )
            print(f"{kind} seed {i}: {m.steps} steps, {m.train_wall_time_s:.0f} s")
            runs[kind].append(run_dir)
    return runs


def run_curves(run_dir: Path, tests: dict, config: RobustnessConfig, kind: str) -> dict:
    """The run's robustness record, measured or read back from ``run_dir/robustness.json``."""
    path = run_dir / "robustness.json"
    if path.is_file():
        record = json.loads(path.read_text())
        if record["config"] == as_json(config):
            return record
    model = tr.restore_mincam(tr.open_run(run_dir), next(iter(tests.values())), "robustness")
    record = robustness_curves(model, tests, config, name=run_dir.name, robust=kind == "robust")
    path.write_text(strict_json.dumps(record, indent=None) + "\n")
    return record


def summary(design: dict[str, Any]) -> dict[str, Any]:
    """A design's figures without the raw per-draw increases."""
    curves = {}
    for name, c in design["curves"].items():
        curves[name] = {
            "default": c["default"],
            "levels": [{k: v for k, v in lv.items() if k != "increases"} for lv in c["levels"]],
            "tolerance": c["tolerance"],
            "spec": c["spec"],
        }
    return {k: v for k, v in design.items() if k != "curves"} | {"curves": curves}


def verdict(designs: dict[str, dict], allowed: float, trivial: float) -> str:
    """The issue's done-when, then which built camera is better, beside the trivial predictor.

    Done-when: robust designs within ``allowed`` under the default mix where nominal
    ones lose more. A relative figure alone favours a design that learned little.
    """
    one = designs["nominal"]["config"]["levels"].index(1.0)
    mix = {kind: d["curves"][MIX]["levels"][one] for kind, d in designs.items()}
    r, n = mix["robust"], mix["nominal"]
    text = (
        f"under the default mix, nominal designs lose {_pct(n, 'increase')}, robust designs "
        f"{_pct(r, 'increase')} (limit {100 * allowed:g} %)"
    )
    text += (
        "; done-when met"
        if r["mean_increase"] <= allowed < n["mean_increase"]
        else ("; done-when NOT met as stated (see note)")
    )
    errors = {k: designs[k]["nominal_error"] for k in KINDS}
    text += (
        f". Error as designed: nominal {errors['nominal']:.4g}, robust {errors['robust']:.4g}; "
        f"under the mix: nominal {_abs(n)}, robust {_abs(r)}; trivial predictor {trivial:.4g}"
    )
    if r["ci95_error"][0] > n["ci95_error"][1]:
        text += " (the nominal design is better under the mix: intervals separate)"
    elif n["ci95_error"][0] > r["ci95_error"][1]:
        text += " (the robust design is better under the mix: intervals separate)"
    return text


def _pct(level: dict, key: str) -> str:
    lo, hi = level[f"ci95_{key}"]
    return f"{100 * level[f'mean_{key}']:+.1f} % [{100 * lo:+.1f}, {100 * hi:+.1f}]"


def _abs(level: dict) -> str:
    lo, hi = level["ci95_error"]
    return f"{level['mean_error']:.4g} [{lo:.4g}, {hi:.4g}]"


def trivial_error(episodes: dict) -> float:
    """The trivial predictor's error (training-label mean, mode if binary) on the test episodes."""
    train = training_split(episodes)
    tests = [d for n, d in episodes.items() if n.startswith("test")]
    return pool_episode_metrics([trivial_metrics(train, d) for d in tests])


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
            k: [{"run": r["name"], "nominal_error": r["nominal_error"]} for r in records[k]]
            for k in KINDS
        },
        "trivial_error": trivial,
        "verdict": text,
    }


def keep_robust_masks(runs: list[Path], episodes: dict, entry: dict, task: str, out: Path) -> None:
    """The best robust run's masks (lowest robust-validation loss) into ``out``.

    The sidecar holds the run's own test error as designed, the robust design's
    error as designed and under the default mix (pooled over its seeds), its
    specs and the verdict, with the episodes' manifest hashes.
    """
    best = min(runs, key=lambda r: json.loads((r / "metrics.json").read_text())["best_val_loss"])
    design = entry["designs"]["robust"]
    own = next(r["nominal_error"] for r in entry["runs"]["robust"] if r["run"] == best.name)
    levels = design["config"]["levels"]
    as_designed, mix = (design["curves"][MIX]["levels"][levels.index(x)] for x in (0.0, 1.0))
    figures = {
        "chosen_by": "lowest validation loss of the robust seeds (each under its own built cameras)",
        "test_error": own,
        "test_error_over_seeds": {
            "mean": as_designed["mean_error"],
            "ci95": as_designed["ci95_error"],
            "resampled": "training seeds (the test episodes pooled per run)",
        },
        "robustness": {
            "under_default_mix": mix,
            "specs": {name: c["spec"] for name, c in design["curves"].items()},
            "verdict": entry["verdict"],
        },
        "episodes": {n: episode_record(d) for n, d in episodes.items()},
    }
    keep_run_masks(best, out, task, figures)


def merged_result(out: Path, task: str, entry: dict, rcfg: RobustnessConfig) -> dict[str, Any]:
    """``out``'s results with ``task``'s entry replaced (other tasks kept if measured alike).

    An entry whose figures equal the old one's (re-read from the same runs, e.g.
    to keep masks) keeps the old machine block: the machine that measured them.
    """
    tasks: dict[str, Any] = {}
    if out.is_file():
        old = json.loads(out.read_text())
        if old.get("robustness_config") == as_json(rcfg):
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
    runs = train_runs(cfg, episodes, runs_dir, args.seeds)
    tests = {n: in_memory(d) for n, d in episodes.items() if n.startswith("test")}
    rcfg = RobustnessConfig(draws=args.draws)
    records = {k: [run_curves(r, tests, rcfg, k) for r in runs[k]] for k in KINDS}
    designs = {k: pool_curves(records[k], f"{entry_name}, mincam {PIXELS} px, {k}") for k in KINDS}
    trivial = trivial_error(episodes)
    text = verdict(designs, rcfg.allowed_increase, trivial)
    print(text)
    for d in designs.values():
        print(f"{d['name']}: nominal error {d['nominal_error']:.4f}")
        for c in d["curves"].values():
            print(f"  {c['spec']}")
    paths = write_robustness_report(list(designs.values()), args.work / "report", notes=[text])
    entry = task_entry(cfg, args, designs, records, text, trivial)
    if args.keep_masks is not None:
        out = args.keep_masks / args.task / f"robust-mincam-{PIXELS}px"
        keep_robust_masks(runs["robust"], episodes, entry, args.task, out)
        entry["masks"] = str(out)
    write_result(args.out, merged_result(args.out, entry_name, entry, rcfg))
    png = args.out.with_name(f"{args.out.stem}_{entry_name}.png")
    shutil.copyfile(paths["png"], png)
    print(f"wrote {png.name} and {paths['html']}")


if __name__ == "__main__":
    main()
