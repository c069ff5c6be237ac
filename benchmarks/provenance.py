"""Where and at which revision a benchmark ran: the ``machine`` block of every results JSON.

The benchmark scripts import it as ``from provenance import machine`` (Python puts
the script's folder first on ``sys.path``).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

from mincam_render.core import strict_json

REPO = Path(__file__).resolve().parents[1]
#: The benchmarks' results, relative to the repository (not part of the code's state).
RESULTS_DIR = "benchmarks/results"


def git(*args: str) -> str:
    """Stdout of ``git ARGS`` in this repository ("" where git is missing or refuses)."""
    try:
        done = subprocess.run(["git", *args], capture_output=True, text=True, cwd=REPO)
    except OSError:
        return ""
    return done.stdout.strip() if done.returncode == 0 else ""


def machine() -> dict[str, Any]:
    """Platform, cores, load, Python (and torch, if the script imported it), git revision.

    ``git_dirty``: files other than the benchmarks' results differ from the revision
    (a benchmark writes its results before it records the machine).
    """
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "processor": platform.processor(),
        "cpus": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "python": platform.python_version(),
    }
    torch = sys.modules.get("torch")
    if torch is not None:
        info |= {"torch": torch.__version__, "torch_threads": torch.get_num_threads()}
    revision = git("rev-parse", "HEAD")
    return info | {
        "git_revision": revision or "unknown",
        "git_dirty": bool(git("status", "--porcelain", "--", ".", f":!{RESULTS_DIR}"))
        if revision
        else False,
    }


def cpu_times() -> tuple[int, int]:
    """``(steal, total)`` CPU ticks of the machine so far (``/proc/stat``; zeros elsewhere)."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return 0, 0
    return (fields[7] if len(fields) > 7 else 0), sum(fields)


def write_result(path: Path, result: dict[str, Any]) -> None:
    """Write a benchmark's results JSON (its folder created) and say where."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(strict_json.dumps(result, indent=2) + "\n")
    print(f"wrote {path}")
