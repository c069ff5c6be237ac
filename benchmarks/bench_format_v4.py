"""What dataset format 4 changed, measured: run once at a format-3 checkout, once at format 4.

For the checkout on ``PYTHONPATH`` (the package imported, whatever its format):

- per family (patches, workspace, lighting, traffic; 600 frames, seed 0): the
  mean transport per frame, ``sum T[k, row, col]`` (W) averaged over 6 frames
  spread over the episode, rendered with the family's estimator at 16 spp and
  render seed 0, with the family's default camera; where that camera has a
  directional response, the same frames with Lambert's cosine instead (the
  response's effect on total detector power);
- people's paths in the workspace room: mean length (m) and planning time (ms)
  of 200 paths between random free points (rng seed 0), and the metres walked
  per person-second and mean people count of a 9000-frame (5 min) episode at
  seed 0;
- the sun of the default daylight (40.8 deg N, day 172): elevation (deg) and
  clear-sky global horizontal irradiance (visible, W/m^2) at 7, 9, 12, 15, 17 h.

Writes ``benchmarks/results/format_v4_<label>.json`` (machine, git revision and
dirtiness of this repository, and of the measured package's checkout).
``--table`` prints the before/after markdown table from the v3 and v4 files.

Usage:
    PYTHONPATH=/path/to/format3/checkout python benchmarks/bench_format_v4.py --label v3
    PYTHONPATH=. python benchmarks/bench_format_v4.py --label v4
    python benchmarks/bench_format_v4.py --table
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from mincam_render.core import strict_json

sys.path.insert(0, str(Path(__file__).parent))
from provenance import machine  # noqa: E402

RESULTS = Path(__file__).parent / "results"
FAMILIES = ("patches", "workspace", "lighting", "traffic")
NUM_FRAMES = 600
PROBE_FRAMES = 6
SPP = 16
HOURS = (7.0, 9.0, 12.0, 15.0, 17.0)
PATHS = 200
PATH_FRAMES = 9000


def _package_checkout() -> dict:
    import mincam_render
    from mincam_render.data.dataset import FORMAT_VERSION

    root = Path(mincam_render.__file__).resolve().parent.parent
    rev = subprocess.run(
        ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=root, check=False
    ).stdout.strip()
    return {"path": str(root), "git_revision": rev, "format_version": FORMAT_VERSION}


def _mean_power(family, scene, camera, frames) -> float:
    powers = []
    for i in frames:
        family.set_frame(scene, int(i))
        t = family.render_transport(scene, camera, spp=SPP, seed=0)
        powers.append(float(t.astype(np.float64).sum()))
    return float(np.mean(powers))


def transport_figures() -> dict:
    """Mean transport per frame (W) per family, and with a cosine diode where it differs."""
    from mincam_render.scenes import load_family

    out = {}
    for name in FAMILIES:
        family = load_family(name, seed=0, num_frames=NUM_FRAMES)
        scene, camera = family.build_scene(), family.camera()
        frames = np.linspace(0, NUM_FRAMES - 1, PROBE_FRAMES).round().astype(int)
        t0 = time.perf_counter()
        row = {"mean_power_w": _mean_power(family, scene, camera, frames)}
        row["seconds"] = time.perf_counter() - t0
        if getattr(camera, "directional_response", None) is not None:
            cosine = replace(camera, directional_response=None)
            row["mean_power_cosine_w"] = _mean_power(family, scene, cosine, frames)
        out[name] = row
        print(name, row, flush=True)
    return out


def path_figures() -> dict:
    """Workspace paths: mean planned length and time, metres walked per person-second."""
    from mincam_render.scenes import load_family
    from mincam_render.scenes.indoor.config import FurnitureKind
    from mincam_render.scenes.indoor.motion import NavGrid

    family = load_family("workspace", seed=0, num_frames=PATH_FRAMES)
    c = family.config
    nav = NavGrid(c.room, [f for f in c.furniture if f.kind is not FurnitureKind.CHAIR])
    rng = np.random.default_rng(0)
    lengths, seconds = [], []
    for _ in range(PATHS):
        a, b = nav.random_point(rng), nav.random_point(rng)
        t0 = time.perf_counter()
        way = nav.plan(a, b)
        seconds.append(time.perf_counter() - t0)
        lengths.append(float(np.linalg.norm(np.diff(np.asarray(way), axis=0), axis=1).sum()))
    track = family.track
    both = track.active[1:] & track.active[:-1] & (track.visit[1:] == track.visit[:-1])
    steps = np.linalg.norm(track.pose[1:, :, :2] - track.pose[:-1, :, :2], axis=-1)
    person_s = float(track.active.sum()) / c.fps
    return {
        "mean_path_length_m": float(np.mean(lengths)),
        "mean_plan_ms": 1e3 * float(np.median(seconds)),
        "walked_m_per_person_s": float(steps[both].sum()) / person_s if person_s else 0.0,
        "mean_people": float(track.active.sum(axis=1).mean()),
    }


def sun_figures() -> dict:
    """Elevation (deg) and clear-sky GHI (visible, W/m^2) of the default daylight."""
    from mincam_render.scenes import sky

    config = sky.DaylightConfig()
    out = {}
    for hour in HOURS:
        day = sky.daylight(replace(config, start_hour=hour), 0.0, height=16, width=32)
        elevation = math.degrees(math.asin(float(day.sun_direction[2])))
        out[f"{hour:g}"] = {
            "elevation_deg": elevation,
            "ghi_visible_w_m2": float(day.global_horizontal_w_m2),
        }
    return out


def table(v3: dict, v4: dict) -> str:
    """Markdown table of the before/after figures."""
    rows = ["| quantity | v3 | v4 | v4 / v3 |", "|---|---|---|---|"]

    def add(label: str, a: float, b: float, fmt: str = "{:.4g}") -> None:
        ratio = f"{b / a:.3f}" if a else "-"
        rows.append(f"| {label} | {fmt.format(a)} | {fmt.format(b)} | {ratio} |")

    for name in FAMILIES:
        a, b = v3["transport"][name], v4["transport"][name]
        add(f"{name}: mean transport per frame (W)", a["mean_power_w"], b["mean_power_w"])
        if "mean_power_cosine_w" in b:
            add(
                f"{name}: v4 with a cosine diode (W)",
                a["mean_power_w"],
                b["mean_power_cosine_w"],
            )
    pa, pb = v3["paths"], v4["paths"]
    add("workspace: mean planned path (m)", pa["mean_path_length_m"], pb["mean_path_length_m"])
    add("workspace: median planning time (ms)", pa["mean_plan_ms"], pb["mean_plan_ms"])
    add(
        "workspace: walked m per person-s", pa["walked_m_per_person_s"], pb["walked_m_per_person_s"]
    )
    add("workspace: mean people in view", pa["mean_people"], pb["mean_people"])
    for hour in v3["sun"]:
        sa, sb = v3["sun"][hour], v4["sun"][hour]
        add(f"sun elevation at {hour} h (deg)", sa["elevation_deg"], sb["elevation_deg"], "{:.2f}")
        add(
            f"clear-sky GHI at {hour} h (W/m², visible)",
            sa["ghi_visible_w_m2"],
            sb["ghi_visible_w_m2"],
            "{:.1f}",
        )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--label", choices=("v3", "v4"))
    parser.add_argument("--table", action="store_true", help="print the before/after table")
    args = parser.parse_args()
    if args.table:
        v3, v4 = (json.loads((RESULTS / f"format_v4_{x}.json").read_text()) for x in ("v3", "v4"))
        print(table(v3, v4))
        return
    if args.label is None:
        parser.error("--label v3|v4 or --table")
    from mincam_render.render import backend

    backend.use_variant()
    res = {
        "machine": machine(),
        "package": _package_checkout(),
        "settings": {
            "num_frames": NUM_FRAMES,
            "probe_frames": PROBE_FRAMES,
            "spp": SPP,
            "path_frames": PATH_FRAMES,
        },
        "sun": sun_figures(),
        "paths": path_figures(),
    }
    print(json.dumps({k: res[k] for k in ("package", "sun", "paths")}, indent=2), flush=True)
    res["transport"] = transport_figures()
    out = RESULTS / f"format_v4_{args.label}.json"
    out.write_text(strict_json.dumps(res, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
