"""Typed figures read from a comparison's result: a design's error, a paired difference.

A comparison (:func:`~mincam_render.studies.comparison.study.run_comparison`) writes
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
    """One design's test figure in one comparison (one task), and its validation figure.

    Args:
        design: the design's name.
        pixels: its pixels (for one task).
        error: mean over seeds of the test error pooled over test episodes.
        ci95: the 95 % bootstrap interval (seeds and test episodes).
        per_seed: each seed's pooled test error.
        state: ``converged``, ``early-stopped, not converged`` or ``budget-limited``.
        steps: each seed's steps.
        train_s_per_run: mean training wall time of a run (s).
        episode_errors: ``error[seed][episode]`` and frames, for paired differences.
        val_error: mean over seeds of the kept states' error pooled over the
            validation episodes (None for runs without them).
        val_ci95: its 95 % interval (seeds and validation episodes).
        validation_errors: those errors per seed and validation episode (the
            form of ``episode_errors``), or None.
        structure: a minimalist design's masks (its best-validation run):
            :class:`~mincam_render.analysis.mask_structure.MaskStructure` fields;
            None for a box camera.
    """

    design: str
    pixels: int
    error: float
    ci95: tuple[float, float]
    per_seed: tuple[float, ...]
    state: str
    steps: tuple[int, ...]
    train_s_per_run: float
    episode_errors: Mapping[str, Any]
    val_error: float | None = None
    val_ci95: tuple[float, float] | None = None
    validation_errors: Mapping[str, Any] | None = None
    structure: Mapping[str, Any] | None = None

    @classmethod
    def from_block(cls, block: Mapping[str, Any], name: str) -> DesignFigure:
        """Design ``name`` of a task's block of a comparison's result."""
        d = block["designs"][name]
        validation = d.get("validation")
        return cls(
            design=name,
            pixels=int(d["model"]["pixels"]),
            error=float(d["error"]["mean"]),
            ci95=(float(d["error"]["ci95"][0]), float(d["error"]["ci95"][1])),
            per_seed=tuple(float(e) for e in d["error_per_seed"]),
            state=str(d["state"]),
            steps=tuple(int(s) for s in d["steps"]),
            train_s_per_run=float(np.mean(d["train_wall_time_s"])),
            episode_errors=d["episode_errors"],
            val_error=None if validation is None else float(validation["error"]["mean"]),
            val_ci95=None if validation is None else tuple(validation["error"]["ci95"]),
            validation_errors=None if validation is None else validation["episode_errors"],
            structure=d.get("structure"),
        )

    def errors(self) -> EpisodeErrors:
        """The per-seed, per-episode test errors."""
        return EpisodeErrors.from_dict(self.episode_errors)

    def val(self) -> EpisodeErrors | None:
        """The per-seed, per-validation-episode errors (None if not recorded)."""
        v = self.validation_errors
        return None if v is None else EpisodeErrors.from_dict(v)

    @property
    def val_per_seed(self) -> tuple[float, ...]:
        """Each seed's error pooled over the validation episodes (empty if not recorded)."""
        v = self.val()
        if v is None:
            return ()
        episodes = np.arange(len(v.frames))
        return tuple(v.pooled(np.array([i]), episodes) for i in range(v.error.shape[0]))


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
        return cls.between(a.design, a.errors(), b.design, b.errors(), seed)

    @classmethod
    def between(
        cls, name_a: str, a: EpisodeErrors, name_b: str, b: EpisodeErrors, seed: int = 0
    ) -> Paired:
        """``a - b`` of two sets of errors on the same episodes."""
        diff = paired_difference(a, b, seed=seed)
        return cls(name_a, name_b, diff.mean, (diff.low, diff.high),
                   paired_statement(name_a, name_b, diff))  # fmt: skip

    @property
    def a_lower(self) -> bool:
        """``a`` has the lower error on these episodes (the interval lies below 0)."""
        return self.ci95[1] < 0
