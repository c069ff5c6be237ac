"""Time generating and rendering one frame of every scene family at its default camera.

Usage:
    python benchmarks/bench_families.py [--out benchmarks/results/families.json]
        [--frames 300] [--spp 16] [--repeats 7] [--families patches workspace ...]

Per family: seconds to construct the sequence (trajectory simulation, SUMO for
traffic) for --frames frames, to build the Mitsuba scene, and per frame the
median (and spread) of ``set_frame`` and of ``render_transport`` at the
family's default camera, after a warm-up frame (JIT compilation not timed).
Each rendered transport is checked to be finite and non-negative first.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from provenance import machine, write_result

from mincam_render import render_transport
from mincam_render.render import backend
from mincam_render.scenes import FAMILY_NAMES, load_family


def bench(name: str, frames: int, spp: int, repeats: int) -> dict:
    t0 = time.perf_counter()
    family = load_family(name, seed=0, num_frames=frames)
    construct_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    scene = family.build_scene()
    build_s = time.perf_counter() - t0
    camera = family.camera()
    set_s, render_s = [], []
    indices = np.linspace(0, frames - 1, repeats + 1).astype(int)
    for k, i in enumerate(indices):
        t0 = time.perf_counter()
        family.set_frame(scene, int(i))
        t1 = time.perf_counter()
        t = render_transport(scene, camera, spp=spp, seed=int(i))
        t2 = time.perf_counter()
        if not (np.all(np.isfinite(t)) and np.all(t >= 0)):
            raise SystemExit(f"{name}: non-finite or negative transport at frame {i}")
        if k > 0:  # frame 0 warms up (compilation)
            set_s.append(t1 - t0)
            render_s.append(t2 - t1)
    return {
        "family": name,
        "frames_simulated": frames,
        "detectors": camera.num_detectors,
        "mask_resolution": list(camera.mask_resolution),
        "spp": spp,
        "construct_seconds": construct_s,
        "build_scene_seconds": build_s,
        "set_frame_seconds_median": statistics.median(set_s),
        "render_seconds_median": statistics.median(render_s),
        "render_seconds_min": min(render_s),
        "render_seconds_max": max(render_s),
        "frame_seconds_median": statistics.median(
            [a + b for a, b in zip(set_s, render_s, strict=True)]
        ),
    }


def main() -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/families.json"))
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--families", nargs="+", default=list(FAMILY_NAMES))
    args = p.parse_args()
    rows = []
    for name in args.families:
        row = bench(name, args.frames, args.spp, args.repeats)
        rows.append(row)
        res = row["mask_resolution"]
        ms = {k: row[k] * 1e3 for k in row if k.endswith("seconds_median") or "render_seconds" in k}
        print(
            f"{name:10s} {row['detectors']} det {res[0]}x{res[1]} {args.spp} spp: "
            f"construct {row['construct_seconds']:.2f} s ({args.frames} frames), "
            f"build {row['build_scene_seconds']:.2f} s, "
            f"set_frame {ms['set_frame_seconds_median']:.1f} ms, "
            f"render {ms['render_seconds_median']:.1f} ms "
            f"[{ms['render_seconds_min']:.0f}, {ms['render_seconds_max']:.0f}]"
        )
    result = {
        "benchmark": "scene families: generate and render one frame at the default camera",
        "machine": machine(),
        "backend": backend.describe(),
        "results": rows,
    }
    write_result(args.out, result)


if __name__ == "__main__":
    main()
