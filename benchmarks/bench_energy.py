"""Self-powered budget of the workspace and lighting scenes, as ``mincam-render report energy`` runs it.

Usage:
    PYTHONPATH=. python benchmarks/bench_energy.py [--family workspace --family lighting]
        [--config scenes/energy.toml] [--out benchmarks/results/energy.json]

1. **Depth check** (:func:`mincam_render.studies.energy.panel.depth_check`).
   The panel sees lit walls, so its irradiance needs
   interreflections: one component of the first family (its first ceiling light
   alone, and the noon daylight if it has a window) is rendered at path depths
   3, 6, 12 and 24 with the description's samples, and the depth used is held to
   within 1 % of depth 24.
2. **The day.** :func:`mincam_render.studies.energy.run` with the shipped description (daylight
   every 15 min, office lights 08:00-18:00) and the study tables of
   ``benchmarks/results`` for the matched module. Reported per family: lux over
   the day, sustainable fps for 1..24 pixels, hours at 30 fps, the largest
   Monte Carlo standard error of the day's total irradiance (from 8 independent
   batches) and the render time; and the illuminance 24 pixels need at 30 fps
   beside the paper's ~600 lux.

Writes ``--out`` (JSON: machine, git revision, git_dirty, the full result) and
``energy.png`` beside it (the README's figure).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from provenance import machine

from mincam_render.core import strict_json

REPO = Path(__file__).resolve().parents[1]
DEPTHS = (3, 6, 12, 24)


def main() -> None:
    import logging

    from mincam_render.analysis.report import figure_png
    from mincam_render.studies.energy import headline, load_energy_config, run
    from mincam_render.studies.energy.figures import summary_figure
    from mincam_render.studies.energy.panel import depth_check

    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", action="append", default=None)
    ap.add_argument("--config", default=None)
    ap.add_argument("--out", default=str(REPO / "benchmarks/results/energy.json"))
    args = ap.parse_args()
    families = args.family or ["workspace", "lighting"]
    config = load_energy_config(args.config)
    info = machine()

    out = Path(args.out)
    start = time.perf_counter()
    depth = depth_check(families[0], config, DEPTHS)
    depth_s = time.perf_counter() - start
    for row in depth.rows:
        print(
            f"depth {row.depth:2d} {row.component:18s} {row.irradiance_w_m2:.4f} W/m^2 "
            f"({100 * row.relative_to_deepest:+.2f} % vs depth {DEPTHS[-1]})"
        )

    start = time.perf_counter()
    result = run(config, out.parent, families=families, studies_dir=REPO / "benchmarks/results")
    seconds = time.perf_counter() - start
    out.parent.mkdir(parents=True, exist_ok=True)
    (out.parent / "energy.png").write_bytes(figure_png(summary_figure(result)))

    summary = {
        "headline": headline(result),
        "threshold_lux_24px_30fps": result.threshold.budget.threshold_lux,
        "paper_lux": result.threshold.paper_lux,
        "power_24px_30fps_w": result.threshold.budget.power_at_fps_w,
        "families": {
            name: {
                "peak_lux": max(fam.lux),
                "hours_at_30fps": {str(k): fam.hours_at_fps[k] for k in (1, 8, 16, 24)},
                "max_relative_error_total": fam.render.max_relative_error_total,
                "render_seconds": fam.render.seconds,
            }
            for name, fam in result.families.items()
        },
        "comparisons": {
            name: {
                "grid": list(comp.match.grid),
                "pixels": comp.mincam.budget.pixels,
                "source": comp.match.source,
                "mincam_power_w": comp.mincam.budget.power_at_fps_w,
                "module_power_w": comp.module.budget.power_at_fps_w,
                "module_outputs_only_power_w": comp.module_outputs_only.budget.power_at_fps_w,
                "mincam_lux": comp.mincam.budget.threshold_lux,
                "module_lux": comp.module.budget.threshold_lux,
                "module_outputs_only_lux": comp.module_outputs_only.budget.threshold_lux,
            }
            for name, comp in result.comparisons.items()
        },
    }
    print(json.dumps(summary, indent=1))
    payload = {
        "machine": info,
        "command": "PYTHONPATH=. python benchmarks/bench_energy.py",
        "seconds": {"depth_check": depth_s, "analysis": seconds},
        "summary": summary,
        "depth_check": depth.as_json(),
        "result": result.as_json(),
    }
    out.write_text(strict_json.dumps(payload, indent=1) + "\n")
    print(f"wrote {out} and {out.parent / 'energy.png'}")


if __name__ == "__main__":
    main()
