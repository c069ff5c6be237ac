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

Transport images come from Mitsuba (``--transport mitsuba``, ~30 frames/s, 4 spp)
or, for large training sets, from the linear operator of the patches scene
(``--transport linear``: ``T = W L`` with ``W`` estimated once by
:mod:`mincam_render.scenes.patches_linear` with the same estimator at
``--operator-spp`` samples per texel; ~3000 frames/s). Both give every camera
the same ``T[frame, detector, 32, 32]`` (float32, W): the mincam reads it through
its masks, the baselines box-filter its detector mean. ``--workers N`` trains the
cameras in N processes (1 thread each) on a shared memory-mapped cache and writes
``patches_paper_linear.json`` and ``.md`` for the linear transport.

Usage:
    PYTHONPATH=. python benchmarks/bench_patches_paper.py [--frames 4000] [--steps 2000]
        [--baselines 2x2,4x4,8x8,16x16] [--light-scales 1,0.01|none] [--out benchmarks/results]
        [--count-loss paper|mse|cross_entropy] [--transport mitsuba|linear]
        [--operator-spp 4096] [--cache PATH] [--workers 2] [--no-mincam]

Example (300k frames, linear transport, 2 cores):
    PYTHONPATH=. python benchmarks/bench_patches_paper.py --transport linear \
        --frames 300000 --steps 80000 --light-scales none --workers 2 \
        --cache /tmp/patches_linear_300k
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from provenance import machine

from mincam_render.core import strict_json
from mincam_render.learn import train as tr
from mincam_render.learn.models import CountLoss
from mincam_render.learn.train_config import GAIN_AUGMENTATION_20
from mincam_render.scenes import load_family
from mincam_render.scenes import patches_linear as pl

#: Frames per batch of the linear transport (images + one sparse product).
_LINEAR_BATCH = 2048
#: Relative training cost per step (measured: mincam 8.3 ms, baselines 2.8-3.8 ms).
_COST = {"mincam_4px": 2.5}


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
                "test_rmse": m.error,
                "test_rmse_raw": m.labels["count"].rmse_raw,
            }
        )
        print(
            f"    {res.steps:5d} steps {res.wall_time_s:7.1f} s  test RMSE {m.error:.3f}",
            flush=True,
        )
    return curve


_GEN: dict = {}


def _fill_linear(bounds: tuple[int, int]) -> None:
    """Worker: write frames ``[a, b)`` of the linear transport into the shared cache."""
    fam, op, path_t, path_c = _GEN["family"], _GEN["operator"], _GEN["t"], _GEN["c"]
    torch.set_num_threads(1)
    t_out = np.load(path_t, mmap_mode="r+")
    c_out = np.load(path_c, mmap_mode="r+")
    a, b = bounds
    for i, (t, c) in enumerate(
        pl.linear_transport_batches(fam, op, range(a, b), batch=_LINEAR_BATCH)
    ):
        s = a + i * _LINEAR_BATCH
        t_out[s : s + len(t)] = t
        c_out[s : s + len(t)] = c
    t_out.flush()
    c_out.flush()


def linear_data(fam, frames: int, operator_spp: int, seed: int, cache: Path, workers: int):
    """Transport ``W L`` of frames ``0..frames-1`` in a memory-mapped cache directory.

    Returns ``(transport memmap [N, K, R, C] float32, count [N, 1] float32, info dict)``.
    The cache is reused when its ``meta.json`` matches (family seed, frames, spp).
    """
    import multiprocessing as mp

    cache.mkdir(parents=True, exist_ok=True)
    meta_path, path_t, path_c = cache / "meta.json", cache / "transport.npy", cache / "count.npy"
    want = {"family": "patches", "seed": seed, "frames": frames, "operator_spp": operator_spp}
    if meta_path.is_file():
        meta = json.loads(meta_path.read_text())
        if {k: meta.get(k) for k in want} == want:
            return np.load(path_t, mmap_mode="r"), np.load(path_c), meta
    t0 = time.perf_counter()
    cam = fam.camera()
    # one thread: libgomp must not have started a team before the pool forks
    torch.set_num_threads(1)
    op = pl.build_plane_transport(pl.PlaneGeometry.of(fam), cam, spp=operator_spp, seed=seed)
    build_s = time.perf_counter() - t0
    rows, cols = cam.mask_resolution
    np.lib.format.open_memmap(
        path_t, mode="w+", dtype=np.float32, shape=(frames, cam.num_detectors, rows, cols)
    ).flush()
    np.lib.format.open_memmap(path_c, mode="w+", dtype=np.float32, shape=(frames, 1)).flush()
    _GEN.update(family=fam, operator=op, t=path_t, c=path_c)
    t1 = time.perf_counter()
    n_jobs = max(1, workers)
    edges = np.linspace(0, frames, 8 * n_jobs + 1).astype(int) // _LINEAR_BATCH * _LINEAR_BATCH
    edges[-1] = frames
    bounds = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]
    if n_jobs == 1:
        for b in bounds:
            _fill_linear(b)
    else:
        with mp.get_context("fork").Pool(n_jobs) as pool:
            pool.map(_fill_linear, bounds)
    gen_s = time.perf_counter() - t1
    meta = {
        **want,
        "operator_nnz": int(op.matrix._nnz()),
        "operator_build_s": build_s,
        "generate_s": gen_s,
        "generate_processes": n_jobs,
        "frames_per_s": frames / gen_s,
    }
    meta_path.write_text(strict_json.dumps(meta, indent=2))
    return np.load(path_t, mmap_mode="r"), np.load(path_c), meta


def _split_jobs(names: list[str], workers: int) -> list[list[str]]:
    """Cameras per worker, greedily balancing the per-step cost."""
    loads = [0.0] * workers
    groups: list[list[str]] = [[] for _ in range(workers)]
    for name in sorted(names, key=lambda n: -_COST.get(n, 1.0)):
        i = int(np.argmin(loads))
        groups[i].append(name)
        loads[i] += _COST.get(name, 1.0)
    return [g for g in groups if g]


def write_table(results: dict, path: Path) -> None:
    """A markdown table of test RMSE against steps and wall time."""
    lines = [
        f"# Patches paper reproduction ({results['transport']} transport, "
        f"{results['frames']} frames: {results['train_samples']} train / "
        f"{results['test_samples']} test)",
        "",
        f"Scene {results.get('scene', 'patches')}: "
        + ", ".join(f"{k} {v}" for k, v in results.get("generator_ranges", {}).items())
        + ".",
        "",
        f"Count loss {results['count_loss']}; batch {results['config']['batch_size']}; "
        f"{results['config']['max_steps']} steps; predict-the-mean RMSE "
        f"{results['predict_mean_rmse']:.3f}. Test RMSE (rounded counts) at each point of "
        "the budget; last column: best-validation state.",
        "",
    ]
    names = list(results["cameras"])
    steps = [p["steps"] for p in results["cameras"][names[0]]["curve"]]
    lines.append(
        "| camera | pixels | "
        + " | ".join(f"{s} steps" for s in steps)
        + " | best val | train wall (s) |"
    )
    lines.append("|---|---:|" + "---:|" * (len(steps) + 2))
    for name in names:
        r = results["cameras"][name]
        cells = " | ".join(f"{p['test_rmse']:.3f}" for p in r["curve"])
        lines.append(
            f"| {name} | {r['pixels']} | {cells} | {r['test_rmse_best_val']:.3f} | "
            f"{r['wall_time_s']:.0f} |"
        )
    lines.append("")
    path.write_text("\n".join(lines))


def scaled(d: tr.TrainingData, s: float) -> tr.TrainingData:
    return replace(d, transport=d.transport * np.float32(s)) if s != 1 else d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=4000)
    ap.add_argument("--spp", type=int, default=4, help="Mitsuba samples per texel")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--baselines", default="2x2,4x4,8x8,16x16")
    ap.add_argument("--no-mincam", action="store_true", help="train the baselines only")
    ap.add_argument("--light-scales", default="1,0.01", help="supplement A; 'none' skips it")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--count-loss",
        choices=["paper", *(c.value for c in CountLoss)],
        default="paper",
        help="how the count is learned (paper: cross-entropy, Sec. 5)",
    )
    ap.add_argument(
        "--transport",
        choices=["mitsuba", "linear"],
        default="mitsuba",
        help="render each frame with Mitsuba, or T = W L with the plane's linear operator",
    )
    ap.add_argument(
        "--operator-spp",
        type=int,
        default=pl.DEFAULT_OPERATOR_SPP,
        help="samples per mask texel of the linear operator W",
    )
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="processes generating linear transport and training cameras (1 thread each)",
    )
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    ap.add_argument("--json-name", default=None, help="default patches_paper[_linear].json")
    ap.add_argument(
        "--scene",
        default="patches",
        help="patches description (TOML path) for sensitivity runs; default: the shipped one",
    )
    ap.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="mitsuba: npz of rendered frames; linear: directory of memory-mapped .npy "
        "(reused if present, written if missing)",
    )
    a = ap.parse_args()
    count_loss = None if a.count_loss == "paper" else CountLoss(a.count_loss)
    json_name = a.json_name or (
        "patches_paper_linear.json" if a.transport == "linear" else "patches_paper.json"
    )
    if a.workers > 1 and a.cache is None:
        ap.error("--workers > 1 needs --cache (the processes share the transport on disk)")
    if a.workers > 1 and a.transport != "linear":
        ap.error("--workers > 1 is implemented for --transport linear")

    t0 = time.perf_counter()
    fam = load_family(a.scene, seed=a.seed, num_frames=a.frames)
    source = {
        "family": "patches",
        "scene": str(a.scene),
        "description": {
            "patch_size": list(fam.config.patch_size),
            "patch_radiance_w_m2_sr": list(fam.config.patch_radiance_w_m2_sr),
            "illumination_amplitude": list(fam.config.illumination_amplitude),
        },
        "seed": a.seed,
        "transport": a.transport,
    }
    linear_info = None
    if a.transport == "linear":
        cache = a.cache or Path(tempfile.mkdtemp(prefix="patches_linear_"))
        transport, count, linear_info = linear_data(
            fam, a.frames, a.operator_spp, a.seed, cache, a.workers
        )
        data = tr.TrainingData(
            transport=transport,
            labels={"count": count},
            label_specs=tuple(fam.labels),
            camera=fam.camera(),
            fps=fam.fps,
            source={**source, "cache": str(cache), "operator_spp": a.operator_spp},
        )
        render_s = linear_info["operator_build_s"] + linear_info["generate_s"]
    elif a.cache is not None and a.cache.is_file():
        z = np.load(a.cache)
        data = tr.TrainingData(
            transport=z["transport"],
            labels={"count": z["count"]},
            label_specs=tuple(fam.labels),
            camera=fam.camera(),
            fps=fam.fps,
            source={**source, "cache": str(a.cache)},
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
        f"{a.transport} transport of {a.frames} frames in {render_s:.1f} s: train {len(train)}, "
        f"val {len(val)}, test {len(test)}; label std {train.labels['count'].std():.3f}",
        flush=True,
    )
    config = tr.TrainConfig(
        max_steps=a.steps,
        batch_size=a.batch_size,
        eval_every=max(1, a.steps // 10),
        patience=10**6,
        count_loss=count_loss,
        seed=a.seed,
        gain_range=GAIN_AUGMENTATION_20,  # as patches_paper*.json were measured
    )
    checkpoints = sorted({a.steps // 16, a.steps // 8, a.steps // 4, a.steps // 2, a.steps} - {0})
    results = {
        "machine": machine(),
        "transport": a.transport,
        "scene": source["scene"],
        "generator_ranges": source["description"],
        "frames": a.frames,
        "spp": a.spp if a.transport == "mitsuba" else None,
        "linear_transport": linear_info,
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
    jobs = {}
    if not a.no_mincam:
        jobs["mincam_4px"] = lambda: tr.build_mincam(train, 4, count_loss=cl, seed=a.seed)
    for g in [g for g in a.baselines.split(",") if g]:
        grid = tuple(int(v) for v in g.lower().split("x"))
        jobs[f"baseline_{g}"] = lambda grid=grid: tr.build_baseline(
            train, grid, count_loss=cl, seed=a.seed
        )
    if a.workers > 1:
        # one child per group of cameras, each on the shared cache with one thread
        procs = []
        for w, group in enumerate(_split_jobs(list(jobs), a.workers)):
            bl = ",".join(n.removeprefix("baseline_") for n in group if n != "mincam_4px")
            cmd = [
                sys.executable, __file__, "--transport", "linear", "--frames", str(a.frames),
                "--steps", str(a.steps), "--batch-size", str(a.batch_size), "--seed", str(a.seed),
                "--count-loss", a.count_loss, "--operator-spp", str(a.operator_spp),
                "--cache", str(a.cache), "--light-scales", "none", "--workers", "1",
                "--baselines", bl, "--out", str(work), "--json-name", f"worker{w}.json",
            ]  # fmt: skip
            if "mincam_4px" not in group:
                cmd.append("--no-mincam")
            env = {**os.environ, "OMP_NUM_THREADS": "1", "DRJIT_NUM_THREADS": "1"}
            print(f"  worker {w}: {', '.join(group)}", flush=True)
            procs.append(subprocess.Popen(cmd, env=env))
        for proc in procs:
            if proc.wait() != 0:
                raise RuntimeError(f"worker {proc.args} failed with code {proc.returncode}")
        for w in range(len(procs)):
            part = json.loads((work / f"worker{w}.json").read_text())
            results["cameras"].update(part["cameras"])
        results["cameras"] = {n: results["cameras"][n] for n in jobs}
        results["workers"] = len(procs)
    else:
        for name, make in jobs.items():
            print(f"  {name}", flush=True)
            model = make()
            curve = budget_curve(model, train, val, test, config, checkpoints, work / name)
            final = tr.evaluate(model, test)  # best validation state
            results["cameras"][name] = {
                **tr.describe_model(model),
                "curve": curve,
                "test_rmse_best_val": final.error,
                "wall_time_s": curve[-1]["wall_time_s"],
            }
    scales = [] if a.light_scales.lower() == "none" else a.light_scales.split(",")
    for s in [float(v) for v in scales]:
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
                "test_rmse": ev.error,
                "wall_time_s": time.perf_counter() - t1,
                "mean_transmittance": float(mt.mean()),
                "mean_signal_v": float(volts.mean()),
                "signal_std_over_frames_v": float(volts.std(dim=0).mean()),
            }
            print(
                f"    {label}: test RMSE {ev.error:.3f}; mean M {float(mt.mean()):.3f}; "
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
    path = a.out / json_name
    path.write_text(strict_json.dumps(results, indent=2))
    if results["cameras"]:
        write_table(results, path.with_suffix(".md"))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
