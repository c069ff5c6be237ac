"""One way back from a run directory to its trained camera, for every kind of run.

A run directory (:func:`~mincam_render.learn.runs.train_run`) holds ``run.json``
(what was trained, on what data, with which recipe), ``checkpoint.pt`` (the state
of the lowest validation loss so far) and, once training has finished,
``metrics.json``: written last, it marks a finished run (as for the comparisons'
resume, :mod:`mincam_render.data.run_dispatch`). A run trained again starts
by removing it.

:func:`open_run` reads a run and refuses an unfinished one unless asked;
:meth:`TrainedRun.require` refuses a kind of camera a command has no use for, in
one line; :func:`restore_model` rebuilds the camera of any run: minimalist or
baseline, MLP or temporal-convolution head, regressed or classified counts, any
history, trained nominally, robustly or with the privacy term (whose adversary
is not part of the camera that is measured, and is the only state left out).
:func:`run_masks` gives a minimalist run's masks. Every command that reads a run
(``export-masks``, ``prune``, ``report robustness``, the privacy attacks, the
ablation's frozen masks) goes through here.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import NotRequired, TypedDict, cast

import numpy as np
import torch

from mincam_render.core.strict_json import JsonObject
from mincam_render.data.dataset import LabelSpecRecord
from mincam_render.learn.builders import ModelRecord, build_head
from mincam_render.learn.checkpoint import load_checkpoint
from mincam_render.learn.models import BaselineCamera, MincamCamera, Model
from mincam_render.learn.train_config import HIDDEN_UNITS, HeadKind, ModelKind
from mincam_render.learn.training_data import TrainingData
from mincam_render.optics.camera import FreeformCamera

#: The file that marks a finished run (written last by ``train_run``).
FINISHED_MARK = "metrics.json"
#: State of a privacy-trained run that belongs to its training, not to its camera.
ADVERSARY_PREFIX = "adversary."


#: How a message names the runs of a kind.
_KIND_NAMES = {
    ModelKind.MINCAM: "minimalist-camera (mincam)",
    ModelKind.BASELINE: "baseline-camera",
}


class UnfinishedRunError(ValueError):
    """A run whose training did not finish was given where a finished one is needed."""


def run_finished(run_dir: str | os.PathLike) -> bool:
    """Whether the run in ``run_dir`` finished training (its ``metrics.json`` exists)."""
    return (Path(run_dir) / FINISHED_MARK).is_file()


class RunRecord(TypedDict):
    """A run's ``run.json`` (:func:`~mincam_render.learn.runs.describe_run`), read back here.

    ``camera``, ``data``, ``config`` and each of ``label_specs`` are the JSON
    records of their own writers (the camera, the datasets' provenance, the
    recipe, the label specifications).
    """

    model: ModelRecord
    camera: JsonObject
    data: JsonObject
    config: JsonObject
    fps: float
    history: int
    label_specs: list[LabelSpecRecord]
    frozen_masks_from: NotRequired[str]
    reference: NotRequired[JsonObject]


@dataclass(frozen=True)
class TrainedRun:
    """A run directory as read back: its record, its best state and how far it got.

    Args:
        path: the run directory.
        record: ``run.json`` (model description, camera, data, recipe, labels).
        state: the model's ``state_dict`` of the lowest validation loss (torch).
        finished: whether training finished (:data:`FINISHED_MARK` exists).
        step: optimisation steps the checkpoint holds.
    """

    path: Path
    record: RunRecord
    state: dict[str, torch.Tensor]
    finished: bool
    step: int

    @property
    def kind(self) -> ModelKind:
        """The kind of camera the run trained."""
        return ModelKind(self.record["model"]["kind"])

    @property
    def training(self) -> str:
        """``"finished"``, or ``"unfinished: step S of M"`` (for provenance and sheets)."""
        if self.finished:
            return "finished"
        return f"unfinished: step {self.step} of {self.record['config']['max_steps']}"

    def require(self, kind: ModelKind, use: str) -> None:
        """Refuse, in one line, a run of another kind than ``use`` takes.

        Args:
            kind: the kind ``use`` takes.
            use: what the run is for, as a phrase (``"prune"``, ``"a robustness report"``).

        Raises:
            ValueError: the run is of another kind.
        """
        if self.kind is not kind:
            raise ValueError(
                f"{self.path} is a {self.kind.value} run: {use} takes {_KIND_NAMES[kind]} runs only"
            )


def open_run(run_dir: str | os.PathLike, *, allow_unfinished: bool = False) -> TrainedRun:
    """Read the run in ``run_dir``: ``run.json``, the checkpoint's best state, its progress.

    Args:
        run_dir: a directory written by ``train_run``.
        allow_unfinished: read a run whose training did not finish (its best
            state so far); the caller marks what it makes of it.

    Raises:
        UnfinishedRunError: training did not finish and ``allow_unfinished`` is False.
        ValueError: not a run directory, or an unreadable ``run.json`` or checkpoint.
    """
    path = Path(run_dir)
    run_path, ckpt_path = path / "run.json", path / "checkpoint.pt"
    if not run_path.is_file() or not ckpt_path.is_file():
        raise ValueError(f"{path}: not a training run (needs run.json and checkpoint.pt)")
    try:
        record = json.loads(run_path.read_text())
    except ValueError:
        raise ValueError(f"{run_path}: not valid JSON (truncated?)") from None
    ck = load_checkpoint(ckpt_path)
    run = TrainedRun(path, record, ck["best_state"], run_finished(path), int(ck["step"]))
    if not (run.finished or allow_unfinished):
        raise UnfinishedRunError(
            f"{path}: training did not finish ({run.training}, no {FINISHED_MARK}); run the "
            "same `train` command again to finish it, or pass --allow-unfinished to use its "
            "best state so far (marked unfinished)"
        )
    return run


def restore_model(run: TrainedRun, data: TrainingData) -> Model:
    """The trained camera of ``run``, to be measured on ``data`` (in evaluation mode).

    Built from the run's own description (kind, detectors or grid, signed
    pairs, head kind, width and bottleneck, count classes, history, sensor
    model, camera or exposure) and loaded with its best state, strictly but for a privacy
    adversary's.

    Raises:
        ValueError: ``data`` does not fit the run (history, mask resolution,
            detectors), or the checkpoint does not fit ``run.json``.
    """
    desc = run.record["model"]
    if data.history != desc["history"]:
        raise ValueError(
            f"{run.path}: trained on windows of {desc['history']} frames; the data gives "
            f"{data.history}"
        )
    steps = max(desc["history"] - 1, 1)
    kind = HeadKind(desc.get("head", HeadKind.MLP.value))
    hidden = int(desc.get("hidden", HIDDEN_UNITS))
    bottleneck = int(desc.get("bottleneck", 0))
    model: Model
    if run.kind is ModelKind.MINCAM:
        camera = _run_camera(run, data)
        signed = bool(desc.get("signed", False))
        head = build_head(
            data,
            len(desc["detectors"]) // (2 if signed else 1) * steps,
            count_classes=desc.get("count_classes"),
            kind=kind,
            hidden=hidden,
            bottleneck=bottleneck,
        )
        model = MincamCamera(
            camera,
            head,
            detectors=desc["detectors"],
            sensor_model=desc["sensor_model"],
            history=desc["history"],
            mask_block=desc.get("mask_block", 1),
            signed=signed,
        )
    else:
        grid = (int(desc["grid"][0]), int(desc["grid"][1]))
        head = build_head(
            data,
            grid[0] * grid[1] * steps,
            count_classes=desc.get("count_classes"),
            kind=kind,
            hidden=hidden,
            bottleneck=bottleneck,
        )
        model = BaselineCamera(grid, head, exposure_w=desc["exposure_w"], history=desc["history"])
    state = {k: v for k, v in run.state.items() if not k.startswith(ADVERSARY_PREFIX)}
    try:
        model.load_state_dict(state)
    except RuntimeError as err:
        raise ValueError(
            f"{run.path}: checkpoint.pt does not fit the camera run.json describes "
            f"({str(err).splitlines()[-1].strip()[:160]})"
        ) from None
    model.eval()
    return model


def restore_mincam(run: TrainedRun, data: TrainingData, use: str) -> MincamCamera:
    """:func:`restore_model` of a run that must be a minimalist camera's.

    Args:
        run: the run.
        data: what the camera will measure.
        use: what it is for, as the refusal of another kind says it (``"prune"``).

    Raises:
        ValueError: a baseline run, or as :func:`restore_model`.
    """
    run.require(ModelKind.MINCAM, use)
    return cast(MincamCamera, restore_model(run, data))


def _run_camera(run: TrainedRun, data: TrainingData) -> FreeformCamera:
    """The run's camera, checked against ``data``'s transport (resolution, detectors)."""
    from mincam_render.data.dataset import camera_from_dict

    camera = camera_from_dict(run.record["camera"])
    detectors = run.record["model"]["detectors"]
    if data.camera.mask_resolution != camera.mask_resolution:
        raise ValueError(
            f"{run.path}: masks of {camera.mask_resolution} texels, but the data's transport "
            f"has {data.camera.mask_resolution}"
        )
    if max(detectors) >= data.transport.shape[1]:
        raise ValueError(
            f"{run.path}: reads detectors {detectors}; the data has {data.transport.shape[1]}"
        )
    return camera


def masks_of(run: TrainedRun) -> tuple[np.ndarray, FreeformCamera]:
    """A minimalist run's trained transmittance ``M[pixel, row, col]`` (numpy) and camera.

    Raises:
        ValueError: a baseline run (no masks).
    """
    from mincam_render.data.dataset import camera_from_dict
    from mincam_render.optics.maskplane import transmittance

    run.require(ModelKind.MINCAM, "exporting masks")
    camera = camera_from_dict(run.record["camera"])
    with torch.no_grad():
        m = transmittance(run.state["logits"], camera.transmittance_range).numpy()
    return m, camera


def run_masks(run_dir: str | os.PathLike) -> tuple[np.ndarray, FreeformCamera, RunRecord]:
    """``(M[pixel, row, col], camera, run.json)`` of a finished minimalist run (:func:`masks_of`).

    Raises:
        UnfinishedRunError: training did not finish.
        ValueError: not a run, or a baseline run.
    """
    run = open_run(run_dir)
    return (*masks_of(run), run.record)
