"""A comparison's result, typed: what :func:`~.study.run_comparison` returns and writes.

``metrics.json`` is :meth:`ComparisonResult.as_json`: the same keys, in the same
order, as the dicts the comparison wrote before it had these classes, so old
files read back (:meth:`ComparisonResult.from_json`) and new ones compare byte
for byte. The records of each design, the trivial predictor, paired
differences and labels stay JSON records (``Mapping``): the report and figure
code reads them as the file holds them, and :meth:`TaskComparison.figure`
reads a design's record into a typed :class:`~.figures.DesignFigure`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mincam_render.analysis.statistics import Interval
from mincam_render.core import strict_json
from mincam_render.studies.comparison.config import Protocol
from mincam_render.studies.comparison.figures import DesignFigure


def _interval(record: Mapping[str, Any]) -> Interval:
    """``{"mean", "ci95": [lo, hi]}`` as an :class:`Interval`."""
    return Interval(float(record["mean"]), float(record["ci95"][0]), float(record["ci95"][1]))


@dataclass(frozen=True, kw_only=True)
class TaskComparison:
    """One task's figures: every design, the trivial predictor, verdicts, every label.

    Args:
        error_name: the task's headline error (``count RMSE``, ``error rate``).
        designs: ``{design: its record}`` (error and interval, per seed, state,
            steps, training times, per-episode errors, mask structure).
        trivial: the trivial predictor's ``error``, ``episode_errors`` and ``episodes``.
        verdict: the first two designs' verdict (None unless exactly two designs).
        versus_trivial: ``{design: verdict against the trivial predictor}``.
        paired: ``{"A - B": {"mean", "ci95", "statement"}}`` on the same test episodes.
        labels: ``{label: its metric, unit and figure per design}``.
    """

    error_name: str
    designs: Mapping[str, Mapping[str, Any]]
    trivial: Mapping[str, Any]
    verdict: str | None
    versus_trivial: Mapping[str, str]
    paired: Mapping[str, Mapping[str, Any]]
    labels: Mapping[str, Mapping[str, Any]]

    @classmethod
    def from_json(cls, block: Mapping[str, Any]) -> TaskComparison:
        """A block as written in ``metrics.json`` (``tasks[<task>]``)."""
        return cls(
            error_name=str(block["error_name"]),
            designs=block["designs"],
            trivial=block["trivial"],
            verdict=block.get("verdict"),
            versus_trivial=block.get("versus_trivial", {}),
            paired=block.get("paired", {}),
            labels=block.get("labels", {}),
        )

    def as_json(self) -> dict[str, Any]:
        """The block as ``metrics.json`` holds it."""
        return {
            "error_name": self.error_name,
            "designs": self.designs,
            "trivial": self.trivial,
            "verdict": self.verdict,
            "versus_trivial": self.versus_trivial,
            "paired": self.paired,
            "labels": self.labels,
        }

    def figure(self, design: str) -> DesignFigure:
        """Design ``design``'s figures, typed."""
        return DesignFigure.from_block(self.as_json(), design)

    def train_seconds(self, design: str) -> float:
        """The training wall time of all of ``design``'s runs (s)."""
        return float(sum(self.designs[design]["train_wall_time_s"]))

    @property
    def trivial_error(self) -> Interval:
        """The trivial predictor's error and 95 % interval."""
        return _interval(self.trivial["error"])

    @property
    def paired_statements(self) -> tuple[str, ...]:
        """Each paired difference as a sentence."""
        return tuple(str(p["statement"]) for p in self.paired.values())


@dataclass(frozen=True, kw_only=True)
class CombinedCamera:
    """A design as one camera for every task trained: its pixels and each task's error."""

    pixels: int
    tasks: Mapping[str, Mapping[str, Any]]

    def as_json(self) -> dict[str, Any]:
        """``{"pixels", "tasks"}``."""
        return {"pixels": self.pixels, "tasks": self.tasks}


@dataclass(frozen=True, kw_only=True)
class ReductionFactor:
    """Pixel reduction of the reference design at equal error (the paper's 256x, 2048x).

    Args:
        reference: the reference design.
        baseline: the grid (``RxC``) of the smallest baseline that reaches it,
            None if none does.
        factor: that baseline's pixels over the reference's, None if none does.
        largest_tried_factor: the largest baseline's pixels over the
            reference's (None without baselines).
    """

    reference: str
    baseline: str | None
    factor: float | None
    largest_tried_factor: float | None

    def as_json(self) -> dict[str, Any]:
        """The four fields, in this order."""
        return {
            "reference": self.reference,
            "baseline": self.baseline,
            "factor": self.factor,
            "largest_tried_factor": self.largest_tried_factor,
        }


@dataclass(frozen=True, kw_only=True)
class StudySummary:
    """What a study (a sweep of designs) adds to its comparison.

    Args:
        reduction_factor: the reference design's pixel reduction at equal error.
        configurations: per design, its headline figures by name
            (:func:`~.study.study_summary`).
        reference_verdicts: the reference against every baseline, and the
            paired differences, as sentences.
    """

    reduction_factor: ReductionFactor
    configurations: Mapping[str, Mapping[str, Any]]
    reference_verdicts: tuple[str, ...]

    def as_json(self) -> dict[str, Any]:
        """The three keys a study adds to ``metrics.json``."""
        return {
            "reduction_factor": self.reduction_factor.as_json(),
            "configurations": self.configurations,
            "reference_verdicts": list(self.reference_verdicts),
        }


@dataclass(frozen=True, kw_only=True)
class ComparisonResult:
    """Everything a comparison found (module docstring); ``metrics.json`` is :meth:`as_json`.

    Args:
        family: the scene family's name (``task`` in the file).
        protocol: a camera per task or one joint camera.
        config: the comparison's configuration, JSON-ready.
        episodes: ``{episode: its samples, source and manifest checksum}``.
        labels: every task's labels, ``{label: its figures}``.
        tasks: ``{task: its figures}``; the first is the headline, which the
            file also holds at its top level.
        combined: each design as one camera for every task.
        element_names: ``{label: names of its elements}`` (lighting's lights).
        coverage: the label coverage of every split and its warnings.
        figure: the path of ``comparison.png``.
        versions: the versions of the packages that computed it.
        masks: the records of the kept masks (None when none were kept).
        not_of_this_comparison: what the comparison's folders hold that is not
            its own (None before it was looked at; ``{}`` when nothing is).
        study: what a study adds (None for a plain comparison).
    """

    family: str
    protocol: Protocol
    config: Mapping[str, Any]
    episodes: Mapping[str, Mapping[str, Any]]
    labels: Mapping[str, Mapping[str, Any]]
    tasks: Mapping[str, TaskComparison]
    combined: Mapping[str, CombinedCamera]
    element_names: Mapping[str, tuple[str, ...]]
    coverage: Mapping[str, Any]
    figure: str
    versions: Mapping[str, str]
    masks: Mapping[str, Any] | None = None
    not_of_this_comparison: Mapping[str, Any] | None = None
    study: StudySummary | None = None

    @property
    def headline(self) -> TaskComparison:
        """The first task's figures."""
        return next(iter(self.tasks.values()))

    def as_json(self) -> dict[str, Any]:
        """``metrics.json``'s contents: the comparison's dict, key for key, in order."""
        out: dict[str, Any] = {
            "task": self.family,
            "protocol": self.protocol.value,
            "config": self.config,
            "episodes": self.episodes,
            **self.headline.as_json(),
            "labels": self.labels,  # every task's, in the headline's place
            "tasks": {task: block.as_json() for task, block in self.tasks.items()},
            "combined": {name: c.as_json() for name, c in self.combined.items()},
            "element_names": {k: list(v) for k, v in self.element_names.items()},
            "coverage": self.coverage,
            "figure": self.figure,
            "versions": self.versions,
        }
        if self.masks is not None:
            out["masks"] = self.masks
        if self.not_of_this_comparison is not None:
            out["not_of_this_comparison"] = self.not_of_this_comparison
        if self.study is not None:
            out |= self.study.as_json()
        return out

    def write(self, path: str | Path) -> None:
        """Write :meth:`as_json` as strict JSON (one line and a newline) to ``path``."""
        Path(path).write_text(strict_json.dumps(self.as_json()) + "\n")

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ComparisonResult:
        """A result read back from ``metrics.json``."""
        tasks = {t: TaskComparison.from_json(b) for t, b in data["tasks"].items()}
        study = None
        if "reduction_factor" in data:
            study = StudySummary(
                reduction_factor=ReductionFactor(**data["reduction_factor"]),
                configurations=data["configurations"],
                reference_verdicts=tuple(data["reference_verdicts"]),
            )
        return cls(
            family=str(data["task"]),
            protocol=Protocol(data["protocol"]),
            config=data["config"],
            episodes=data["episodes"],
            labels=data["labels"],
            tasks=tasks,
            combined={
                name: CombinedCamera(pixels=int(c["pixels"]), tasks=c["tasks"])
                for name, c in data["combined"].items()
            },
            element_names={k: tuple(v) for k, v in data["element_names"].items()},
            coverage=data["coverage"],
            figure=str(data["figure"]),
            versions=data["versions"],
            masks=data.get("masks"),
            not_of_this_comparison=data.get("not_of_this_comparison"),
            study=study,
        )

    def block(self, task: str) -> TaskComparison:
        """The figures of ``task`` (the headline's if the cameras were joint)."""
        return self.tasks[task] if task in self.tasks else next(iter(self.tasks.values()))
