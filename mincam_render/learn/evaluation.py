"""Evaluation of a camera on a split: predictions, the paper's post-processing, metrics.

Post-processing runs in time order over a split: counts are rounded (and
clipped at 0), states thresholded at 0.5, then every label is median filtered
over ``LabelSpec.median_filter_s`` at the data's frame rate (2 s for counts and
speeds, 0.5 s for states). Then the labels' evaluation rules: the paper's
traffic evaluation sets a predicted speed to 0 where the true speed is below
3 mph (``LabelSpec.zero_below_true``). The headline figure pools the labels the
task names as its headline (:func:`headline`). Arrays are numpy unless a
docstring says torch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.models import Model, task_loss
from mincam_render.learn.training_data import TrainingData
from mincam_render.optics.perturbation import PerturbationDraw


def median_filter_window(median_filter_s: float, fps: float) -> int:
    """Odd number of frames spanning ``median_filter_s`` at ``fps`` (1 = no filtering)."""
    n = int(round(median_filter_s * fps))
    if n <= 1:
        return 1
    return n if n % 2 else n + 1


def median_filter(x: np.ndarray, window: int) -> np.ndarray:
    """Centred running median of ``x[time, ...]`` over ``window`` frames (edges replicated)."""
    if window <= 1:
        return np.array(x, copy=True)
    half = window // 2
    pad = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)])
    win = np.lib.stride_tricks.sliding_window_view(pad, window, axis=0)
    return np.median(win, axis=-1).astype(x.dtype)


def postprocess(
    pred: Mapping[str, np.ndarray], specs: Sequence[LabelSpec], fps: float
) -> dict[str, np.ndarray]:
    """The paper's test-time post-processing of predictions ``{name: [time, size]}``.

    COUNT: round to the nearest integer >= 0, then median filter; REGRESSION:
    median filter; BINARY: threshold probabilities at 0.5, then median filter.
    """
    out = {}
    for s in specs:
        y = np.asarray(pred[s.name], np.float64)
        if s.kind is LabelKind.COUNT:
            y = np.maximum(np.rint(y), 0.0)
        elif s.kind is LabelKind.BINARY:
            y = (y >= 0.5).astype(np.float64)
        out[s.name] = median_filter(y, median_filter_window(s.median_filter_s, fps))
    return out


def even_indices(n: int, limit: int | None) -> np.ndarray:
    """Indices ``0 .. n-1``, or at most ``limit`` of them spread evenly (sorted, unique)."""
    if limit is None or n <= limit:
        return np.arange(n)
    return np.unique(np.linspace(0, n - 1, limit).round().astype(np.int64))


@torch.no_grad()
def predict(
    model: Model,
    data: TrainingData,
    *,
    batch_size: int = 1024,
    noise: bool = True,
    seed: int = 1234,
    limit: int | None = None,
    draw: PerturbationDraw | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], float]:
    """Predictions, labels (``{name: [n, size]}``) and mean loss over a split, in time order.

    Batches of consecutive samples: a temporal batch measures each frame once.
    ``draw``: measure through this built camera (None: as designed).
    """
    was_training = model.training
    model.eval()
    g = torch.Generator().manual_seed(seed)
    idx = even_indices(len(data), limit)
    preds: dict[str, list] = {s.name: [] for s in data.label_specs}
    labs: dict[str, list] = {s.name: [] for s in data.label_specs}
    loss_sum = 0.0
    for a in range(0, len(idx), batch_size):
        batch = data.sample(torch.from_numpy(idx[a : a + batch_size]))
        y = batch.labels
        out = model(**batch.inputs(), noise=noise, generator=g, draw=draw)
        loss, _ = task_loss(model.head, out, y)
        loss_sum += float(loss) * len(batch)
        for k, v in model.head.predict(out).items():
            preds[k].append(v.numpy())
            labs[k].append(y[k].numpy())
    model.train(was_training)
    cat = {k: np.concatenate(v) for k, v in preds.items()}
    return cat, {k: np.concatenate(v) for k, v in labs.items()}, loss_sum / max(1, len(idx))


@torch.no_grad()
def mean_loss_under(
    model: Model,
    data: TrainingData,
    draws: Sequence[PerturbationDraw],
    *,
    batch_size: int = 1024,
    seed: int = 1234,
    limit: int | None = None,
) -> float:
    """Mean over ``draws`` (built cameras) of :func:`predict`'s loss on ``data``.

    Each draw's loss is exactly :func:`predict`'s with that draw (the same
    samples, the same sensor noise from ``seed``), so two evaluations differ only
    by the model. Every batch is gathered once for all draws: the gather, not
    the measurement, is most of an evaluation's cost.
    """
    if not draws:
        raise ValueError("mean_loss_under needs at least one draw")
    was_training = model.training
    model.eval()
    generators = [torch.Generator().manual_seed(seed) for _ in draws]
    idx = even_indices(len(data), limit)
    loss_sums = np.zeros(len(draws))
    for a in range(0, len(idx), batch_size):
        batch = data.sample(torch.from_numpy(idx[a : a + batch_size]))
        inputs = batch.inputs()
        for i, (draw, g) in enumerate(zip(draws, generators, strict=True)):
            out = model(**inputs, noise=True, generator=g, draw=draw)
            loss_sums[i] += float(task_loss(model.head, out, batch.labels)[0]) * len(batch)
    model.train(was_training)
    return float(np.mean(loss_sums / max(1, len(idx))))


def episode_limits(episodes: Sequence[TrainingData], limit: int | None) -> list[int | None]:
    """Samples evaluated per episode: ``limit`` in all, shared in proportion to their lengths.

    None (or a limit above the total) evaluates every sample of every episode.
    """
    total = sum(len(e) for e in episodes)
    if limit is None or total <= limit:
        return [None] * len(episodes)
    return [max(2, round(limit * len(e) / total)) for e in episodes]


def pooled_validation(
    model: Model,
    episodes: Sequence[TrainingData],
    *,
    limit: int | None = None,
    draws: Sequence[PerturbationDraw] = (),
) -> dict[str, float]:
    """Validation on several episodes (other scene seeds), pooled over their samples.

    Each episode is evaluated as :func:`predict` does (time order, the fixed noise
    seed) on its share of ``limit`` samples (:func:`episode_limits`); the loss is
    the sample-weighted mean, the error the headline pooled like the test error
    (RMSE as the root of the mean square over frames, error rates as a mean).

    Args:
        model: the camera.
        episodes: validation episodes.
        limit: samples evaluated in all (None: every sample).
        draws: built cameras; when given, ``loss`` is the mean of the loss under
            them (:func:`mean_loss_under`) and ``loss_nominal`` the design's own.

    Returns:
        ``{"loss", "error"[, "loss_nominal"]}``.
    """
    if not episodes:
        raise ValueError("pooled_validation needs at least one validation episode")
    losses, errors, weights, under = [], [], [], []
    for ep, lim in zip(episodes, episode_limits(episodes, limit), strict=True):
        pred, lab, loss = predict(model, ep, limit=lim)
        m = metrics(pred, lab, loss, ep)
        losses.append(loss)
        errors.append(m.error)
        weights.append(m.samples)
        if draws:
            under.append(mean_loss_under(model, ep, draws, limit=lim))
    w = np.asarray(weights, np.float64) / sum(weights)
    rms = m.error_name.endswith("RMSE")
    error = np.sqrt(w @ np.square(errors)) if rms else w @ np.asarray(errors)
    out = {"loss": float(w @ np.asarray(losses)), "error": float(error)}
    if draws:  # the built cameras' mean decides; the design's own loss is kept beside
        out["loss_nominal"], out["loss"] = out["loss"], float(w @ np.asarray(under))
    return out


def evaluate(
    model: Model,
    data: TrainingData,
    *,
    noise: bool = True,
    seed: int = 1234,
    draw: PerturbationDraw | None = None,
) -> Evaluation:
    """Test metrics after post-processing (every sample of ``data``, in time order).

    ``draw``: measure through this built camera (None: as designed).

    Returns :func:`metrics` of :func:`predict`'s output.
    """
    pred, lab, loss = predict(model, data, noise=noise, seed=seed, draw=draw)
    return metrics(pred, lab, loss, data)


def zero_where_true_below(
    post: Mapping[str, np.ndarray], lab: Mapping[str, np.ndarray], specs: Sequence[LabelSpec]
) -> dict[str, np.ndarray]:
    """The paper's traffic rule: prediction 0 where the true value < ``spec.zero_below_true``.

    Applied after :func:`postprocess` (the paper filters, then zeroes); labels
    without the rule are returned unchanged. Arrays ``{name: [time, size]}``.
    """
    out = dict(post)
    for s in specs:
        if s.zero_below_true is not None:
            out[s.name] = np.where(lab[s.name] < s.zero_below_true, 0.0, post[s.name])
    return out


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


@dataclass(frozen=True, kw_only=True)
class LabelMetrics:
    """One label's test figures, in the label's unit (:func:`metrics`).

    BINARY labels have ``accuracy`` (mean over elements) and
    ``accuracy_per_element``; COUNT and REGRESSION labels ``rmse``
    (post-processed, rules applied), ``rmse_raw`` (neither) and ``mae``, with a
    zero rule also ``zero_below_true`` and ``rmse_without_zero_rule``. The
    figures a label's kind has not are None.

    Attributes:
        unit: the label's unit ("" for BINARY).
        median_filter_frames: the post-processing window (1 = not filtered).
    """

    unit: str
    median_filter_frames: int
    accuracy: float | None = None
    accuracy_per_element: tuple[float, ...] | None = None
    rmse: float | None = None
    rmse_raw: float | None = None
    mae: float | None = None
    zero_below_true: float | None = None
    rmse_without_zero_rule: float | None = None

    def as_json(self) -> JsonObject:
        """The label's record in ``metrics.json`` (the figures it has, in their order)."""
        if self.accuracy is not None:
            out: JsonObject = {
                "accuracy": self.accuracy,
                "accuracy_per_element": list(self.accuracy_per_element or ()),
                "unit": self.unit,
            }
        else:
            out = {"rmse": self.rmse, "rmse_raw": self.rmse_raw, "mae": self.mae, "unit": self.unit}
            if self.zero_below_true is not None:
                out["zero_below_true"] = self.zero_below_true
                out["rmse_without_zero_rule"] = self.rmse_without_zero_rule
        out["median_filter_frames"] = self.median_filter_frames
        return out

    @classmethod
    def from_json(cls, record: JsonObject) -> LabelMetrics:
        """The figures of :meth:`as_json`'s record."""
        per_element = record.get("accuracy_per_element")
        return cls(
            **{k: v for k, v in record.items() if k != "accuracy_per_element"},
            accuracy_per_element=None if per_element is None else tuple(per_element),
        )


@dataclass(frozen=True, kw_only=True)
class Headline:
    """The task's headline figure (:func:`headline`).

    Attributes:
        error: an RMSE (label unit) or ``1 - accuracy``.
        error_name: ``"<name> RMSE"`` or ``"<name> error rate"``.
        name: the headline's name (the label's when none is named).
        labels: the labels pooled into it.
        pooling: how they are pooled, in words.
    """

    error: float
    error_name: str
    name: str
    labels: tuple[str, ...]
    pooling: str


@dataclass(frozen=True, kw_only=True)
class Evaluation:
    """Test metrics of a camera on an episode (:func:`metrics`, :func:`evaluate`).

    Attributes:
        loss: the task loss.
        samples: samples evaluated.
        labels: per label name, its figures.
        headline: the task's figure; ``error`` and ``error_name`` are its.
    """

    loss: float
    samples: int
    labels: Mapping[str, LabelMetrics]
    headline: Headline

    @property
    def error(self) -> float:
        """The headline error."""
        return self.headline.error

    @property
    def error_name(self) -> str:
        """The headline error's name."""
        return self.headline.error_name

    def as_json(self) -> JsonObject:
        """``{"loss", "samples", "labels": {name: {...}}, "error", "error_name", "headline"}``."""
        h = self.headline
        return {
            "loss": self.loss,
            "samples": self.samples,
            "labels": {name: m.as_json() for name, m in self.labels.items()},
            "error": h.error,
            "error_name": h.error_name,
            "headline": {"name": h.name, "labels": list(h.labels), "pooling": h.pooling},
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> Evaluation:
        """The metrics of :meth:`as_json`'s record (a run's ``metrics.json``)."""
        h = record["headline"]
        return cls(
            loss=record["loss"],
            samples=record["samples"],
            labels={k: LabelMetrics.from_json(v) for k, v in record["labels"].items()},
            headline=Headline(
                error=record["error"],
                error_name=record["error_name"],
                name=h["name"],
                labels=tuple(h["labels"]),
                pooling=h["pooling"],
            ),
        )


def _label_metrics(
    s: LabelSpec,
    pred: np.ndarray,
    filtered: np.ndarray,
    scored: np.ndarray,
    y: np.ndarray,
    median_filter_frames: int,
) -> LabelMetrics:
    """One label's figures: ``pred`` raw, ``filtered`` post-processed, ``scored`` ruled."""
    if s.kind is LabelKind.BINARY:
        acc = (scored == y).mean(axis=0)
        return LabelMetrics(
            accuracy=float(acc.mean()),
            accuracy_per_element=tuple(acc.tolist()),
            unit="",
            median_filter_frames=median_filter_frames,
        )
    ruled = s.zero_below_true is not None
    return LabelMetrics(
        rmse=_rmse(scored, y),
        rmse_raw=_rmse(pred, y),
        mae=float(np.mean(np.abs(scored - y))),
        unit=s.unit,
        zero_below_true=s.zero_below_true,
        rmse_without_zero_rule=_rmse(filtered, y) if ruled else None,
        median_filter_frames=median_filter_frames,
    )


def headline(labels: Mapping[str, LabelMetrics], specs: Sequence[LabelSpec]) -> Headline:
    """The task's headline figure from per-label metrics ``labels``.

    The labels sharing a ``LabelSpec.headline`` name are pooled over every test
    frame and every element of every such label: an RMSE as the root of the
    mean squared error over all (frame, label element) pairs, i.e.
    ``sqrt(sum_l size_l * rmse_l**2 / sum_l size_l)`` (for traffic, the RMSE over
    frames and both directions: ``sqrt((rmse_left**2 + rmse_right**2) / 2)``); an
    accuracy as the mean over those pairs. Without a headline label, the first
    label's figure (unchanged behaviour for patches, workspace and lighting).

    Returns:
        The :class:`Headline`; its ``error`` is an RMSE or ``1 - accuracy``.

    Raises:
        ValueError: more than one headline name, or labels of one headline of
            mixed kinds (RMSE with accuracy).
    """
    group = [s for s in specs if s.headline]
    names = {s.headline for s in group}
    if len(names) > 1:
        raise ValueError(f"labels name several headlines {sorted(names)}: a task has one")
    group = group or [specs[0]]
    figures = [labels[s.name] for s in group]
    binary = [m.accuracy is not None for m in figures]
    if any(binary) and not all(binary):
        raise ValueError(f"headline {group[0].headline!r} mixes RMSE and accuracy labels")
    w = np.array([s.size for s in group], np.float64)
    w /= w.sum()
    name = group[0].headline or group[0].name
    if binary[0]:
        error = 1.0 - float(np.dot(w, [m.accuracy for m in figures if m.accuracy is not None]))
        pooling, kind = "mean accuracy over frames and label elements", "error rate"
    else:
        error = float(np.sqrt(np.dot(w, [m.rmse**2 for m in figures if m.rmse is not None])))
        pooling, kind = "root mean square over frames and label elements", "RMSE"
    return Headline(
        error=error,
        error_name=f"{name} {kind}",
        name=name,
        labels=tuple(s.name for s in group),
        pooling=pooling,
    )


def metrics(
    pred: Mapping[str, np.ndarray],
    lab: Mapping[str, np.ndarray],
    loss: float,
    data: TrainingData,
) -> Evaluation:
    """Metrics of :func:`predict`'s output (time-ordered samples of ``data``).

    Post-processing (:func:`postprocess`), then the evaluation rules of the
    labels (:func:`zero_where_true_below`); every label's figures
    (:class:`LabelMetrics`, with its ``median_filter_frames``: 1 = not filtered
    at this frame rate) and the :func:`headline`.

    Raises:
        ValueError: ``data`` joins episodes with their windows (its samples are
            not one time series for the median filter: evaluate each episode).
    """
    if not data.one_sequence:
        raise ValueError(
            "metrics: the samples of joined temporal episodes are not one time series (the "
            "median filter runs over time); evaluate each episode on its own"
        )
    post = postprocess(pred, data.label_specs, data.fps)
    y = {s.name: np.asarray(lab[s.name], np.float64) for s in data.label_specs}
    scored = zero_where_true_below(post, y, data.label_specs)
    labels = {
        s.name: _label_metrics(
            s,
            pred[s.name],
            post[s.name],
            scored[s.name],
            y[s.name],
            median_filter_window(s.median_filter_s, data.fps),
        )
        for s in data.label_specs
    }
    return Evaluation(
        loss=loss,
        samples=len(next(iter(lab.values()))),
        labels=labels,
        headline=headline(labels, data.label_specs),
    )
