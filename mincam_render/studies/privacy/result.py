"""A privacy audit's result, typed: what :func:`~.study.run` returns and ``privacy.json`` holds.

:meth:`PrivacyResult.as_json` is ``privacy.json``: the same keys, in the same
order, as the dicts the audit wrote before it had these classes, so kept files
read back (:meth:`PrivacyResult.from_json`) and write again byte for byte.
Intervals are :class:`~mincam_render.analysis.statistics.Interval`
(``{"mean", "ci95": [lo, hi]}`` on disk). PSNR in dB; SSIM, foreground
fractions and top-1 accuracies are dimensionless, 0-1. The comparison's
records kept beside the audit (``config``, ``episodes``) stay JSON records:
they are the comparison's schema.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from mincam_render.analysis.statistics import Interval
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.comparison.config import Design, designs_by_name
from mincam_render.studies.privacy.config import DecoderKind

#: The reconstruction figures (foreground, then the whole view), in ``privacy.json``'s order.
IMAGE_FIGURES = ("fg_psnr_db", "fg_ssim", "psnr_db", "ssim")
#: Every attack figure, in ``privacy.json``'s order.
FIGURES = (*IMAGE_FIGURES, "reid_top1")

#: A training run's convergence record (:func:`~mincam_render.analysis.statistics.converged`):
#: ``converged``, ``improvement`` and ``steps``, with a null reason when undecided.
ConvergenceRecord = Mapping[str, float | bool | str | None]


def interval_from_json(record: Mapping[str, Any]) -> Interval:
    """An :class:`Interval` from ``{"mean", "ci95": [lo, hi]}`` (values as read)."""
    return Interval(record["mean"], record["ci95"][0], record["ci95"][1])


@dataclass(frozen=True, kw_only=True)
class EpisodeScores:
    """An attacker's figures on one test episode.

    Attributes:
        fg_psnr_db, fg_ssim: reconstruction of the people's pixels (dB; 0-1).
        psnr_db, ssim: reconstruction of the whole view (dB; 0-1).
        fg_fraction: share of the episode's pixels in the foreground (0-1; the
            trivial attacker's record only).
        fg_frames: frames with a foreground (the trivial attacker's only).
        reid_top1: re-identification top-1 accuracy (0-1; None for the prior).
    """

    fg_psnr_db: float
    fg_ssim: float
    psnr_db: float
    ssim: float
    fg_fraction: float | None = None
    fg_frames: int | None = None
    reid_top1: float | None = None

    def figure(self, name: str) -> float:
        """The figure called ``name`` (one of :data:`FIGURES`).

        Raises:
            KeyError: ``name`` is not a figure this record holds.
        """
        value = getattr(self, name, None) if name in FIGURES else None
        if value is None:
            raise KeyError(f"{name}: not a figure of this episode's record")
        return float(value)

    def as_json(self) -> JsonObject:
        """The set figures, in ``privacy.json``'s order."""
        keys = (*IMAGE_FIGURES, "fg_fraction", "fg_frames", "reid_top1")
        return {k: getattr(self, k) for k in keys if getattr(self, k) is not None}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> EpisodeScores:
        """A record as ``privacy.json`` holds it."""
        return cls(**{k: record[k] for k in record})


def _scores_json(episodes: Mapping[str, EpisodeScores]) -> JsonObject:
    return {name: s.as_json() for name, s in episodes.items()}


def _scores_from_json(record: Mapping[str, Any]) -> dict[str, EpisodeScores]:
    return {name: EpisodeScores.from_json(s) for name, s in record.items()}


@dataclass(frozen=True, kw_only=True)
class AttackFigures:
    """Attack figures with 95 % intervals over attacker seeds and test episodes.

    Attributes:
        fg_psnr_db, fg_ssim, psnr_db, ssim: reconstruction (dB; 0-1).
        reid_top1: re-identification top-1 (0-1); None where none was scored
            (the prior attacker, a decoder's own figures).
    """

    fg_psnr_db: Interval
    fg_ssim: Interval
    psnr_db: Interval
    ssim: Interval
    reid_top1: Interval | None = None

    def figure(self, name: str) -> Interval:
        """The interval of figure ``name`` (one of :data:`FIGURES`).

        Raises:
            KeyError: ``name`` is not a figure held here.
        """
        value = getattr(self, name, None) if name in FIGURES else None
        if value is None:
            raise KeyError(f"{name}: not an attack figure of this record")
        return value

    def as_json(self) -> JsonObject:
        """``{figure: {"mean", "ci95"}}`` in :data:`FIGURES` order."""
        return {f: getattr(self, f).as_dict() for f in FIGURES if getattr(self, f) is not None}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> AttackFigures:
        """The figures of a record that holds them beside other keys."""
        reid = record.get("reid_top1")
        return cls(
            **{f: interval_from_json(record[f]) for f in IMAGE_FIGURES},
            reid_top1=None if reid is None else interval_from_json(reid),
        )


@dataclass(frozen=True, kw_only=True)
class AttackConvergence:
    """Did one attacker seed's networks converge?

    Attributes:
        decoder: the kept decoder's (ridge, solved exactly, always converged).
        reid: the re-identifier's.
        decoders: every trained (not closed-form) decoder's, by kind.
    """

    decoder: ConvergenceRecord
    reid: ConvergenceRecord
    decoders: Mapping[DecoderKind, ConvergenceRecord]

    def as_json(self) -> JsonObject:
        """``{"decoder", "reid", "decoders"}``."""
        decoders = {k.value: dict(v) for k, v in self.decoders.items()}
        return {"decoder": dict(self.decoder), "reid": dict(self.reid), "decoders": decoders}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> AttackConvergence:
        """A record as ``privacy.json`` holds it."""
        return cls(
            decoder=record["decoder"],
            reid=record["reid"],
            decoders={DecoderKind(k): v for k, v in record["decoders"].items()},
        )


@dataclass(frozen=True, kw_only=True)
class DecoderChoice:
    """Which decoder one attacker seed kept, and why.

    Attributes:
        decoder: the kept one (the lowest validation error).
        decoder_val_mse: every decoder's validation mean squared error
            (display units squared).
        ridge_penalty: the ridge decoder's chosen penalty.
    """

    decoder: DecoderKind
    decoder_val_mse: Mapping[DecoderKind, float]
    ridge_penalty: float

    def as_json(self) -> JsonObject:
        """``{"decoder", "decoder_val_mse", "ridge_penalty"}``."""
        return {
            "decoder": self.decoder.value,
            "decoder_val_mse": {k.value: v for k, v in self.decoder_val_mse.items()},
            "ridge_penalty": self.ridge_penalty,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> DecoderChoice:
        """A record as ``privacy.json`` holds it."""
        return cls(
            decoder=DecoderKind(record["decoder"]),
            decoder_val_mse={DecoderKind(k): v for k, v in record["decoder_val_mse"].items()},
            ridge_penalty=record["ridge_penalty"],
        )


@dataclass(frozen=True, kw_only=True)
class AttackerSeed:
    """One attacker seed against one trained design (not written; :class:`DesignAttack` is).

    Attributes:
        episodes: per test episode, the kept decoder's figures and re-id top-1.
        by_decoder: per decoder, per test episode, its image figures.
        choice: the decoder kept.
        convergence: whether its networks converged.
    """

    episodes: Mapping[str, EpisodeScores]
    by_decoder: Mapping[DecoderKind, Mapping[str, EpisodeScores]]
    choice: DecoderChoice
    convergence: AttackConvergence


@dataclass(frozen=True, kw_only=True)
class DesignAttack:
    """Every attacker seed against one design: figures with intervals and their makings.

    Attributes:
        figures: :data:`FIGURES` with intervals.
        fg_psnr_gain_db: people PSNR minus the trivial attacker's, paired (dB).
        fg_psnr_over_prior_db: people PSNR minus the prior attacker's, paired (dB).
        by_decoder: each decoder's image figures, whichever the attacker kept.
        per_seed: per attacker seed, per test episode, the kept decoder's figures.
        convergence: per attacker seed.
        decoders: per attacker seed, the decoder kept.
    """

    figures: AttackFigures
    fg_psnr_gain_db: Interval
    fg_psnr_over_prior_db: Interval
    by_decoder: Mapping[DecoderKind, AttackFigures]
    per_seed: tuple[Mapping[str, EpisodeScores], ...]
    convergence: tuple[AttackConvergence, ...]
    decoders: tuple[DecoderChoice, ...]

    def as_json(self) -> JsonObject:
        """The attack's keys of a design's record in ``privacy.json``."""
        return {
            **self.figures.as_json(),
            "fg_psnr_gain_db": self.fg_psnr_gain_db.as_dict(),
            "fg_psnr_over_prior_db": self.fg_psnr_over_prior_db.as_dict(),
            "by_decoder": {k.value: f.as_json() for k, f in self.by_decoder.items()},
            "per_seed": [_scores_json(s) for s in self.per_seed],
            "convergence": [c.as_json() for c in self.convergence],
            "decoders": [d.as_json() for d in self.decoders],
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> DesignAttack:
        """The attack's keys of a design's record."""
        return cls(
            figures=AttackFigures.from_json(record),
            fg_psnr_gain_db=interval_from_json(record["fg_psnr_gain_db"]),
            fg_psnr_over_prior_db=interval_from_json(record["fg_psnr_over_prior_db"]),
            by_decoder={
                DecoderKind(k): AttackFigures.from_json(f) for k, f in record["by_decoder"].items()
            },
            per_seed=tuple(_scores_from_json(s) for s in record["per_seed"]),
            convergence=tuple(AttackConvergence.from_json(c) for c in record["convergence"]),
            decoders=tuple(DecoderChoice.from_json(d) for d in record["decoders"]),
        )


@dataclass(frozen=True, kw_only=True)
class DesignAudit:
    """One design: its task figures (from the comparison) and the attacks on it.

    Attributes:
        pixels: measurements per frame.
        task_error: the task's test error over training seeds and test episodes.
        task_state: how its training ended (``converged``, ``budget-limited``).
        task_seeds: training seeds of the task.
        attack: the attacks (:class:`DesignAttack`).
    """

    pixels: int
    task_error: Interval
    task_state: str
    task_seeds: int
    attack: DesignAttack

    def figure(self, name: str) -> Interval:
        """The interval of attack figure ``name``."""
        return self.attack.figures.figure(name)

    def as_json(self) -> JsonObject:
        """The design's record in ``privacy.json``."""
        return {
            "pixels": self.pixels,
            "task_error": self.task_error.as_dict(),
            "task_state": self.task_state,
            "task_seeds": self.task_seeds,
            **self.attack.as_json(),
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> DesignAudit:
        """A design's record as ``privacy.json`` holds it."""
        return cls(
            pixels=record["pixels"],
            task_error=interval_from_json(record["task_error"]),
            task_state=record["task_state"],
            task_seeds=record["task_seeds"],
            attack=DesignAttack.from_json(record),
        )


@dataclass(frozen=True, kw_only=True)
class TrivialAudit:
    """The trivial attacker (each frame's background: sees no one) and task predictor.

    Attributes:
        task_error: the trivial task predictor's error.
        figures: :data:`FIGURES` with intervals over the test episodes.
        fg_fraction: mean share of the test pixels in the foreground (0-1).
        episodes: per test episode, its figures with the foreground's size.
    """

    task_error: Interval
    figures: AttackFigures
    fg_fraction: float
    episodes: Mapping[str, EpisodeScores]

    def as_json(self) -> JsonObject:
        """``privacy.json``'s ``trivial``."""
        return {
            "task_error": self.task_error.as_dict(),
            **self.figures.as_json(),
            "fg_fraction": self.fg_fraction,
            "episodes": _scores_json(self.episodes),
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> TrivialAudit:
        """``privacy.json``'s ``trivial`` read back."""
        return cls(
            task_error=interval_from_json(record["task_error"]),
            figures=AttackFigures.from_json(record),
            fg_fraction=record["fg_fraction"],
            episodes=_scores_from_json(record["episodes"]),
        )


@dataclass(frozen=True, kw_only=True)
class PriorAudit:
    """The prior attacker: each frame's background plus where people usually are.

    Attributes:
        figures: :data:`IMAGE_FIGURES` with intervals over the test episodes.
        fg_psnr_gain_db: its people PSNR minus the trivial attacker's, paired (dB).
        episodes: per test episode, its image figures.
    """

    figures: AttackFigures
    fg_psnr_gain_db: Interval
    episodes: Mapping[str, EpisodeScores]

    def as_json(self) -> JsonObject:
        """``privacy.json``'s ``prior``."""
        return {
            **self.figures.as_json(),
            "fg_psnr_gain_db": self.fg_psnr_gain_db.as_dict(),
            "episodes": _scores_json(self.episodes),
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> PriorAudit:
        """``privacy.json``'s ``prior`` read back."""
        return cls(
            figures=AttackFigures.from_json(record),
            fg_psnr_gain_db=interval_from_json(record["fg_psnr_gain_db"]),
            episodes=_scores_from_json(record["episodes"]),
        )


@dataclass(frozen=True, kw_only=True)
class CornerVerdict:
    """A minimalist design against the task-matched baselines (:func:`~.curve.corner_verdicts`).

    Attributes:
        task_matched: baselines no better at the task.
        more_private_than: per attack figure, the matched baselines it beats.
        in_corner_against: matched baselines it beats on every attack figure.
        paired: per matched baseline, per attack figure, design - baseline, paired.
        paired_more_private_than: matched baselines below on every figure, paired.
        verdict: one line.
    """

    task_matched: tuple[str, ...]
    more_private_than: Mapping[str, tuple[str, ...]]
    in_corner_against: tuple[str, ...]
    paired: Mapping[str, Mapping[str, Interval]]
    paired_more_private_than: tuple[str, ...]
    verdict: str

    def as_json(self) -> JsonObject:
        """The verdict's record in ``privacy.json``'s ``corner``."""
        return {
            "task_matched": list(self.task_matched),
            "more_private_than": {f: list(b) for f, b in self.more_private_than.items()},
            "in_corner_against": list(self.in_corner_against),
            "paired": {b: {f: i.as_dict() for f, i in p.items()} for b, p in self.paired.items()},
            "paired_more_private_than": list(self.paired_more_private_than),
            "verdict": self.verdict,
        }

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> CornerVerdict:
        """A verdict's record read back."""
        return cls(
            task_matched=tuple(record["task_matched"]),
            more_private_than={f: tuple(b) for f, b in record["more_private_than"].items()},
            in_corner_against=tuple(record["in_corner_against"]),
            paired={
                b: {f: interval_from_json(i) for f, i in p.items()}
                for b, p in record["paired"].items()
            },
            paired_more_private_than=tuple(record["paired_more_private_than"]),
            verdict=record["verdict"],
        )


@dataclass(frozen=True, kw_only=True)
class PrivacyResult:
    """Everything a privacy audit found; ``privacy.json`` is :meth:`as_json`.

    Attributes:
        task: the scene family's name.
        error_name: the task's headline error (``people_count RMSE``).
        config: the audit's :class:`~.config.PrivacyConfig`, JSON-ready.
        roster: people of the roster.
        episodes: the comparison's episode records (``samples``, ``dataset``, ...).
        designs: every design's task and attack figures, in the comparison's order.
        trivial: the trivial attacker and task predictor.
        prior: the prior attacker.
        comparison: the path of the comparison's ``metrics.json``.
        corner: per minimalist design, its verdict (:func:`~.curve.corner_verdicts`).
    """

    task: str
    error_name: str
    config: JsonObject
    roster: int
    episodes: Mapping[str, Mapping[str, Any]]
    designs: Mapping[str, DesignAudit]
    trivial: TrivialAudit
    prior: PriorAudit
    comparison: str
    corner: Mapping[str, CornerVerdict]

    @property
    def seed(self) -> int:
        """The comparison's root seed (the intervals' bootstrap seed)."""
        return int(self.config["comparison"]["seed"])

    def design_kinds(self) -> dict[str, Design]:
        """``{name: design}`` of the audit's designs (from its ``config``, not their names)."""
        return designs_by_name(self.config["comparison"]["designs"])

    def samples(self) -> dict[str, int]:
        """Frames of every episode."""
        return {name: int(e["samples"]) for name, e in self.episodes.items()}

    def as_json(self) -> JsonObject:
        """``privacy.json``'s contents, key for key, in order."""
        return {
            "task": self.task,
            "error_name": self.error_name,
            "config": self.config,
            "roster": self.roster,
            "episodes": dict(self.episodes),
            "designs": {name: d.as_json() for name, d in self.designs.items()},
            "trivial": self.trivial.as_json(),
            "prior": self.prior.as_json(),
            "comparison": self.comparison,
            "corner": {name: c.as_json() for name, c in self.corner.items()},
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> PrivacyResult:
        """A result read back from ``privacy.json`` (a benchmark's extra keys are ignored)."""
        return cls(
            task=data["task"],
            error_name=data["error_name"],
            config=data["config"],
            roster=data["roster"],
            episodes=data["episodes"],
            designs={n: DesignAudit.from_json(d) for n, d in data["designs"].items()},
            trivial=TrivialAudit.from_json(data["trivial"]),
            prior=PriorAudit.from_json(data["prior"]),
            comparison=data["comparison"],
            corner={n: CornerVerdict.from_json(c) for n, c in data["corner"].items()},
        )
