"""Paper reproduction on the toy task (patches, paper Sec. 5 and supplement A).

Renders a patches sequence in memory (4 detectors, 32x32 mask texels), splits it
70/10/20 in time and trains, at an equal training budget (same steps, batch
size and data; no early stopping):

* the 4-pixel minimalist camera, and baselines of 2x2, 4x4, 8x8, 16x16 (and
  optionally 32x32) box pixels with an 8-bit camera's noise;
* supplement A: 4 masks trained *without* the sensor model, then frozen while
  a fresh head is trained *with* it, against masks trained with it -- both
  evaluated with the sensor model; at each ``--light-scales`` factor (the
  scene's light multiplied, which the sensor noise cares about).

The count is learned as the paper did (Sec. 5: cross-entropy over the counts
0..10, predicting the expected count) unless ``--count-loss mse``.

Test RMSE (counts rounded; patches frames are independent, so no median filter)
is evaluated at several fractions of the budget to show RMSE against training
wall time. Prints a table and writes ``benchmarks/results/patches_paper.json``
(machine, git revision, data sizes, wall times).

Usage:
    PYTHONPATH=. python benchmarks/bench_patches_paper.py [--frames 4000] [--steps 2000]
        [--baselines 2x2,4x4,8x8,16x16] [--light-scales 1,0.01] [--out benchmarks/results]
        [--count-loss paper|mse|cross_entropy]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from mincam_render import train as tr
from mincam_render.generators import load_family
from mincam_render.models import CountLoss


def machine() -> dict:
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            cwd=Path(__file__).parent,
            check=False,
        ).stdout.strip()
        dirty = bool(
            subprocess.run(
                ["git", "status", "--porcelain"],
                capture_output=True,
                text=True,
                cwd=Path(__file__).parent,
            ).stdout.strip()
        )
    except OSError:
        rev, dirty = "", False
    return {
        "platform": platform.platform(),
        "processor": platform.processor(),
        "cpus": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "git_revision": rev,
        "git_dirty": dirty,
    }


def budget_curve(model, train, val, test, config, checkpoints, run_dir):
    """Train in chunks (resuming), evaluating test RMSE after each chunk."""
    curve = []
    for steps in checkpoints:
        res = tr.train_model(
            model,
            train,
            val,
            config,
            out_dir=run_dir,
            stop_after_steps=steps if steps < config.max_steps else None,
        )
        m = tr.evaluate(model, test)
        curve.append(
            {
                "steps": res.steps,
                "wall_time_s": res.wall_time_s,
                "test_rmse": m["error"],
                "test_rmse_raw": m["labels"]["count"]["rmse_raw"],
            }
        )
        print(
            f"    {res.steps:5d} steps {res.wall_time_s:7.1f} s  test RMSE {m['error']:.3f}",
            flush=True,
        )
    return curve


def scaled(d: tr.TrainingData, s: float) -> tr.TrainingData:
    return replace(d, transport=d.transport * np.float32(s)) if s != 1 else d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=4000)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--baselines", default="2x2,4x4,8x8,16x16")
    ap.add_argument("--light-scales", default="1,0.01")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--count-loss",
        choices=["paper", *(c.value for c in CountLoss)],
        default="paper",
        help="how the count is learned (paper: cross-entropy, Sec. 5)",
    )
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="npz of rendered frames to reuse (written if missing)",
    )
    a = ap.parse_args()
    count_loss = None if a.count_loss == "paper" else CountLoss(a.count_loss)

    t0 = time.perf_counter()
    fam = load_family("patches", seed=a.seed, num_frames=a.frames)
    if a.cache is not None and a.cache.is_file():
        z = np.load(a.cache)
        data = tr.TrainingData(
            transport=z["transport"],
            labels={"count": z["count"]},
            label_specs=tuple(fam.labels),
            camera=fam.camera(),
            fps=fam.fps,
            source={"family": "patches", "seed": a.seed, "cache": str(a.cache)},
        )
        render_s = float(z["render_s"])
    else:
        data = tr.TrainingData.render(fam, range(a.frames), spp=a.spp, seed=a.seed, progress=True)
        render_s = time.perf_counter() - t0
        if a.cache is not None:
            np.savez(
                a.cache, transport=data.transport, count=data.labels["count"], render_s=render_s
            )
    train, val, test = data.split((0.7, 0.1, 0.2))
    print(
        f"rendered {a.frames} frames in {render_s:.1f} s: train {len(train)}, val {len(val)}, "
        f"test {len(test)}; label std {train.labels['count'].std():.3f}",
        flush=True,
    )
    config = tr.TrainConfig(
        max_steps=a.steps,
        batch_size=a.batch_size,
        eval_every=max(1, a.steps // 10),
        patience=10**6,
        count_loss=count_loss,
        seed=a.seed,
    )
    checkpoints = sorted({a.steps // 8, a.steps // 4, a.steps // 2, a.steps})
    results = {
        "machine": machine(),
        "frames": a.frames,
        "spp": a.spp,
        "train_samples": len(train),
        "val_samples": len(val),
        "test_samples": len(test),
        "render_wall_time_s": render_s,
        "config": {**config.__dict__},
        "count_loss": tr.count_loss_for(train, count_loss).value,
        "predict_mean_rmse": float(test.labels["count"].std()),
        "cameras": {},
        "gap": {},
    }
    work = Path(tempfile.mkdtemp(prefix="bench_patches_"))
    cl = config.count_loss
    jobs = [("mincam_4px", lambda: tr.build_mincam(train, 4, count_loss=cl, seed=a.seed))]
    for g in a.baselines.split(","):
        grid = tuple(int(v) for v in g.lower().split("x"))
        jobs.append(
            (
                f"baseline_{g}",
                lambda grid=grid: tr.build_baseline(train, grid, count_loss=cl, seed=a.seed),
            )
        )
    for name, make in jobs:
        print(f"  {name}", flush=True)
        model = make()
        curve = budget_curve(model, train, val, test, config, checkpoints, work / name)
        final = tr.evaluate(model, test)  # best validation state
        results["cameras"][name] = {
            **tr.describe_model(model),
            "curve": curve,
            "test_rmse_best_val": final["error"],
            "wall_time_s": curve[-1]["wall_time_s"],
        }
    for s in [float(v) for v in a.light_scales.split(",")]:
        print(f"  supplement A gap, light x{s:g}", flush=True)
        trs, vas, tes = scaled(train, s), scaled(val, s), scaled(test, s)
        gap = {}
        for label, sensor in (("with_sensor_model", True), ("without_sensor_model", False)):
            t1 = time.perf_counter()
            m = tr.build_mincam(trs, 4, sensor_model=sensor, count_loss=cl, seed=a.seed)
            tr.train_model(m, trs, vas, config)
            if not sensor:  # freeze the masks, retrain a fresh head with the sensor model
                m2 = tr.build_mincam(trs, 4, sensor_model=True, count_loss=cl, seed=a.seed + 1)
                with torch.no_grad():
                    m2.logits.copy_(m.logits)
                m2.logits.requires_grad_(False)
                tr.train_model(m2, trs, vas, config)
                m = m2
            ev = tr.evaluate(m, tes)
            with torch.no_grad():
                mt = m.transmittance()
            volts = m.measure(torch.from_numpy(tes.transport[:256]), noise=False).detach()
            gap[label] = {
                "test_rmse": ev["error"],
                "wall_time_s": time.perf_counter() - t1,
                "mean_transmittance": float(mt.mean()),
                "mean_signal_v": float(volts.mean()),
                "signal_std_over_frames_v": float(volts.std(dim=0).mean()),
            }
            print(
                f"    {label}: test RMSE {ev['error']:.3f}; mean M {float(mt.mean()):.3f}; "
                f"signal {float(volts.mean()):.3g} V",
                flush=True,
            )
        results["gap"][f"light_x{s:g}"] = gap
    results["total_wall_time_s"] = time.perf_counter() - t0
    print("\ncamera            pixels  test RMSE (end / best val)  train wall time")
    for name, r in results["cameras"].items():
        print(
            f"{name:17s} {r['pixels']:6d}  {r['curve'][-1]['test_rmse']:.3f} / "
            f"{r['test_rmse_best_val']:.3f}            {r['wall_time_s']:.1f} s"
        )
    for k, g in results["gap"].items():
        print(
            f"supplement A ({k}): with sensor model {g['with_sensor_model']['test_rmse']:.3f}, "
            f"without {g['without_sensor_model']['test_rmse']:.3f} (paper: 0.93 vs 2.28)"
        )
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "patches_paper.json"
    path.write_text(json.dumps(results, indent=2, default=str))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
