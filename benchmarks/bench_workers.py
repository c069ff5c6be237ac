"""Worker processes vs rendering in this process, by job size (issue 17: --workers by job size).

For each job, renders the same dataset with ``workers=0`` (this process),
``workers=cores`` (a pool) and ``workers=None`` (the automatic choice), checks
that all three wrote identical shards, and prints and writes the wall times.
The fidelity plan is measured once before timing (it is cached), so only
rendering is compared.

Usage:
    PYTHONPATH=. .venv/bin/python benchmarks/bench_workers.py
    (writes benchmarks/results/workers.json: machine and git revision, wall times)
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

from provenance import machine

from mincam_render.core import strict_json
from mincam_render.data.dataset import SHARD_DIR
from mincam_render.data.render_job import (
    POOL_BREAK_EVEN_S,
    RenderRequest,
    plan_render,
    render_dataset,
)

JOBS = {
    "patches 40 frames": RenderRequest(family="patches", num_frames=40, shard_frames=10),
    "patches 4000 frames": RenderRequest(family="patches", num_frames=4000, shard_frames=500),
    "workspace 48 frames": RenderRequest(family="workspace", num_frames=48, shard_frames=12),
}


def _shards(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((root / SHARD_DIR).iterdir())}


def main() -> None:
    cores = os.cpu_count() or 1
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["MINCAM_RENDER_PLAN_CACHE"] = str(Path(tmp) / "plans")
        for name, request in JOBS.items():
            plan_render(request)  # measured and cached: not part of the timings
            times, shards = {}, {}
            for label, workers in (("in_process", 0), ("pool", cores), ("auto", None)):
                out = Path(tmp) / f"{name}-{label}".replace(" ", "_")
                t0 = time.perf_counter()
                render_dataset(request, out, workers=workers)
                times[label] = time.perf_counter() - t0
                shards[label] = _shards(out)
                shutil.rmtree(out)
            assert shards["pool"] == shards["in_process"] == shards["auto"], name
            row = {"job": name, **{f"{k}_s": round(v, 2) for k, v in times.items()}}
            row["auto_vs_best"] = round(times["auto"] / min(times["in_process"], times["pool"]), 2)
            rows.append(row)
            print(row, flush=True)
    result = {
        "machine": machine(),
        "cores": cores,
        "pool_break_even_s": POOL_BREAK_EVEN_S,
        "identical_shards": True,
        "rows": rows,
    }
    path = Path(__file__).parent / "results" / "workers.json"
    path.write_text(strict_json.dumps(result, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
