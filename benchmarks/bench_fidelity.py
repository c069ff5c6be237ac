"""Error against run time of every fidelity knob, for every shipped scene family.

Usage:
    PYTHONPATH=. python benchmarks/bench_fidelity.py [--out benchmarks/results/fidelity]
        [--families patches,workspace,lighting,traffic] [--frames 2] [--reference-spp 256]
        [--base-spp 16] [--repeats 1]

Writes fidelity.json (rows: family, knob, level, error, effect, seconds per frame, plus
machine, variant and git revision), pareto_<family>.png and fidelity.html, and prints
the Pareto table and the per-family statements. About 2-4 minutes per family on 2 CPU
cores (traffic needs the optional SUMO extra).
"""

from __future__ import annotations

import argparse
import logging

from mincam_render.scenes import FAMILY_NAMES
from mincam_render.studies.fidelity import FidelityBenchConfig, pareto_table, run, write_report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="benchmarks/results/fidelity")
    ap.add_argument("--families", default=",".join(FAMILY_NAMES))
    ap.add_argument("--frames", type=int, default=2)
    ap.add_argument("--reference-spp", type=int, default=256)
    ap.add_argument("--base-spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    cfg = FidelityBenchConfig(
        families=tuple(args.families.split(",")),
        num_frames=args.frames,
        reference_spp=args.reference_spp,
        base_spp=args.base_spp,
        repeats=args.repeats,
    )
    result = run(cfg, args.out)
    for res in result.families:
        print(f"== {res.family}\n{pareto_table(res)}")
        print("\n".join(res.statements))
    paths = write_report(result, args.out)
    print(f"wrote {paths['json']} and {paths['html']}")


if __name__ == "__main__":
    main()
