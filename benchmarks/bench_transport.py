"""Time render_transport for the default 24-detector camera in the demo scene.

Usage:
    python benchmarks/bench_transport.py [--out benchmarks/results/transport.json]
        [--spp 16] [--resolutions 32 64] [--repeats 5]

For each mask resolution: checks the renderer against the closed form for an
open mask under a uniform sky (fails loudly if off by > 1 %), warms up (JIT
compilation and kernel recording are not timed), then times several calls and
reports the median and spread. A plain Mitsuba render of the same scene with
the same number of rays (a perspective sensor with K*rows*cols pixels at the
same spp, same integrator) is timed alongside; the ratio is our overhead.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
from provenance import machine, write_result

import mincam_render as mr
from mincam_render.render import backend
from mincam_render.render import mitsuba_scene as ms


def check_closed_form(camera: mr.FreeformCamera, spp: int) -> dict[str, float]:
    """Max relative error over detectors of open, half and quarter masks in a uniform sky."""
    scene = ms.scene_dict({"sky": ms.constant_environment(1.0)})
    t = mr.render_transport(scene, camera, spp=spp, seed=0).astype(np.float64)
    a, w, d = camera.detector_size_m, camera.mask_size_m, camera.mask_distance_m
    rows, cols = camera.mask_resolution
    det = (-a / 2, a / 2, -a / 2, a / 2)
    cases = {
        "open": (t.sum(axis=(1, 2)), (-w / 2, w / 2, -w / 2, w / 2)),
        "right_half": (t[:, :, cols // 2 :].sum(axis=(1, 2)), (0.0, w / 2, -w / 2, w / 2)),
        "top_left_quarter": (
            t[:, : rows // 2, : cols // 2].sum(axis=(1, 2)),
            (-w / 2, 0.0, 0.0, w / 2),
        ),
    }
    errors = {}
    for name, (got, rect) in cases.items():
        expected = mr.parallel_rectangles_coupling(det, rect, d)
        errors[name] = float(np.abs(got / expected - 1).max())
    if max(errors.values()) > 0.01:
        raise SystemExit(f"closed-form check failed: {errors} (> 1 %)")
    return errors


def timed(fn, repeats: int) -> list[float]:
    fn()  # warm-up: compile and record kernels
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        dr.sync_thread()
        out.append(time.perf_counter() - t0)
    return out


def main() -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/transport.json"))
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--resolutions", type=int, nargs="+", default=[32, 64])
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()

    info = backend.describe()
    scene = ms.load_scene(ms.demo_scene())
    rows_out = []
    for res in args.resolutions:
        cam = mr.FreeformCamera(mask_resolution=(res, res))
        err = check_closed_form(cam, args.spp)
        ours = timed(
            lambda cam=cam: mr.render_transport(scene, cam, spp=args.spp, seed=0), args.repeats
        )
        sensor = mi.load_dict(
            {
                "type": "perspective",
                "fov": 70.0,
                "film": {
                    "type": "hdrfilm",
                    "width": res * 6,
                    "height": res * 4,
                    "rfilter": {"type": "box"},
                },
            }
        )
        plain = timed(
            lambda sensor=sensor: mi.render(scene, sensor=sensor, spp=args.spp, seed=0).numpy(),
            args.repeats,
        )
        rays = cam.num_detectors * res * res * args.spp
        row = {
            "detectors": cam.num_detectors,
            "mask_resolution": [res, res],
            "spp": args.spp,
            "rays": rays,
            "closed_form_max_rel_error": err,
            "seconds_median": statistics.median(ours),
            "seconds_min": min(ours),
            "seconds_max": max(ours),
            "mrays_per_s": rays / statistics.median(ours) / 1e6,
            "plain_mitsuba_seconds_median": statistics.median(plain),
            "overhead_ratio": statistics.median(ours) / statistics.median(plain),
        }
        rows_out.append(row)
        print(
            f"{cam.num_detectors} detectors x {res}x{res} x {args.spp} spp: "
            f"{row['seconds_median'] * 1e3:.1f} ms median [{row['seconds_min'] * 1e3:.1f}, "
            f"{row['seconds_max'] * 1e3:.1f}], {row['mrays_per_s']:.1f} Mrays/s; plain Mitsuba "
            f"{row['plain_mitsuba_seconds_median'] * 1e3:.1f} ms "
            f"(ratio {row['overhead_ratio']:.2f}); "
            f"closed-form max rel. errors {', '.join(f'{k} {v:.1e}' for k, v in err.items())}"
        )
    result = {
        "benchmark": "render_transport, demo scene, default camera",
        "machine": machine(),
        "backend": info,
        "results": rows_out,
    }
    write_result(args.out, result)


if __name__ == "__main__":
    main()
