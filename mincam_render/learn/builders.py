"""Cameras built for a split's task: head, minimalist and baseline cameras, their description.

The paper's choices that follow from the data live here: the COUNT loss by
scene family (:data:`PAPER_COUNT_LOSS`), the classes of classified counts, and
the head's learning rate by its number of inputs (:func:`learning_rate_for`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Required, TypedDict

import numpy as np
import torch

from mincam_render.core.labels import LabelKind
from mincam_render.learn.models import BaselineCamera, CountLoss, Head, MincamCamera, Model
from mincam_render.learn.temporal_head import TemporalConvHead
from mincam_render.learn.train_config import HIDDEN_UNITS, HeadKind, ModelKind
from mincam_render.learn.training_data import TrainingData

#: The paper's loss for COUNT labels by scene family (``TrainingData.source["family"]``):
#: cross-entropy for the toy task (Sec. 5: "trained by minimizing the cross-entropy
#: loss"); the workspace people count was regressed (supplement C: "minimizing the mean
#: squared error"), and so is every count of a family not listed.
PAPER_COUNT_LOSS: dict[str, CountLoss] = {"patches": CountLoss.CROSS_ENTROPY}


def count_loss_for(data: TrainingData, count_loss: CountLoss | None = None) -> CountLoss:
    """``count_loss``, or when None the paper's choice for ``data``'s family."""
    if count_loss is not None:
        return CountLoss(count_loss)
    return PAPER_COUNT_LOSS.get(str(data.source.get("family", "")), CountLoss.MSE)


def count_classes_for(data: TrainingData, count_loss: CountLoss | None = None) -> dict[str, int]:
    """``{name: classes}`` of the COUNT labels to classify (empty for MSE).

    The classes are the counts ``0 .. max`` of the training labels (at least 2).
    """
    if count_loss_for(data, count_loss) is CountLoss.MSE:
        return {}
    out = {}
    for s in data.label_specs:
        if s.kind is LabelKind.COUNT:
            y = np.asarray(data.labels[s.name])
            top = int(np.rint(y.max())) if y.size else 0
            out[s.name] = max(2, top + 1)
    return out


def learning_rate_for(num_inputs: int) -> float:
    """The head's Adam learning rate: ``1e-3 * min(1, sqrt(16 / num_inputs))``."""
    return 1e-3 * min(1.0, math.sqrt(16.0 / max(1, num_inputs)))


def build_head(
    data: TrainingData,
    in_features: int,
    *,
    count_classes: dict[str, int] | None = None,
    seed: int = 0,
    kind: HeadKind = HeadKind.MLP,
    hidden: int = HIDDEN_UNITS,
    bottleneck: int = 0,
) -> Head:
    """A head of ``kind`` for ``data``'s labels (targets standardised by its statistics).

    ``in_features`` is pixels x time steps (``max(history - 1, 1)`` steps after
    forward differencing); ``hidden`` the width of its two hidden layers;
    ``bottleneck`` the linear combinations of the inputs they read (an MLP's
    option, :class:`Head`; 0: none). Its initial weights come from ``seed``;
    torch's global RNG (used by ``nn.Linear``) is restored afterwards.

    Raises:
        ValueError: a bottleneck for a temporal convolution head.
    """
    mean, std = data.target_stats()
    steps = max(data.history - 1, 1)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        if HeadKind(kind) is HeadKind.TCN:
            if bottleneck:
                raise ValueError(
                    f"bottleneck = {bottleneck}: the temporal convolution head has none; "
                    "use the MLP head"
                )
            if in_features % steps:
                raise ValueError(f"in_features = {in_features} is not pixels x {steps} steps")
            return TemporalConvHead(
                in_features // steps,
                steps,
                data.label_specs,
                target_mean=mean,
                target_std=std,
                count_classes=count_classes,
                hidden=hidden,
            )
        return Head(
            in_features,
            data.label_specs,
            target_mean=mean,
            target_std=std,
            count_classes=count_classes,
            hidden=hidden,
            bottleneck=bottleneck,
        )


def head_kind(head: Head) -> HeadKind:
    """The :class:`HeadKind` of a built head."""
    return HeadKind.TCN if isinstance(head, TemporalConvHead) else HeadKind.MLP


def hidden_width(head: Head) -> int:
    """The width of a built head's hidden layers."""
    return int(head.out.in_features)


def build_mincam(
    data: TrainingData,
    pixels: int | None = None,
    *,
    detectors: Sequence[int] | None = None,
    sensor_model: bool = True,
    count_loss: CountLoss | None = None,
    seed: int = 0,
    head: HeadKind = HeadKind.MLP,
    head_hidden: int = HIDDEN_UNITS,
    head_bottleneck: int = 0,
    mask_block: int = 1,
    signed: bool = False,
) -> MincamCamera:
    """A minimalist camera of ``pixels`` freeform pixels for ``data``'s task.

    Pixel ``j`` reads detector ``j`` of the data unless ``detectors`` is given
    (None: every rendered detector). More pixels than rendered detectors is an
    error: reusing a detector's transport for a second mask must be asked for
    with an explicit ``detectors`` list. ``signed``: ``pixels`` signed pixels,
    each a pair of photodiodes and masks (:class:`MincamCamera`), so twice as
    many detectors; ``detectors`` then lists both of every pair.
    COUNT labels are learned by ``count_loss`` (None: :func:`count_loss_for` the data);
    ``head`` chooses the inference network, ``head_hidden`` its width and
    ``head_bottleneck`` its linear bottleneck (:class:`Head`);
    ``mask_block`` the masks' block size in texels (:class:`MincamCamera`).
    """
    k_data = data.transport.shape[1]
    if detectors is None:
        detectors = _first_detectors(k_data, pixels, signed)
    detectors = list(detectors)
    if any(not 0 <= d < k_data for d in detectors):
        raise ValueError(f"detectors {detectors} outside the data's [0, {k_data})")
    outputs = len(detectors) // 2 if signed else len(detectors)
    net = build_head(
        data,
        outputs * max(data.history - 1, 1),
        count_classes=count_classes_for(data, count_loss),
        seed=seed,
        kind=head,
        hidden=head_hidden,
        bottleneck=head_bottleneck,
    )
    return MincamCamera(
        data.camera,
        net,
        detectors=detectors,
        sensor_model=sensor_model,
        history=data.history,
        init_seed=seed,
        mask_block=mask_block,
        signed=signed,
    )


def _first_detectors(k_data: int, pixels: int | None, signed: bool) -> list[int]:
    """Detectors ``0 .. n-1`` for ``pixels`` pixels (``2 pixels`` signed; None: all ``k_data``)."""
    if pixels is None:
        n = k_data - k_data % 2 if signed else k_data
        if n < 1:
            raise ValueError("signed pixels: pairs of detectors; the data has only one")
    else:
        n = 2 * int(pixels) if signed else int(pixels)
        if n < 1:
            raise ValueError(f"pixels = {pixels!r}: need at least 1")
    if n > k_data:
        what = f"{pixels} signed pixels need {n} photodiodes" if signed else f"pixels = {n}"
        raise ValueError(
            f"{what}: the data has only {k_data} rendered detectors; render it with "
            f"more (`render --detectors {n}`, or camera.detectors = {n} in the scene "
            "description), or ask for fewer pixels"
        )
    return list(range(n))


def build_baseline(
    data: TrainingData,
    grid: tuple[int, int],
    *,
    count_loss: CountLoss | None = None,
    seed: int = 0,
    head: HeadKind = HeadKind.MLP,
    head_hidden: int = HIDDEN_UNITS,
    head_bottleneck: int = 0,
) -> BaselineCamera:
    """A baseline camera of ``grid`` box pixels for ``data``'s task (exposure from ``data``).

    COUNT labels are learned by ``count_loss`` (None: :func:`count_loss_for` the data);
    ``head`` chooses the inference network, ``head_hidden`` its width and
    ``head_bottleneck`` its linear bottleneck (:class:`Head`: ``K`` unconstrained
    linear measurements of the box pixels).
    """
    net = build_head(
        data,
        grid[0] * grid[1] * max(data.history - 1, 1),
        count_classes=count_classes_for(data, count_loss),
        seed=seed,
        kind=head,
        hidden=head_hidden,
        bottleneck=head_bottleneck,
    )
    return BaselineCamera(
        grid,
        net,
        exposure_w=BaselineCamera.exposure_from(data.frames_np(0, 2048), grid),
        history=data.history,
    )


class ModelRecord(TypedDict, total=False):
    """A model's description as ``run.json`` holds it (:func:`describe_model`).

    Read back from disk by :mod:`~mincam_render.learn.restore`: the keys of the
    model's kind, the optional ones only when used.
    """

    kind: Required[str]
    pixels: Required[int]
    history: Required[int]
    detectors: list[int]
    sensor_model: bool
    mask_block: int
    grid: list[int]
    exposure_w: float
    count_classes: dict[str, int]
    head: str
    hidden: int
    bottleneck: int
    signed: bool


def pixels_label(model: Model) -> str:
    """A model's kind and pixel budget for progress bars and logs.

    ``"mincam 8 px"``, ``"baseline 112 px"``; signed freeform pixels name their
    outputs and their photodiodes, ``"mincam 2 signed px (4 photodiodes)"``.
    """
    if isinstance(model, MincamCamera) and model.signed:
        return f"mincam {model.num_outputs} signed px ({model.num_pixels} photodiodes)"
    kind = ModelKind.MINCAM if isinstance(model, MincamCamera) else ModelKind.BASELINE
    return f"{kind.value} {model.num_pixels} px"


def describe_model(model: Model) -> ModelRecord:
    """A JSON-ready description of a model (kind, pixels, options).

    ``count_classes`` appears only for classified counts, ``head`` only for a
    head other than the paper's MLP, ``hidden`` only for a width other than the
    paper's, ``bottleneck`` and ``mask_block`` only above 0 and 1, ``signed``
    only when true, so descriptions (and the resume check against checkpoints)
    of the paper's models are unchanged.
    """
    desc: ModelRecord
    if isinstance(model, MincamCamera):
        desc = {
            "kind": ModelKind.MINCAM.value,
            "pixels": model.num_pixels,
            "detectors": model.detectors.tolist(),
            "sensor_model": model.sensor_model,
            "history": model.history,
        }
        if model.mask_block != 1:
            desc["mask_block"] = model.mask_block
        if model.signed:
            desc["signed"] = True
    else:
        desc = {
            "kind": ModelKind.BASELINE.value,
            "pixels": model.num_pixels,
            "grid": list(model.grid),
            "exposure_w": float(model.exposure_w),
            "history": model.history,
        }
    if model.head.count_classes:
        desc["count_classes"] = dict(model.head.count_classes)
    if head_kind(model.head) is not HeadKind.MLP:
        desc["head"] = head_kind(model.head).value
    if hidden_width(model.head) != HIDDEN_UNITS:
        desc["hidden"] = hidden_width(model.head)
    if model.head.bottleneck:
        desc["bottleneck"] = model.head.bottleneck
    return desc
