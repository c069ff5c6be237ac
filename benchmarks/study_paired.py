"""Paired differences for a kept study whose metrics predate them.

`mincam-render study` now writes, beside every verdict, the paired difference of
two designs on the same test episodes (``analysis.statistics.paired_difference``).
Studies kept in ``benchmarks/results/`` before that have each run's per-episode
test metrics only in its run directory (``RUN/metrics.json``). This script
reads them back, adds ``episode_errors`` to every design and to the trivial
predictor, recomputes ``reference_verdicts`` (each separate-interval verdict
followed by its paired line) and ``paired`` (every design against the trivial
predictor), records ``paired_added`` (git revision, date) and appends the lines
to the study's ``.md``. Nothing is retrained: the figures are the kept runs'.

Usage:
    PYTHONPATH=. python benchmarks/study_paired.py benchmarks/results/study_patches.json \
        [--also mincam-16px]
"""

from __future__ import annotations

import argparse
import datetime
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from bench_patches_paper import machine

from mincam_render.analysis.statistics import EpisodeErrors, Pooling
from mincam_render.core import strict_json
from mincam_render.studies.comparison.records import DesignRecord
from mincam_render.studies.comparison.study import paired_differences, reference_verdicts


def episode_errors(per_seed: Sequence[Mapping[str, Any]]) -> EpisodeErrors:
    """Per-seed, per-episode errors of kept runs' ``episodes`` records (as their files hold them)."""
    names = sorted(per_seed[0])
    first = per_seed[0][names[0]]
    return EpisodeErrors(
        error=np.array([[m[e]["error"] for e in names] for m in per_seed]),
        frames=np.array([per_seed[0][e]["samples"] for e in names]),
        pooling=Pooling.RMS if first["error_name"].endswith("RMSE") else Pooling.MEAN,
    )


def add_paired(result: dict[str, Any], also: list[str]) -> list[str]:
    """Add per-episode errors and paired differences to ``result``; the new lines.

    ``also``: further minimalist designs compared with every baseline (kept
    under ``paired_also``), beside the study's reference.
    """
    errors = {}
    for name, d in result["designs"].items():
        runs = [json.loads((Path(r) / "metrics.json").read_text())["episodes"] for r in d["runs"]]
        errors[name] = episode_errors(runs)
        d["episode_errors"] = errors[name].as_dict()
    errors["trivial"] = episode_errors([result["trivial"]["episodes"]])
    result["trivial"]["episode_errors"] = errors["trivial"].as_dict()
    seed = int(result["config"].get("seed", 0))
    # a kept study: the headline's designs at the top level
    designs = {n: DesignRecord.from_json(d) for n, d in result["designs"].items()}
    result["reference_verdicts"] = reference_verdicts(
        designs, result["reduction_factor"]["reference"], seed
    )
    paired = paired_differences(errors, [], seed)
    result["paired"] = {key: p.as_json() for key, p in paired.items()}
    result["paired_also"] = {name: reference_verdicts(designs, name, seed) for name in also}
    extra = [line for lines in result["paired_also"].values() for line in lines]
    return [
        line for line in [*result["reference_verdicts"], *extra] if line.startswith("paired")
    ] + [p["statement"] for p in result["paired"].values()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", type=Path, help="a study_*.json of benchmarks/results")
    parser.add_argument(
        "--also", action="append", default=[], help="another design against every baseline"
    )
    args = parser.parse_args()
    result = json.loads(args.study.read_text())
    lines = add_paired(result, args.also)
    revision = machine()["git_revision"]
    result["paired_added"] = {"git_revision": revision, "date": str(datetime.date.today())}
    args.study.write_text(strict_json.dumps(result, indent=2) + "\n")
    md = args.study.with_suffix(".md")
    section = [
        "",
        f"## Paired differences on the same test episodes (added at {revision})",
        "",
        "Each design's error minus the other's, the test episodes resampled once for "
        "both and each design's seeds independently (95 % bootstrap interval; "
        "`benchmarks/study_paired.py`, no retraining). An interval that excludes 0 says "
        "the ordering holds beyond seeds and the difficulty the episodes share; the "
        "verdicts above keep the stricter separate-interval rule.",
        "",
        *[f"- {line}" for line in lines],
    ]
    md.write_text(md.read_text().rstrip("\n") + "\n" + "\n".join(section) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
