"""Typed figures read from a comparison's result: a design's error, a paired difference.

A comparison (:func:`~mincam_render.analysis.comparison.run_comparison`) writes
its figures as JSON-ready dicts; the study reads what it reports into these
frozen records once, so its tables and checks work on named fields.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mincam_render.analysis.statistics import EpisodeErrors, paired_difference, paired_statement


@dataclass(frozen=True)
class DesignFigure:
    """One design's test figure in one comparison (one task).

    Args:
        design: the design's name.
        pixels: its pixels (for one task).
        error: mean over seeds of the test error pooled over test episodes.
        ci95: the 95 % bootstrap interval (seeds and test episodes).
        per_seed: each seed's pooled test error.
        val_per_seed: each seed's pooled validation error at its kept
            (best-validation) state; None for a run that did not record it.
        state: ``converged``, ``early-stopped, not converged`` or ``budget-limited``.
        steps: each seed's steps.
        train_s_per_run: mean training wall time of a run (s).
        episode_errors: ``error[seed][episode]`` and frames, for paired differences.
    """

    design: str
    pixels: int
    error: float
    ci95: tuple[float, float]
    per_seed: tuple[float, ...]
    val_per_seed: tuple[float | None, ...]
    state: str
    steps: tuple[int, ...]
    train_s_per_run: float
    episode_errors: Mapping[str, Any]

    @classmethod
    def from_block(cls, block: Mapping[str, Any], name: str) -> DesignFigure:
        """Design ``name`` of a task's block of a comparison's result."""
        d = block["designs"][name]
        vals = d.get("val_error_per_seed") or [None] * len(d["error_per_seed"])
        return cls(
            design=name,
            pixels=int(d["model"]["pixels"]),
            error=float(d["error"]["mean"]),
            ci95=(float(d["error"]["ci95"][0]), float(d["error"]["ci95"][1])),
            per_seed=tuple(float(e) for e in d["error_per_seed"]),
            val_per_seed=tuple(None if v is None else float(v) for v in vals),
            state=str(d["state"]),
            steps=tuple(int(s) for s in d["steps"]),
            train_s_per_run=float(np.mean(d["train_wall_time_s"])),
            episode_errors=d["episode_errors"],
        )

    @property
    def val_error(self) -> float | None:
        """Mean over seeds of the pooled validation error (None if a run lacks it)."""
        vals = self.val_per_seed
        return None if None in vals else float(np.mean(vals))  # type: ignore[arg-type]

    def errors(self) -> EpisodeErrors:
        """The per-seed, per-episode test errors."""
        return EpisodeErrors.from_dict(self.episode_errors)


@dataclass(frozen=True)
class Paired:
    """``a - b`` on the same test episodes, with its 95 % interval and a sentence."""

    a: str
    b: str
    mean: float
    ci95: tuple[float, float]
    statement: str

    @classmethod
    def of(cls, a: DesignFigure, b: DesignFigure, seed: int = 0) -> Paired:
        """The paired difference of two designs tested on the same episodes."""
        diff = paired_difference(a.errors(), b.errors(), seed=seed)
        return cls(a.design, b.design, diff.mean, (diff.low, diff.high),
                   paired_statement(a.design, b.design, diff))  # fmt: skip

    @property
    def a_lower(self) -> bool:
        """``a`` has the lower error on these episodes (the interval lies below 0)."""
        return self.ci95[1] < 0
