"""A comparison's training runs in this process vs on local workers (``--train-workers``).

Renders the episodes of a small patches comparison once (not timed), then trains
its runs (2 designs x ``--seeds`` seeds) with ``train_workers=1`` (in this
process, as before) and ``train_workers=N``, ``--repeats`` times each into fresh
directories; checks that every way gives every run the same figures bit for bit
before reporting the wall times (median and all), their ratio, the load average
and the CPU steal over each timing (the machine may be shared: the figures say
how loaded it was).

Usage:
    PYTHONPATH=. .venv/bin/python benchmarks/bench_train_workers.py [--workers 2]
        [--seeds 3] [--steps 400] [--repeats 2]
    (writes benchmarks/results/train_workers.json: machine, git revision, times)
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

from provenance import cpu_times, machine, write_result

from mincam_render.learn.train_config import TrainConfig
from mincam_render.studies.comparison.runs import ComparisonRun, RunsByTask, Splits, train_runs
from mincam_render.studies.comparison.study import (
    ComparisonConfig,
    Design,
    comparison_splits,
    render_episodes,
)

QUICK = {"spp": 4, "max_depth": 0, "shared_render": False, "differential": False}
#: What must not depend on where a run trained.
SAME = ("steps", "best_step", "best_val_loss", "stopped_early", "episodes")


def _config(seeds: int, steps: int) -> ComparisonConfig:
    return ComparisonConfig(
        family="patches",
        train_episodes=1,
        train_frames=300,
        val_frames=100,
        test_frames=100,
        test_episodes=2,
        val_episodes=1,
        seeds=seeds,
        designs=(Design(pixels=4), Design(grid=(4, 4))),
        train=TrainConfig(max_steps=steps, eval_every=50),
        fidelity=QUICK,
    )


def _same(run: ComparisonRun) -> dict:
    """What must not depend on where ``run`` trained (:data:`SAME`), as JSON."""
    record = run.as_json()
    return {k: record[k] for k in SAME}


def _figures(runs: RunsByTask) -> dict[str, list[dict]]:
    """Each design's figures per seed (patches has one task)."""
    (by_design,) = runs.values()
    return {n: [_same(r) for r in rs] for n, rs in by_design.items()}


def _time(cfg: ComparisonConfig, splits: Splits, out: Path, workers: int) -> tuple[float, dict]:
    """Wall time of training every run into ``out`` on ``workers``; load and steal over it."""
    load0, (steal0, total0) = os.getloadavg()[0], cpu_times()
    t0 = time.perf_counter()
    runs = train_runs(cfg, splits, out, train_workers=workers, progress=False)
    wall = time.perf_counter() - t0
    steal1, total1 = cpu_times()
    load = {
        "load_average_1min_before": load0,
        "load_average_1min_after": os.getloadavg()[0],
        "cpu_steal_fraction": (steal1 - steal0) / max(total1 - total0, 1),
    }
    return wall, {"figures": _figures(runs), "load": load}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    cfg = _config(args.seeds, args.steps)
    ways = {"in_process": 1, f"train_workers_{args.workers}": args.workers}
    times: dict[str, list[float]] = {w: [] for w in ways}
    loads: dict[str, list[dict]] = {w: [] for w in ways}
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MINCAM_RENDER_PLAN_CACHE"] = str(Path(tmp) / "plans")
        splits = comparison_splits(render_episodes(cfg, Path(tmp) / "episodes", workers=0))
        reference = None
        for repeat in range(args.repeats):
            for way, workers in ways.items():  # alternated: a change of load hits both
                wall, got = _time(cfg, splits, Path(tmp) / f"{way}-{repeat}", workers)
                reference = reference or got["figures"]
                assert got["figures"] == reference, f"{way}: other figures than in process"
                times[way].append(wall)
                loads[way].append(got["load"])
                print(f"{way} repeat {repeat}: {wall:.1f} s {got['load']}", flush=True)
    medians = {w: statistics.median(t) for w, t in times.items()}
    result = {
        "machine": machine(),
        "note": "2-core machine shared with a long render; see each timing's load",
        "config": {
            "family": cfg.family,
            "designs": [d.name for d in cfg.designs],
            "seeds": cfg.seeds,
            "runs": len(cfg.designs) * cfg.seeds,
            "max_steps": args.steps,
            "train_frames": cfg.train_frames,
            "fidelity": QUICK,
        },
        "identical_figures": True,
        "wall_s": {w: [round(t, 2) for t in ts] for w, ts in times.items()},
        "median_wall_s": {w: round(t, 2) for w, t in medians.items()},
        "speedup_vs_in_process": {
            w: round(medians["in_process"] / t, 2) for w, t in medians.items()
        },
        "load": loads,
    }
    print({k: result[k] for k in ("median_wall_s", "speedup_vs_in_process")})
    write_result(Path(__file__).parent / "results" / "train_workers.json", result)


if __name__ == "__main__":
    main()
