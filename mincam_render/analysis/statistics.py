"""Statistics of a comparison: pooled test error, bootstrap intervals, convergence, verdicts.

A configuration (one camera design) is trained with several seeds and tested on
several independent scene episodes. Its figure is the mean over seeds of the
error pooled over the test episodes (RMSE pooled as the root of the mean
squared error over all test frames; an error rate as the mean over all frames).
Frames within an episode are correlated in time, so the unit of resampling is
the episode, not the frame: :func:`bootstrap_interval` resamples test episodes
and training seeds independently (``scipy.stats.bootstrap``, percentile
method; with 3 episodes and 3 seeds the interval is coarse, and honest about it).

"A beats B" holds only where the two 95 % intervals do not overlap
(:func:`verdict`). Two designs tested on the same episodes also get the
interval of their difference (:func:`paired_difference`): the episodes are
resampled once for both, so an episode that is hard for every camera moves both
errors together and drops out of the difference; the separate intervals keep
that shared variation. The paired interval is reported beside the verdict; the
verdict itself stays the stricter separate-interval rule. A run counts as
converged when the last doubling of its steps improved its best validation loss
by less than 2 % (:func:`converged`).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypedDict

import numpy as np

#: Confidence level of every interval.
CONFIDENCE = 0.95
#: Bootstrap resamples.
RESAMPLES = 4000
#: A run is converged when its last doubling of steps improved less than this.
CONVERGED_IMPROVEMENT = 0.02


class Pooling(enum.StrEnum):
    """How an episode's per-frame errors pool into one figure (``EpisodeErrors``)."""

    RMS = "rms"  # root mean square over frames: RMSE
    MEAN = "mean"  # mean over frames: error rates, accuracies, attack figures


class EpisodeErrorsJson(TypedDict):
    """:class:`EpisodeErrors` as JSON holds it (read back by :meth:`EpisodeErrors.from_dict`)."""

    error: list[list[float]]
    frames: list[float]
    pooling: str


@dataclass(frozen=True)
class EpisodeErrors:
    """Test errors of one configuration: ``error[seed, episode]`` and frames per episode.

    Args:
        error: ``[seeds, episodes]`` RMSE (``Pooling.RMS``) or error rate
            (``Pooling.MEAN``) of each seed on each test episode.
        frames: ``[episodes]`` test frames of each episode (the pooling weights).
        pooling: :class:`Pooling` (or its value, ``"rms"``/``"mean"``, as JSON holds it).

    Raises:
        ValueError: shapes that do not match, non-finite errors, an episode
            without frames, or an unknown pooling (naming the allowed ones).
    """

    error: np.ndarray
    frames: np.ndarray
    pooling: Pooling

    def __post_init__(self) -> None:
        err = np.asarray(self.error, np.float64)
        n = np.asarray(self.frames, np.float64)
        if err.ndim != 2 or err.shape[1] != n.shape[0] or err.size == 0:
            raise ValueError(
                f"error has shape {err.shape}, frames {n.shape}: expected (seeds, episodes) "
                "and (episodes,), non-empty"
            )
        if not np.all(np.isfinite(err)) or np.any(n <= 0):
            raise ValueError("errors must be finite and every episode must have frames")
        try:
            object.__setattr__(self, "pooling", Pooling(self.pooling))
        except ValueError:
            allowed = ", ".join(repr(p.value) for p in Pooling)
            raise ValueError(f"pooling = {self.pooling!r}: allowed {allowed}") from None
        object.__setattr__(self, "error", err)
        object.__setattr__(self, "frames", n)

    def pooled(self, seeds: np.ndarray, episodes: np.ndarray) -> float:
        """Mean over ``seeds`` of the error pooled over ``episodes`` (index arrays)."""
        e = self.error[np.ix_(seeds, episodes)]
        w = self.frames[episodes] / self.frames[episodes].sum()
        per_seed = np.sqrt((e**2) @ w) if self.pooling is Pooling.RMS else e @ w
        return float(per_seed.mean())

    def as_dict(self) -> EpisodeErrorsJson:
        """JSON form: ``{"error": [[seed x episode]], "frames": [...], "pooling": ...}``."""
        return {
            "error": self.error.tolist(),
            "frames": self.frames.tolist(),
            "pooling": self.pooling.value,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EpisodeErrors:
        """Inverse of :meth:`as_dict`."""
        return cls(np.asarray(d["error"]), np.asarray(d["frames"]), d["pooling"])

    def point(self) -> float:
        """The configuration's figure: every seed, every episode."""
        s, e = self.error.shape
        return self.pooled(np.arange(s), np.arange(e))


@dataclass(frozen=True)
class Interval:
    """A point estimate and its 95 % bootstrap interval."""

    mean: float
    low: float
    high: float

    def as_dict(self) -> dict[str, float | list[float]]:
        """``{"mean": m, "ci95": [lo, hi]}`` for JSON."""
        return {"mean": self.mean, "ci95": [self.low, self.high]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Interval:
        """Inverse of :meth:`as_dict`."""
        return cls(float(d["mean"]), float(d["ci95"][0]), float(d["ci95"][1]))

    def __str__(self) -> str:
        return f"{self.mean:.3f} [{self.low:.3f}, {self.high:.3f}]"


def _bootstrap(
    axes: list[np.ndarray], statistic: Callable[..., float], point: float, seed: int
) -> Interval:
    """``point`` with the percentile interval of ``statistic(*index arrays)``.

    Each axis of index arrays (seeds, episodes) is resampled independently; an
    axis of one index is kept as it is (a lone seed is not resampled), and with
    nothing to resample the interval is degenerate, said as such.
    """
    from scipy.stats import bootstrap

    varied = [i for i, a in enumerate(axes) if len(a) >= 2]
    if not varied:
        return Interval(point, point, point)

    def resampled_statistic(*resampled: np.ndarray) -> float:
        idx = list(axes)
        for i, r in zip(varied, resampled, strict=True):
            idx[i] = r.astype(int)
        return statistic(*idx)

    res = bootstrap(
        tuple(axes[i] for i in varied),
        resampled_statistic,
        vectorized=False,
        paired=False,
        confidence_level=CONFIDENCE,
        n_resamples=RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    ci = res.confidence_interval
    return Interval(point, float(ci.low), float(ci.high))


def bootstrap_interval(errors: EpisodeErrors, seed: int = 0) -> Interval:
    """:meth:`EpisodeErrors.point` with its interval, resampling seeds and episodes."""
    s, e = errors.error.shape
    return _bootstrap([np.arange(s), np.arange(e)], errors.pooled, errors.point(), seed)


def paired_difference(a: EpisodeErrors, b: EpisodeErrors, seed: int = 0) -> Interval:
    """``a.point() - b.point()`` with its 95 % interval, on the same test episodes.

    Every bootstrap resample draws one set of test episodes for both
    configurations and each configuration's training seeds independently (seed
    ``i`` of ``a`` and of ``b`` are unrelated models). An interval that excludes
    0 says the ordering holds on these episodes' kind of scene, beyond seeds and
    episode-to-episode difficulty.

    Raises:
        ValueError: the two were not tested on the same number of episodes or
            frames, or with the same pooling.
    """
    if not np.array_equal(a.frames, b.frames) or a.pooling != b.pooling:
        raise ValueError(
            "a paired difference needs the same test episodes: frames "
            f"{a.frames.tolist()} vs {b.frames.tolist()}, "
            f"pooling {a.pooling.value!r} vs {b.pooling.value!r}"
        )
    axes = [np.arange(a.error.shape[0]), np.arange(b.error.shape[0]), np.arange(len(a.frames))]
    return _bootstrap(
        axes,
        lambda sa, sb, ep: a.pooled(sa, ep) - b.pooled(sb, ep),
        a.point() - b.point(),
        seed,
    )


def paired_statement(name_a: str, name_b: str, diff: Interval) -> str:
    """One line on the paired difference ``a - b`` (lower error is better)."""
    where = (
        f"{name_a} lower on the same episodes"
        if diff.high < 0
        else f"{name_b} lower on the same episodes"
        if diff.low > 0
        else "the interval contains 0"
    )
    return (
        f"paired difference {name_a} - {name_b}: {diff.mean:+.3f} "
        f"[{diff.low:+.3f}, {diff.high:+.3f}] ({where})"
    )


def verdict(name_a: str, a: Interval, name_b: str, b: Interval) -> str:
    """Which of two error intervals is lower, or that they overlap (lower error is better)."""
    if a.high < b.low:
        return f"{name_a} beats {name_b} (95 % intervals separate)"
    if b.high < a.low:
        return f"{name_b} beats {name_a} (95 % intervals separate)"
    return f"no verdict: the 95 % intervals of {name_a} and {name_b} overlap"


def _undecided(steps: int) -> dict[str, float | bool | str | None]:
    """:func:`converged`'s record of a run with no evaluation by half its steps."""
    return {
        "converged": False,
        "improvement": None,
        "improvement_null_reason": "no evaluation by half the steps: nothing to compare",
        "steps": steps,
    }


def converged(history: Sequence[Mapping[str, float]]) -> dict[str, float | bool | str | None]:
    """Did the last doubling of steps improve the best validation loss by < 2 %?

    Args:
        history: evaluations ``{"step", "val_loss"}`` in step order.

    Returns:
        ``{"converged", "improvement", "steps"}``: the relative improvement of
        the best validation loss from step ``S / 2`` to the last step ``S``
        (None, with ``improvement_null_reason``, and not converged when no
        evaluation was made by step ``S / 2``).
    """
    if len(history) < 2:
        return _undecided(0)
    steps = np.array([h["step"] for h in history], np.float64)
    loss = np.array([h["val_loss"] for h in history], np.float64)
    last = steps[-1]
    half = steps <= last / 2
    if not half.any():
        return _undecided(int(last))
    best_half, best_all = loss[half].min(), loss.min()
    improvement = float((best_half - best_all) / max(abs(best_half), 1e-12))
    return {
        "converged": bool(improvement < CONVERGED_IMPROVEMENT),
        "improvement": improvement,
        "steps": int(last),
    }
