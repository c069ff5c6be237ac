"""The sim2real verdicts of every family's surrogate recording, as the command line gives them.

For each family runs ``mincam-render report sim2real --surrogate FAMILY --frames N --spp S``
(a surrogate "real" recording with injected gain, offset and fabrication errors,
simulated back and compared; docs/sim2real_format.md) in a subprocess, and keeps
the command, the verdict, the thresholds and the per-pixel fits of its
``sim2real.json``. Writes ``benchmarks/results/sim2real_surrogate.json`` (machine
and git revision; one entry per family). About 1-3 minutes per family on 2 cores
(traffic needs the optional SUMO extra).

Usage:
    PYTHONPATH=. python benchmarks/bench_sim2real_surrogate.py
        [--families patches workspace lighting traffic] [--frames 300] [--spp 32]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from provenance import REPO, machine, write_result

KEPT = ("verdict", "thresholds", "pixels")


def surrogate_report(family: str, frames: int, spp: int, out: Path) -> dict:
    """The kept parts of one family's ``sim2real.json`` and the command that made it."""
    args = ["report", "sim2real", "--surrogate", family, "--frames", str(frames)]
    args += ["--spp", str(spp)]
    launcher = "from mincam_render.cli.main import main; main()"
    subprocess.run([sys.executable, "-c", launcher, *args, "--out", str(out)], check=True, cwd=REPO)
    report = json.loads((out / "sim2real.json").read_text())
    return {"command": " ".join(["mincam-render", *args])} | {k: report[k] for k in KEPT}


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--families", nargs="+", default=["patches", "workspace", "lighting", "traffic"]
    )
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/sim2real_surrogate.json")
    args = ap.parse_args()
    result: dict = {"machine": machine()}
    with tempfile.TemporaryDirectory() as tmp:
        for family in args.families:
            result[family] = surrogate_report(family, args.frames, args.spp, Path(tmp) / family)
            print(f"{family}: {result[family]['verdict']['summary']}", flush=True)
    write_result(args.out, result)


if __name__ == "__main__":
    main()
