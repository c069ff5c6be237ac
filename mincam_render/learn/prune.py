"""Supplement C's greedy pruning of a trained minimalist camera."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.builders import build_head, head_kind, hidden_width
from mincam_render.learn.evaluation import Evaluation, evaluate, even_indices, predict
from mincam_render.learn.loop import train_model
from mincam_render.learn.models import MincamCamera, task_loss
from mincam_render.learn.train_config import TrainConfig
from mincam_render.learn.training_data import TrainingData


@torch.no_grad()
def _val_loss_without(model: MincamCamera, data: TrainingData, pixel: int, limit: int) -> float:
    """Validation loss when pixel ``pixel``'s inputs are replaced by their running mean."""
    model.eval()
    g = torch.Generator().manual_seed(1234)
    idx = even_indices(len(data), limit)
    k = model.num_pixels
    cols = torch.arange(pixel, model.head.in_features, k)
    total = 0.0
    from mincam_render.learn.models import temporal_features

    for a in range(0, len(idx), 1024):
        b = data.sample(torch.from_numpy(idx[a : a + 1024]))
        x = temporal_features(model.measure(**b.inputs(), noise=True, generator=g))
        x[:, cols] = model.head.input_running_mean()[cols]
        loss, _ = task_loss(model.head, model.head(x), b.labels)
        total += float(loss) * len(b)
    return total / max(1, len(idx))


@dataclass(frozen=True, kw_only=True)
class PruneStep:
    """The camera after one step of greedy pruning (a record of ``prune.json``).

    Attributes:
        pixels: pixels left.
        kept: the original indices of the pixels left.
        removed: the original indices of the pixels removed, in order.
        score_val_loss_without: the validation loss that chose the last removal
            (None for the unpruned camera).
        val_loss: the validation loss after retraining the head.
        test: test metrics, or None without a test split.
    """

    pixels: int
    kept: tuple[int, ...]
    removed: tuple[int, ...]
    score_val_loss_without: float | None = None
    val_loss: float
    test: Evaluation | None

    def as_json(self) -> JsonObject:
        """The record in ``prune.json``."""
        out: JsonObject = {
            "pixels": self.pixels,
            "kept": list(self.kept),
            "removed": list(self.removed),
        }
        if self.score_val_loss_without is not None:
            out["score_val_loss_without"] = self.score_val_loss_without
        out["val_loss"] = self.val_loss
        out["test"] = None if self.test is None else self.test.as_json()
        return out


def greedy_prune(
    model: MincamCamera,
    train: TrainingData,
    val: TrainingData,
    test: TrainingData | None = None,
    config: TrainConfig = TrainConfig(),
    *,
    min_pixels: int = 1,
    progress: bool = False,
) -> list[PruneStep]:
    """Supplement C's greedy pruning of a trained minimalist camera.

    At each step the pixel whose removal raises the validation loss least is
    dropped (its head inputs held at their running mean, so every candidate is
    scored without retraining), the masks are frozen, and a fresh head is
    trained on the remaining pixels with ``config``.

    Returns:
        One :class:`PruneStep` per pixel count, from ``K`` down to ``min_pixels``.

    Raises:
        ValueError: a camera of signed pixels (pruning one photodiode of a pair
            is not defined).

    """
    if model.signed:
        raise ValueError("greedy pruning drops single pixels; this camera's are signed pairs")
    current = model
    keep = list(range(model.num_pixels))  # indices into the original model's pixels
    removed: list[int] = []
    records = [
        PruneStep(
            pixels=len(keep),
            kept=tuple(keep),
            removed=(),
            val_loss=predict(current, val, limit=config.max_eval_samples)[2],
            test=evaluate(current, test) if test is not None else None,
        )
    ]
    while len(keep) > min_pixels:
        scores = [
            _val_loss_without(current, val, j, config.max_eval_samples)
            for j in range(current.num_pixels)
        ]
        j = int(np.argmin(scores))
        removed.append(keep.pop(j))
        nxt = _pruned_camera(model, train, keep, config)
        res = train_model(nxt, train, val, config, progress=progress, desc=f"prune {len(keep)} px")
        current = nxt
        records.append(
            PruneStep(
                pixels=len(keep),
                kept=tuple(keep),
                removed=tuple(removed),
                score_val_loss_without=float(scores[j]),
                val_loss=res.best_val_loss,
                test=evaluate(current, test) if test is not None else None,
            )
        )
    return records


def _pruned_camera(
    model: MincamCamera, train: TrainingData, keep: list[int], config: TrainConfig
) -> MincamCamera:
    """``model``'s pixels ``keep`` with their masks frozen and a fresh head for ``train``."""
    dets = [int(d) for d in model.detectors[keep]]
    head = build_head(
        train,
        len(keep) * max(train.history - 1, 1),
        count_classes=model.head.count_classes,
        seed=stream_seed(config.seed, "prune/head", len(keep)),
        kind=head_kind(model.head),
        hidden=hidden_width(model.head),
        bottleneck=model.head.bottleneck,
    )
    nxt = MincamCamera(
        model.camera,
        head,
        detectors=dets,
        sensor_model=model.sensor_model,
        history=model.history,
    )
    with torch.no_grad():
        nxt.logits.copy_(model.logits[keep])
    nxt.logits.requires_grad_(False)
    return nxt
