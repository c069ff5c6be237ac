"""Typed figures of a comparison's design, and paired differences.

A comparison (:func:`~mincam_render.studies.comparison.study.run`) keeps each
design's figures as a :class:`~.records.DesignRecord`; the studies built on it
(design protocol, task-level fidelity) read what they report into
:class:`DesignFigure` (flat, one interval and the errors' JSON form, as their
reports hold it) and compare two designs with :class:`Paired`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from mincam_render.analysis.mask_structure import MaskStructure
from mincam_render.analysis.statistics import (
    EpisodeErrors,
    EpisodeErrorsJson,
    Interval,
    paired_difference,
    paired_statement,
)
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.comparison.records import DesignRecord


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
        structure: a minimalist design's masks (its best-validation run);
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
    episode_errors: EpisodeErrorsJson
    val_error: float | None = None
    val_ci95: tuple[float, float] | None = None
    validation_errors: EpisodeErrorsJson | None = None
    structure: MaskStructure | None = None

    @classmethod
    def of(cls, name: str, d: DesignRecord) -> DesignFigure:
        """Design ``name``'s figures from its record in a task's block.

        Raises:
            ValueError: the record keeps no per-episode errors (an older study).
        """
        if d.episode_errors is None:
            raise ValueError(f"{name}: the record keeps no per-episode test errors")
        v = d.validation
        return cls(
            design=name,
            pixels=d.pixels,
            error=d.error.mean,
            ci95=(d.error.low, d.error.high),
            per_seed=d.error_per_seed,
            state=d.state,
            steps=d.steps,
            train_s_per_run=float(np.mean(d.train_wall_time_s)),
            episode_errors=d.episode_errors.as_dict(),
            val_error=None if v is None else v.error.mean,
            val_ci95=None if v is None else (v.error.low, v.error.high),
            validation_errors=None if v is None else v.episode_errors.as_dict(),
            structure=d.structure,
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
    def key(self) -> str:
        """``"a - b"``: its key among a block's paired differences."""
        return f"{self.a} - {self.b}"

    def as_json(self) -> JsonObject:
        """``{"mean", "ci95", "statement"}``: its record in a block's ``paired``."""
        return Interval(self.mean, *self.ci95).as_dict() | {"statement": self.statement}

    @classmethod
    def from_json(cls, key: str, d: Mapping[str, Any]) -> Paired:
        """The difference of :meth:`as_json`'s record under ``key`` (``"a - b"``)."""
        a, b = key.split(" - ", 1)
        iv = Interval.from_dict(d)
        return cls(a, b, iv.mean, (iv.low, iv.high), str(d["statement"]))

    @property
    def a_lower(self) -> bool:
        """``a`` has the lower error on these episodes (the interval lies below 0)."""
        return self.ci95[1] < 0
