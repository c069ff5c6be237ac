"""Where a count's errors lie: bias and RMSE of the predictions at each true count.

A count predictor whose features are weak regresses toward the training mean:
it over-counts empty scenes and under-counts crowded ones, and a test episode
with more crowded frames than the training data is then a hard one. This module
splits a design's test error by the true count, pooling every training seed's
post-processed predictions (the headline figure's, ``learn.evaluation.postprocess``):

* ``bias``: mean of ``prediction - truth`` over the frames with that count, with
  a 95 % percentile bootstrap interval that resamples training seeds and test
  episodes (the units of :mod:`.statistics`: frames of an episode are
  correlated in time). A rare count is missing from some resamples of the
  episodes; the interval is taken over the resamples that hold it (conditional
  on the count being seen), which ``scipy.stats.bootstrap`` cannot do, hence the
  few lines of resampling here;
* ``rmse``: root mean square of the same differences;
* ``share``: the fraction of test frames with that count.

Arrays are numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mincam_render.analysis.statistics import CONFIDENCE, RESAMPLES, Interval


@dataclass(frozen=True)
class CountBin:
    """A design's errors on the test frames whose true count is ``count`` (module docstring).

    Args:
        count: the true count.
        frames: test frames with it (each seed's prediction of a frame counts once).
        share: its fraction of the test frames (0-1).
        bias: mean ``prediction - truth`` (counts) with its 95 % interval.
        rmse: root mean square of ``prediction - truth`` (counts).
    """

    count: int
    frames: int
    share: float
    bias: Interval
    rmse: float

    def as_json(self) -> dict[str, object]:
        """JSON form: the fields, ``bias`` as ``{"mean", "ci95"}``."""
        return {
            "count": self.count,
            "frames": self.frames,
            "share": self.share,
            "bias": self.bias.as_dict(),
            "rmse": self.rmse,
        }


def errors_by_count(
    pred: np.ndarray, true: np.ndarray, episode: np.ndarray, *, min_frames: int = 1, seed: int = 0
) -> tuple[CountBin, ...]:
    """Bias and RMSE of ``pred`` at each true count (module docstring), in count order.

    Args:
        pred: ``[seed, frame]`` predicted counts of every training seed on the
            same test frames.
        true: ``[frame]`` true counts (whole numbers >= 0).
        episode: ``[frame]`` index of each frame's test episode (the bootstrap's unit).
        min_frames: counts with fewer test frames are left out.
        seed: seed of the bootstrap.

    Raises:
        ValueError: shapes that do not match, non-finite values, true counts that
            are not whole numbers >= 0, or ``min_frames`` < 1.
    """
    pred, true, episode = _checked(pred, true, episode, min_frames)
    error = pred - true[None, :]
    episodes = np.unique(episode)
    rng = np.random.default_rng(seed)
    draws = (
        rng.integers(0, pred.shape[0], (RESAMPLES, pred.shape[0])),
        rng.integers(0, len(episodes), (RESAMPLES, len(episodes))),
    )
    bins = []
    for count in np.unique(true).astype(int):
        at = true == count
        if at.sum() < min_frames:
            continue
        point = float(error[:, at].mean())
        bins.append(
            CountBin(
                count=int(count),
                frames=int(at.sum()),
                share=float(at.mean()),
                bias=_interval(
                    error, [np.flatnonzero(at & (episode == e)) for e in episodes], point, draws
                ),  # fmt: skip
                rmse=float(np.sqrt(np.mean(error[:, at] ** 2))),
            )
        )
    return tuple(bins)


def _interval(
    error: np.ndarray,
    frames_of: list[np.ndarray],
    point: float,
    draws: tuple[np.ndarray, np.ndarray],
) -> Interval:
    """``point`` with the percentile interval of the mean error over resampled seeds and episodes.

    ``error[seed, frame]``; ``frames_of[episode]``: the frames of the count in each
    episode; ``draws``: ``[resample, seed]`` and ``[resample, episode]`` indices.
    A resample without frames of the count is left out (conditional interval).
    """
    means = []
    for seeds, episodes in zip(*draws, strict=True):
        frames = np.concatenate([frames_of[e] for e in episodes])
        if frames.size:
            means.append(error[np.ix_(seeds, frames)].mean())
    tail = 100 * (1 - CONFIDENCE) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return Interval(point, float(low), float(high))


def _checked(
    pred: np.ndarray, true: np.ndarray, episode: np.ndarray, min_frames: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arrays as float64 / int64, validated (see :func:`errors_by_count`)."""
    pred = np.asarray(pred, np.float64)
    true = np.asarray(true, np.float64)
    episode = np.asarray(episode)
    if pred.ndim != 2 or true.ndim != 1 or pred.shape[1] != true.size or true.size == 0:
        raise ValueError(
            f"pred {pred.shape}, true {true.shape}: expected [seed, frame] and [frame], non-empty"
        )
    if episode.shape != true.shape:
        raise ValueError(f"episode {episode.shape}: one index per frame, {true.shape}")
    if not (np.all(np.isfinite(pred)) and np.all(np.isfinite(true))):
        raise ValueError("pred and true must be finite")
    if np.any(true < 0) or np.any(true != np.rint(true)):
        raise ValueError("true counts must be whole numbers >= 0")
    if min_frames < 1:
        raise ValueError(f"min_frames = {min_frames}: must be >= 1")
    return pred, true, episode
