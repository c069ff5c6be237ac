"""Privacy audit of the workspace designs, as ``mincam-render report privacy`` runs it.

Usage:
    PYTHONPATH=. python benchmarks/bench_privacy.py [--work runs/privacy]
        [--out benchmarks/results/privacy.json] [--workers 2]

1. **Episodes and designs.** the audit (:func:`run`) at its defaults: the
   workspace at 1 fps with a roster of 6 people (3 training episodes of 300
   frames, 1 validation episode of 200, 3 test episodes of 200), rendered at a
   fixed cheap fidelity (4 spp, depth 3); mincam 1, 2, 4, 8 px, 8 px with the
   privacy term (weight 1) and baselines 2x2 .. 32x32, each trained for the
   people count with 2 seeds of at most 1,000 steps.
2. **Attacks.** A 64 x 64 full view of every frame (4 spp) and its background
   (the frame with its people removed, same seed); per design, 3 attacker seeds
   (networks of at most 600 steps) train decoders of what the people add to the
   view (MLP, convolutional, ridge; the best on validation kept) and a
   re-identifier of the roster on the training episodes and are scored on the
   test episodes: PSNR/SSIM on the foreground (the people's pixels) and on the
   whole view, top-1 re-identification; the trivial attacker sees no one.
3. **Output.** ``--out`` (JSON: machine, git revision, timings, the audit),
   ``privacy.md`` (the table) and ``privacy.png`` (the curve) beside it; the
   report (HTML) in ``--work``.

Everything resumes from ``--work`` (episodes, views, backgrounds, task runs);
attacks run again. ``--verdicts-only`` runs nothing: it derives the verdicts
(:func:`rederive_verdicts`) again from ``--out``'s kept figures and rewrites it
and its table.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import time
from pathlib import Path

from mincam_render.core import strict_json
from mincam_render.studies.privacy.result import PrivacyResult

REPO = Path(__file__).resolve().parents[1]


def machine() -> dict:
    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], capture_output=True, text=True, cwd=REPO, check=False
        ).stdout.strip()

    return {
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "python": platform.python_version(),
        "git_revision": git("rev-parse", "HEAD"),
        "git_dirty": bool(git("status", "--porcelain")),
    }


def table(privacy: PrivacyResult) -> str:
    """Markdown: every design's task error and attack success, the trivial row, the verdicts."""
    from mincam_render.studies.privacy.report import (
        DESIGN_COLUMNS,
        PAIRED_HEADER,
        decoder_rows,
        design_rows,
        headline,
        paired_rows,
    )

    def markdown(header: list[str], rows: list[list]) -> list[str]:
        return [
            "| " + " | ".join(header) + " |",
            "|" + "|".join("---:" if h == "pixels" else "---" for h in header) + "|",
            *("| " + " | ".join(map(str, row)) + " |" for row in rows),
        ]

    header = ["design", "pixels", f"task {privacy.error_name}", *DESIGN_COLUMNS]
    lines = ["# Privacy audit: workspace, roster of 6", "", f"**{headline(privacy)}**", ""]
    lines += markdown(header, design_rows(privacy))
    lines += ["", "Verdicts (only where 95 % intervals separate):", ""]
    lines += [f"- {c.verdict}" for c in privacy.corner.values()]
    lines += ["", "Attack figures design − task-matched baseline, paired on the test episodes "
              "(beside the verdict, not as it):", ""]  # fmt: skip
    lines += markdown(PAIRED_HEADER, paired_rows(privacy))
    lines += ["", "Every decoder (the table above keeps the best on validation per seed):", ""]
    lines += markdown(*decoder_rows(privacy))
    return "\n".join(lines) + "\n"


def rederive_verdicts(path: Path) -> None:
    """Derive the corner verdicts again from a kept ``privacy.json``; rewrite it and its table."""
    from mincam_render.studies.privacy.curve import rederive_verdicts as derive

    record = json.loads(path.read_text())
    privacy = derive(PrivacyResult.from_json(record))
    record["corner"] = privacy.as_json()["corner"]  # the benchmark's own keys kept
    path.write_text(strict_json.dumps(record, indent=2) + "\n")
    path.with_suffix(".md").write_text(table(privacy))
    print(table(privacy))


def main() -> None:
    """Run the audit and write its JSON, table and curve."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=REPO / "runs" / "privacy")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks/results/privacy.json")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--verdicts-only", action="store_true")
    args = parser.parse_args()
    if args.verdicts_only:
        rederive_verdicts(args.out)
        return

    from mincam_render.studies.privacy import PrivacyConfig, run, write_report

    t0 = time.perf_counter()
    privacy = run(PrivacyConfig(), args.work, workers=args.workers, progress=True)
    seconds = time.perf_counter() - t0
    paths = write_report(privacy, args.work)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    record = {"benchmark": "bench_privacy", "machine": machine(), "wall_time_s": seconds,
              "report": paths["html"], **privacy.as_json()}  # fmt: skip
    args.out.write_text(strict_json.dumps(record, indent=2) + "\n")
    args.out.with_suffix(".md").write_text(table(privacy))
    shutil.copyfile(paths["png"], args.out.with_suffix(".png"))
    print(table(privacy))
    print(f"wrote {args.out}, {args.out.with_suffix('.md')}, {args.out.with_suffix('.png')}")


if __name__ == "__main__":
    main()
