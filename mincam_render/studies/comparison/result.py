"""A comparison's result, typed: what :func:`~.study.run` returns and writes.

``metrics.json`` is :meth:`ComparisonResult.as_json`: the same keys, in the same
order, as the dicts the comparison wrote before it had these classes, so old
files read back (:meth:`ComparisonResult.from_json`) and new ones compare byte
for byte. Each block is a typed record (:mod:`~.records`): a design's figures,
the trivial predictor's, every label's, paired differences; the configuration
stays the JSON of the :class:`~.config.ComparisonConfig` that produced it (its
resolved record, written next to the output).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mincam_render.analysis.coverage import StudyCoverage
from mincam_render.analysis.statistics import Interval
from mincam_render.core import strict_json
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.comparison.config import Protocol
from mincam_render.studies.comparison.figures import DesignFigure, Paired
from mincam_render.studies.comparison.records import (
    DesignRecord,
    EpisodeRecord,
    FolderOthers,
    KeptMasks,
    LabelFigures,
    TrivialFigures,
)


@dataclass(frozen=True, kw_only=True)
class TaskComparison:
    """One task's figures: every design, the trivial predictor, verdicts, every label.

    Args:
        error_name: the task's headline error (``count RMSE``, ``error rate``).
        designs: ``{design: its record}`` (error and interval, per seed, state,
            steps, training times, per-episode errors, mask structure).
        trivial: the trivial predictor's error, per-episode errors and metrics.
        verdict: the first two designs' verdict (None unless exactly two designs).
        versus_trivial: ``{design: verdict against the trivial predictor}``.
        paired: ``{"A - B": the difference}`` on the same test episodes.
        labels: ``{label: its metric, unit and figure per design}``.
    """

    error_name: str
    designs: Mapping[str, DesignRecord]
    trivial: TrivialFigures
    verdict: str | None
    versus_trivial: Mapping[str, str]
    paired: Mapping[str, Paired]
    labels: Mapping[str, LabelFigures]

    @classmethod
    def from_json(cls, block: Mapping[str, Any]) -> TaskComparison:
        """A block as written in ``metrics.json`` (``tasks[<task>]``)."""
        return cls(
            error_name=str(block["error_name"]),
            designs={n: DesignRecord.from_json(d) for n, d in block["designs"].items()},
            trivial=TrivialFigures.from_json(block["trivial"]),
            verdict=block.get("verdict"),
            versus_trivial=block.get("versus_trivial", {}),
            paired={k: Paired.from_json(k, p) for k, p in block.get("paired", {}).items()},
            labels={k: LabelFigures.from_json(v) for k, v in block.get("labels", {}).items()},
        )

    def as_json(self) -> JsonObject:
        """The block as ``metrics.json`` holds it."""
        return {
            "error_name": self.error_name,
            "designs": {name: d.as_json() for name, d in self.designs.items()},
            "trivial": self.trivial.as_json(),
            "verdict": self.verdict,
            "versus_trivial": dict(self.versus_trivial),
            "paired": {key: p.as_json() for key, p in self.paired.items()},
            "labels": {name: lab.as_json() for name, lab in self.labels.items()},
        }

    def figure(self, design: str) -> DesignFigure:
        """Design ``design``'s figures, typed."""
        return DesignFigure.of(design, self.designs[design])

    def train_seconds(self, design: str) -> float:
        """The training wall time of all of ``design``'s runs (s)."""
        return float(sum(self.designs[design].train_wall_time_s))

    @property
    def trivial_error(self) -> Interval:
        """The trivial predictor's error and 95 % interval."""
        return self.trivial.error

    @property
    def paired_statements(self) -> tuple[str, ...]:
        """Each paired difference as a sentence."""
        return tuple(p.statement for p in self.paired.values())


@dataclass(frozen=True, kw_only=True)
class CombinedCamera:
    """A design as one camera for every task trained: its pixels and each task's error."""

    pixels: int
    tasks: Mapping[str, Interval]

    def as_json(self) -> JsonObject:
        """``{"pixels", "tasks": {task: {"mean", "ci95"}}}``."""
        return {"pixels": self.pixels, "tasks": {t: iv.as_dict() for t, iv in self.tasks.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CombinedCamera:
        """Inverse of :meth:`as_json`."""
        tasks = {t: Interval.from_dict(iv) for t, iv in d["tasks"].items()}
        return cls(pixels=int(d["pixels"]), tasks=tasks)


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

    def as_json(self) -> JsonObject:
        """The four fields, in this order."""
        return {
            "reference": self.reference,
            "baseline": self.baseline,
            "factor": self.factor,
            "largest_tried_factor": self.largest_tried_factor,
        }


@dataclass(frozen=True, kw_only=True)
class DesignSummary:
    """A design's headline figure in a study's ``configurations`` (:func:`~.study.study_summary`).

    Args:
        error: the headline error and its 95 % interval.
        error_rate: the headline is an error rate (else an RMSE).
        unit: the RMSE's unit, where the headline's labels share one (traffic:
            ``mph``; ``""`` otherwise).
        seeds: training seeds.
        converged: every run converged.
    """

    error: Interval
    error_rate: bool
    unit: str
    seeds: int
    converged: bool

    def as_json(self) -> JsonObject:
        """``rmse_mean``/``rmse_ci95`` (or ``error_rate_*``), then ``seeds``, ``converged``.

        An error rate also gives ``accuracy_mean``/``accuracy_ci95`` (one minus
        it); an RMSE in a unit also ``rmse_<unit>_mean``/``rmse_<unit>_ci95``.
        """
        kind = "error_rate" if self.error_rate else "rmse"
        mean, lo, hi = self.error.mean, self.error.low, self.error.high
        row: JsonObject = {f"{kind}_mean": mean, f"{kind}_ci95": [lo, hi]}
        if self.error_rate:
            row |= {"accuracy_mean": 1.0 - mean, "accuracy_ci95": [1.0 - hi, 1.0 - lo]}
        elif self.unit:
            row |= {f"rmse_{self.unit}_mean": mean, f"rmse_{self.unit}_ci95": [lo, hi]}
        return row | {"seeds": self.seeds, "converged": self.converged}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DesignSummary:
        """Inverse of :meth:`as_json`."""
        rate = "error_rate_mean" in d
        kind = "error_rate" if rate else "rmse"
        units = [k[5:-5] for k in d if k.startswith("rmse_") and k.endswith("_mean")]
        units = [u for u in units if u]
        return cls(
            error=Interval(float(d[f"{kind}_mean"]), *map(float, d[f"{kind}_ci95"])),
            error_rate=rate,
            unit="" if rate or not units else units[0],
            seeds=int(d["seeds"]),
            converged=bool(d["converged"]),
        )


@dataclass(frozen=True, kw_only=True)
class StudySummary:
    """What a study (a sweep of designs) adds to its comparison.

    Args:
        reduction_factor: the reference design's pixel reduction at equal error.
        configurations: per design, its headline figures (:func:`~.study.study_summary`).
        reference_verdicts: the reference against every baseline, and the
            paired differences, as sentences.
    """

    reduction_factor: ReductionFactor
    configurations: Mapping[str, DesignSummary]
    reference_verdicts: tuple[str, ...]

    def as_json(self) -> JsonObject:
        """The three keys a study adds to ``metrics.json``."""
        return {
            "reduction_factor": self.reduction_factor.as_json(),
            "configurations": {n: c.as_json() for n, c in self.configurations.items()},
            "reference_verdicts": list(self.reference_verdicts),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> StudySummary:
        """The study's keys of ``metrics.json``."""
        return cls(
            reduction_factor=ReductionFactor(**d["reduction_factor"]),
            configurations={n: DesignSummary.from_json(c) for n, c in d["configurations"].items()},
            reference_verdicts=tuple(d["reference_verdicts"]),
        )


@dataclass(frozen=True, kw_only=True)
class ComparisonResult:
    """Everything a comparison found (module docstring); ``metrics.json`` is :meth:`as_json`.

    Args:
        family: the scene family's name (``task`` in the file).
        protocol: a camera per task or one joint camera.
        config: the comparison's configuration as JSON (``dataclasses.asdict``
            of its :class:`~.config.ComparisonConfig`, enums as strings).
        episodes: ``{episode: its samples, source and manifest checksum}``.
        labels: every task's labels, ``{label: its figures}``.
        tasks: ``{task: its figures}``; the first is the headline, which the
            file also holds at its top level.
        combined: each design as one camera for every task.
        element_names: ``{label: names of its elements}`` (lighting's lights).
        coverage: the label coverage of every split and its warnings.
        figure: the path of ``comparison.png``.
        versions: the versions of the packages that computed it.
        masks: the kept masks of each minimalist design (None when none were kept).
        not_of_this_comparison: what the comparison's folders hold that is not
            its own (None before it was looked at).
        study: what a study adds (None for a plain comparison).
    """

    family: str
    protocol: Protocol
    config: JsonObject
    episodes: Mapping[str, EpisodeRecord]
    labels: Mapping[str, LabelFigures]
    tasks: Mapping[str, TaskComparison]
    combined: Mapping[str, CombinedCamera]
    element_names: Mapping[str, tuple[str, ...]]
    coverage: StudyCoverage
    figure: str
    versions: Mapping[str, str]
    masks: Mapping[str, KeptMasks] | None = None
    not_of_this_comparison: FolderOthers | None = None
    study: StudySummary | None = None

    @property
    def headline(self) -> TaskComparison:
        """The first task's figures."""
        return next(iter(self.tasks.values()))

    @property
    def seed(self) -> int:
        """The comparison's root seed (it seeds the bootstrap)."""
        return int(self.config.get("seed", 0))

    def as_json(self) -> JsonObject:
        """``metrics.json``'s contents: the comparison's dict, key for key, in order."""
        out: JsonObject = {
            "task": self.family,
            "protocol": self.protocol.value,
            "config": self.config,
            "episodes": {k: e.as_json() for k, e in self.episodes.items()},
            **self.headline.as_json(),
            # every task's, in the headline's place
            "labels": {k: lab.as_json() for k, lab in self.labels.items()},
            "tasks": {task: block.as_json() for task, block in self.tasks.items()},
            "combined": {name: c.as_json() for name, c in self.combined.items()},
            "element_names": {k: list(v) for k, v in self.element_names.items()},
            "coverage": self.coverage.as_json(),
            "figure": self.figure,
            "versions": dict(self.versions),
        }
        if self.masks is not None:
            out["masks"] = {k: m.as_json() for k, m in self.masks.items()}
        if self.not_of_this_comparison is not None:
            out["not_of_this_comparison"] = self.not_of_this_comparison.as_json()
        if self.study is not None:
            out |= self.study.as_json()
        return out

    def write(self, path: str | Path) -> None:
        """Write :meth:`as_json` as strict JSON (one line and a newline) to ``path``."""
        Path(path).write_text(strict_json.dumps(self.as_json()) + "\n")

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ComparisonResult:
        """A result read back from ``metrics.json``."""
        masks, others = data.get("masks"), data.get("not_of_this_comparison")
        return cls(
            family=str(data["task"]),
            protocol=Protocol(data["protocol"]),
            config=dict(data["config"]),
            episodes={k: EpisodeRecord.from_json(e) for k, e in data["episodes"].items()},
            labels={k: LabelFigures.from_json(v) for k, v in data["labels"].items()},
            tasks={t: TaskComparison.from_json(b) for t, b in data["tasks"].items()},
            combined={n: CombinedCamera.from_json(c) for n, c in data["combined"].items()},
            element_names={k: tuple(v) for k, v in data["element_names"].items()},
            coverage=StudyCoverage.from_json(data["coverage"]),
            figure=str(data["figure"]),
            versions=dict(data["versions"]),
            masks=None if masks is None else {k: KeptMasks.from_json(m) for k, m in masks.items()},
            not_of_this_comparison=None if others is None else FolderOthers.from_json(others),
            study=StudySummary.from_json(data) if "reduction_factor" in data else None,
        )

    @classmethod
    def read(cls, path: str | Path) -> ComparisonResult:
        """The result of a ``metrics.json`` file."""
        import json

        return cls.from_json(json.loads(Path(path).read_text()))

    def block(self, task: str) -> TaskComparison:
        """The figures of ``task`` (the headline's if the cameras were joint)."""
        return self.tasks[task] if task in self.tasks else next(iter(self.tasks.values()))
