"""Evaluation of a camera on a split: predictions, the paper's post-processing, metrics.

Post-processing runs in time order over a split: counts are rounded (and
clipped at 0), states thresholded at 0.5, then every label is median filtered
over ``LabelSpec.median_filter_s`` at the data's frame rate (2 s for counts and
speeds, 0.5 s for states). Arrays are numpy unless a docstring says torch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from mincam_render.core.labels import LabelKind, LabelSpec
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


def evaluate(
    model: Model,
    data: TrainingData,
    *,
    noise: bool = True,
    seed: int = 1234,
    draw: PerturbationDraw | None = None,
) -> dict[str, Any]:
    """Test metrics after post-processing (every sample of ``data``, in time order).

    ``draw``: measure through this built camera (None: as designed).

    Returns ``{"loss": ..., "labels": {name: {...}}, "error": primary error}`` where
    COUNT/REGRESSION report ``rmse`` (post-processed), ``rmse_raw`` and ``mae`` in the
    label's unit, BINARY ``accuracy`` (mean over elements) and ``accuracy_per_element``;
    ``error`` is the first label's ``rmse`` or ``1 - accuracy``.
    """
    pred, lab, loss = predict(model, data, noise=noise, seed=seed, draw=draw)
    return metrics(pred, lab, loss, data)


def metrics(
    pred: Mapping[str, np.ndarray],
    lab: Mapping[str, np.ndarray],
    loss: float,
    data: TrainingData,
) -> dict[str, Any]:
    """:func:`evaluate`'s metrics of :func:`predict`'s output (time-ordered samples of ``data``)."""
    post = postprocess(pred, data.label_specs, data.fps)
    n = len(next(iter(lab.values())))
    res: dict[str, Any] = {"loss": loss, "samples": n, "labels": {}}
    for s in data.label_specs:
        y = lab[s.name].astype(np.float64)
        if s.kind is LabelKind.BINARY:
            acc = (post[s.name] == y).mean(axis=0)
            res["labels"][s.name] = {
                "accuracy": float(acc.mean()),
                "accuracy_per_element": acc.tolist(),
                "unit": "",
            }
        else:
            raw = pred[s.name].astype(np.float64)
            res["labels"][s.name] = {
                "rmse": float(np.sqrt(np.mean((post[s.name] - y) ** 2))),
                "rmse_raw": float(np.sqrt(np.mean((raw - y) ** 2))),
                "mae": float(np.mean(np.abs(post[s.name] - y))),
                "unit": s.unit,
            }
    first = data.label_specs[0]
    m = res["labels"][first.name]
    res["error"] = m["rmse"] if "rmse" in m else 1.0 - m["accuracy"]
    res["error_name"] = f"{first.name} " + ("RMSE" if "rmse" in m else "error rate")
    return res
