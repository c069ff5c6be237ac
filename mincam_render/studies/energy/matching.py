"""Which conventional grid matches a minimalist camera's task error, from a study's table.

A study (``mincam-render study``, ``benchmarks/results/study_<family>.json``)
holds, per design, the test error's mean and 95 % interval. The reference is
the minimalist design with the most pixels (trained with the sensor model); the
matched baseline is the coarsest grid whose mean error is within the
reference's 95 % interval or better (``mean <= ci95 upper``): a conventional
camera that does the task as well. Without a study table the paper's own
matches are used (Sec. 7, and Sec. 5 for the toy task).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mincam_render.learn.train_config import ModelKind

#: The paper's matches: family -> (freeform pixels, baseline grid) of equal error.
PAPER_MATCHES: dict[str, tuple[int, tuple[int, int]]] = {
    "patches": (4, (32, 32)),
    "workspace": (2, (64, 64)),
    "lighting": (16, (12, 12)),
    "traffic": (16, (8, 14)),
}


@dataclass(frozen=True, kw_only=True)
class Match:
    """A minimalist design and the conventional grid of the same task error.

    Args:
        family: the task's scene family.
        pixels: freeform pixels of the reference design.
        grid: ``(rows, cols)`` of the matched baseline.
        source: where the match comes from (a study file, or the paper).
        mincam_error: the reference's mean error and 95 % interval, or None (paper).
        baseline_error: the baseline's mean error and 95 % interval, or None (paper).
        error_name: what the error measures (e.g. ``count RMSE``).
        matched: False when no grid of the study reached the reference's error (the
            finest grid tried is given).
    """

    family: str
    pixels: int
    grid: tuple[int, int]
    source: str
    mincam_error: tuple[float, float, float] | None = None
    baseline_error: tuple[float, float, float] | None = None
    error_name: str = ""
    matched: bool = True


def _kind(design: Mapping[str, Any]) -> ModelKind:
    """The kind of camera of a study's design record (``model.kind``)."""
    return ModelKind(design["model"]["kind"])


def _error(design: dict) -> tuple[float, float, float]:
    e = design["error"]
    return float(e["mean"]), float(e["ci95"][0]), float(e["ci95"][1])


def match_from_study(study: dict, source: str) -> Match:
    """The match read from a study's result (its ``designs`` table).

    Raises:
        ValueError: the table has no minimalist design or no baseline.
    """
    designs = study.get("designs", {})
    mincams = [
        (d["model"]["pixels"], name)
        for name, d in designs.items()
        if ModelKind(d["model"]["kind"]) is ModelKind.MINCAM
        and d["model"].get("sensor_model", True)
    ]
    grids = sorted(
        (d["model"]["grid"][0] * d["model"]["grid"][1], name)
        for name, d in designs.items()
        if _kind(d) is ModelKind.BASELINE
    )
    if not mincams or not grids:
        raise ValueError(f"{source}: need minimalist and baseline designs in 'designs'")
    pixels, ref = max(mincams)
    ref_err = _error(designs[ref])
    matched = [name for _, name in grids if _error(designs[name])[0] <= ref_err[2]]
    name = matched[0] if matched else grids[-1][1]
    grid = designs[name]["model"]["grid"]
    return Match(
        family=str(study.get("task", "")),
        pixels=int(pixels),
        grid=(int(grid[0]), int(grid[1])),
        source=source,
        mincam_error=ref_err,
        baseline_error=_error(designs[name]),
        error_name=str(study.get("error_name", "")),
        matched=bool(matched),
    )


def load_match(family: str, study_path: str | os.PathLike | None) -> Match:
    """The match of ``family``: from ``study_path`` if it exists, else the paper's.

    Raises:
        ValueError: a study file that is not a study result, or a family the paper
            has no match for (and no study file).
    """
    if study_path is not None and Path(study_path).is_file():
        try:
            study = json.loads(Path(study_path).read_text())
            return match_from_study(study, str(study_path))
        except (json.JSONDecodeError, KeyError, TypeError, IndexError) as err:
            raise ValueError(f"{study_path}: not a study result ({err})") from None
    if family not in PAPER_MATCHES:
        raise ValueError(f"no study table and no paper match for family {family!r}")
    pixels, grid = PAPER_MATCHES[family]
    return Match(family=family, pixels=pixels, grid=grid, source="paper Sec. 5/7")
