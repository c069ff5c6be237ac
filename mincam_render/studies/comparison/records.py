"""The typed records of a comparison's result: an episode, a design, the trivial predictor, a label.

Each is what one entry of ``metrics.json`` holds, as a frozen record whose
``as_json()`` writes the same keys, in the same order, as the dicts the
comparison wrote before it had these classes, and whose ``from_json()`` reads
them back (``from_json(r).as_json() == r``; records with numpy arrays compare
through their JSON). Records of studies from before a field existed
(``benchmarks/results/study_*.json``) read back with that field None.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from mincam_render.analysis.mask_structure import MaskStructure
from mincam_render.analysis.statistics import EpisodeErrors, Interval
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.train_config import ModelKind

if TYPE_CHECKING:  # torch: imported where metrics are read back, not with the records
    from mincam_render.learn.builders import ModelRecord
    from mincam_render.learn.evaluation import Evaluation

#: Why the trivial predictor's episode metrics have no loss.
TRIVIAL_LOSS_REASON = "the trivial predictor has no training loss"


@dataclass(frozen=True, kw_only=True)
class EpisodeRecord:
    """One rendered episode of a comparison: its samples, provenance and manifest hash.

    Args:
        samples: the samples its training view holds.
        source: the view's provenance (``TrainingData.source``: dataset path,
            split, range, family, seed, and what a view changed), free-form.
        manifest_sha256: the sha256 of the dataset's manifest.
    """

    samples: int
    source: JsonObject
    manifest_sha256: str

    @property
    def dataset(self) -> str:
        """The episode dataset's directory."""
        return str(self.source["dataset"])

    def as_json(self) -> JsonObject:
        """``{"samples", **source, "manifest_sha256"}``."""
        return {"samples": self.samples, **self.source, "manifest_sha256": self.manifest_sha256}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EpisodeRecord:
        """Inverse of :meth:`as_json`."""
        source = {k: v for k, v in d.items() if k not in ("samples", "manifest_sha256")}
        return cls(samples=int(d["samples"]), source=source, manifest_sha256=d["manifest_sha256"])


@dataclass(frozen=True, kw_only=True)
class Convergence:
    """Whether a run converged (:func:`~mincam_render.analysis.statistics.converged`).

    Args:
        converged: the last doubling of steps improved the best validation loss < 2 %.
        improvement: that relative improvement (None when not measurable).
        steps: the run's last evaluated step.
        stopped_early: early stopping ended the run.
        improvement_null_reason: why ``improvement`` is None.
    """

    converged: bool
    improvement: float | None
    steps: int
    stopped_early: bool
    improvement_null_reason: str | None = None

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Convergence:
        """A run's record (also :func:`converged`'s dict with ``stopped_early``)."""
        return cls(
            converged=bool(d["converged"]),
            improvement=d["improvement"],
            steps=int(d["steps"]),
            stopped_early=bool(d["stopped_early"]),
            improvement_null_reason=d.get("improvement_null_reason"),
        )

    def as_json(self) -> JsonObject:
        """``converged``, ``improvement`` (and why it is null), ``steps``, ``stopped_early``."""
        out: JsonObject = {"converged": self.converged, "improvement": self.improvement}
        if self.improvement_null_reason is not None:
            out["improvement_null_reason"] = self.improvement_null_reason
        return out | {"steps": self.steps, "stopped_early": self.stopped_early}


def training_state(convergence: Sequence[Convergence]) -> str:
    """``converged`` (every run: last doubling of steps < 2 % better); else why not.

    ``early-stopped, not converged``: validation stopped improving for the
    patience window after the last learning-rate decay, yet the last doubling
    of steps still gained >= 2 % (noisy or slow); ``budget-limited``: some run
    used every step.
    """
    if all(c.converged for c in convergence):
        return "converged"
    if all(c.converged or c.stopped_early for c in convergence):
        return "early-stopped, not converged"
    return "budget-limited"


@dataclass(frozen=True, kw_only=True)
class ErrorFigures:
    """An error over seeds and episodes: its mean and 95 % interval, and the errors themselves."""

    error: Interval
    episode_errors: EpisodeErrors

    def as_json(self) -> JsonObject:
        """``{"error": {"mean", "ci95"}, "episode_errors": {...}}``."""
        return {"error": self.error.as_dict(), "episode_errors": self.episode_errors.as_dict()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> ErrorFigures:
        """Inverse of :meth:`as_json`."""
        return cls(error=Interval.from_dict(d["error"]),
                   episode_errors=EpisodeErrors.from_dict(d["episode_errors"]))  # fmt: skip


def _structure(d: Mapping[str, Any] | None) -> MaskStructure | None:
    return None if d is None else MaskStructure(**{k: tuple(v) for k, v in d.items()})


def _structure_json(s: MaskStructure) -> JsonObject:
    return {k: list(v) for k, v in dataclasses.asdict(s).items()}


@dataclass(frozen=True, kw_only=True)
class DesignRecord:
    """One design's figures over its runs, for one task (a block's ``designs[<name>]``).

    Args:
        model: the model's description (its first run's).
        error: the test error, mean over seeds, 95 % interval over seeds and test episodes.
        episode_errors: each seed's error on each test episode (None in studies
            from before it was kept).
        error_per_seed: each seed's pooled test error.
        val_error_per_seed: each run's pooled validation error at its kept step
            (None where not recorded; the field None in older studies).
        validation: the kept states' error on the validation episodes (None
            for runs without named validation episodes).
        convergence: each run's convergence.
        train_wall_time_s: each run's training wall time (s).
        steps: each run's steps.
        runs: each run's directory.
        structure: a minimalist design's masks' structure (its run of lowest
            validation loss); None for a baseline.
    """

    model: ModelRecord
    error: Interval
    episode_errors: EpisodeErrors | None
    error_per_seed: tuple[float, ...]
    val_error_per_seed: tuple[float | None, ...] | None
    validation: ErrorFigures | None
    convergence: tuple[Convergence, ...]
    train_wall_time_s: tuple[float, ...]
    steps: tuple[int, ...]
    runs: tuple[str, ...]
    structure: MaskStructure | None

    @property
    def converged(self) -> bool:
        """Every run converged."""
        return all(c.converged for c in self.convergence)

    @property
    def state(self) -> str:
        """:func:`training_state` of the runs."""
        return training_state(self.convergence)

    @property
    def pixels(self) -> int:
        """The design's pixels (for one task)."""
        return int(self.model["pixels"])

    @property
    def is_baseline(self) -> bool:
        """A baseline (its model's kind, never its name)."""
        return ModelKind(self.model["kind"]) is ModelKind.BASELINE

    @property
    def head(self) -> str:
        """The head's kind (``mlp`` unless the model names another)."""
        return self.model.get("head", "mlp")

    def as_json(self) -> JsonObject:
        """The record as ``metrics.json`` holds it."""
        return {
            "model": self.model,
            "error": self.error.as_dict(),
            "episode_errors": _opt(self.episode_errors, EpisodeErrors.as_dict),
            "error_per_seed": list(self.error_per_seed),
            "val_error_per_seed": _opt(self.val_error_per_seed, list),
            "validation": _opt(self.validation, ErrorFigures.as_json),
            "converged": self.converged,
            "state": self.state,
            "convergence": [c.as_json() for c in self.convergence],
            "train_wall_time_s": list(self.train_wall_time_s),
            "steps": list(self.steps),
            "runs": list(self.runs),
            "structure": _opt(self.structure, _structure_json),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> DesignRecord:
        """Inverse of :meth:`as_json` (fields a study predates read back as None)."""
        ep, val, per = d.get("episode_errors"), d.get("validation"), d.get("val_error_per_seed")
        return cls(
            model=d["model"],
            error=Interval.from_dict(d["error"]),
            episode_errors=None if ep is None else EpisodeErrors.from_dict(ep),
            error_per_seed=tuple(float(e) for e in d["error_per_seed"]),
            val_error_per_seed=None if per is None else tuple(per),
            validation=None if val is None else ErrorFigures.from_json(val),
            convergence=tuple(Convergence.from_json(c) for c in d["convergence"]),
            train_wall_time_s=tuple(float(t) for t in d["train_wall_time_s"]),
            steps=tuple(int(s) for s in d["steps"]),
            runs=tuple(d["runs"]),
            structure=_structure(d.get("structure")),
        )


def _opt(value: Any, as_json: Any) -> Any:
    """``as_json(value)``, or None for None."""
    return None if value is None else as_json(value)


def trivial_episode_json(metrics: Evaluation) -> JsonObject:
    """The trivial predictor's metrics on an episode: its loss null, with the reason."""
    return metrics.as_json() | {"loss": None, "loss_null_reason": TRIVIAL_LOSS_REASON}


def trivial_episode_from_json(record: Mapping[str, Any]) -> Evaluation:
    """Inverse of :func:`trivial_episode_json` (the loss NaN)."""
    from mincam_render.learn.evaluation import Evaluation

    figures = {k: v for k, v in record.items() if k != "loss_null_reason"}
    return Evaluation.from_json(figures | {"loss": float("nan")})


@dataclass(frozen=True, kw_only=True)
class TrivialFigures:
    """The trivial predictor (every label's training mean; the mode if binary) on the tests.

    Args:
        error: its pooled test error (a one-seed interval over the test episodes).
        episode_errors: its error on each test episode (None in older studies).
        episodes: its metrics on each test episode.
    """

    error: Interval
    episode_errors: EpisodeErrors | None
    episodes: Mapping[str, Evaluation]

    def as_json(self) -> JsonObject:
        """``{"error", "episode_errors", "episodes"}``."""
        return {
            "error": self.error.as_dict(),
            "episode_errors": _opt(self.episode_errors, EpisodeErrors.as_dict),
            "episodes": {k: trivial_episode_json(m) for k, m in self.episodes.items()},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> TrivialFigures:
        """Inverse of :meth:`as_json`."""
        ep = d.get("episode_errors")
        return cls(
            error=Interval.from_dict(d["error"]),
            episode_errors=None if ep is None else EpisodeErrors.from_dict(ep),
            episodes={k: trivial_episode_from_json(m) for k, m in d["episodes"].items()},
        )


def _intervals_json(configs: Mapping[str, Interval]) -> JsonObject:
    return {name: iv.as_dict() for name, iv in configs.items()}


def _intervals_of(d: Mapping[str, Any]) -> dict[str, Interval]:
    return {name: Interval.from_dict(iv) for name, iv in d.items()}


@dataclass(frozen=True, kw_only=True)
class LabelFigures:
    """One label's figure per configuration (designs and ``trivial``), with its interval.

    Args:
        metric: ``rmse`` (pooled as a root mean square over test frames) or
            ``accuracy`` (a mean; higher is better).
        unit: the label's unit (``""`` for accuracy).
        configs: ``{configuration: its figure and 95 % interval}``.
        elements: a BINARY label of several elements (lighting's lights):
            ``{element index: {configuration: its accuracy}}``; None otherwise.
    """

    metric: str
    unit: str
    configs: Mapping[str, Interval]
    elements: Mapping[str, Mapping[str, Interval]] | None = None

    def as_json(self) -> JsonObject:
        """``{"metric", "unit", "configs"[, "elements": {i: {"configs"}}]}``."""
        out: JsonObject = {"metric": self.metric, "unit": self.unit,
                           "configs": _intervals_json(self.configs)}  # fmt: skip
        if self.elements is not None:
            out["elements"] = {i: {"configs": _intervals_json(c)} for i, c in self.elements.items()}
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> LabelFigures:
        """Inverse of :meth:`as_json`."""
        elements = d.get("elements")
        return cls(
            metric=str(d["metric"]),
            unit=str(d["unit"]),
            configs=_intervals_of(d["configs"]),
            elements=None if elements is None else {
                i: _intervals_of(e["configs"]) for i, e in elements.items()
            },
        )  # fmt: skip


@dataclass(frozen=True, kw_only=True)
class KeptMasks:
    """The files of a design's kept masks (:func:`~.study.keep_run_masks`) and ``looks_at.png``."""

    png: tuple[str, ...]
    exr: str
    svg: str
    json: str
    looks_at: str
    pdf: str | None = None

    def as_json(self) -> JsonObject:
        """``{"png": [...], "exr", "svg"[, "pdf"], "json", "looks_at"}``."""
        out: JsonObject = {"png": list(self.png), "exr": self.exr, "svg": self.svg}
        if self.pdf is not None:
            out["pdf"] = self.pdf
        return out | {"json": self.json, "looks_at": self.looks_at}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> KeptMasks:
        """Inverse of :meth:`as_json`."""
        return cls(png=tuple(d["png"]), exr=d["exr"], svg=d["svg"], json=d["json"],
                   looks_at=d["looks_at"], pdf=d.get("pdf"))  # fmt: skip


#: Why ``not_of_this_comparison`` lists what it lists.
OTHERS_NOTE = (
    "left in these folders by an earlier comparison with other options: not of this "
    "one, and not in its figures"
)


@dataclass(frozen=True)
class FolderOthers:
    """What a comparison's folders hold besides its own entries (an earlier comparison's).

    Args:
        entries: ``{kind: names of other entries}`` of the kinds (``episodes``,
            ``runs``, ``masks``) that hold others.
    """

    entries: Mapping[str, tuple[str, ...]]

    def as_json(self) -> JsonObject:
        """``{kind: [names]}`` and a ``note`` when any kind holds others (else ``{}``)."""
        out: JsonObject = {kind: list(names) for kind, names in self.entries.items()}
        if out:
            out["note"] = OTHERS_NOTE
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FolderOthers:
        """Inverse of :meth:`as_json`."""
        return cls({kind: tuple(names) for kind, names in d.items() if kind != "note"})
