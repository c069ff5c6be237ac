"""Checkpoints of a training run: the resumable state, written atomically, read back.

A checkpoint (``checkpoint.pt``, written after every evaluation) holds the
model, the optimiser, the random generator and the batch source's state
besides :class:`TrainingState`: a killed run started again with the same
arguments resumes from it and reaches the same state as an uninterrupted run.
"""

from __future__ import annotations

import io
import math
import pickle
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mincam_render.learn.batches import DatasetBatches, RenderedBatches
from mincam_render.learn.builders import describe_model
from mincam_render.learn.models import Model
from mincam_render.learn.train_config import TrainConfig


@dataclass
class TrainingState:
    """Where a training run stands, besides its model, optimiser, generator and batch source.

    Args:
        step: optimisation steps taken.
        best_step: step of the lowest validation loss so far.
        bad: evaluations since the last improvement or learning-rate decay (early
            stopping counts them).
        lr_decays: learning-rate decays done (each at a plateau of ``patience``).
        best_loss: lowest validation loss so far (inf before the first evaluation).
        best_state: the model's ``state_dict`` at ``best_step`` (torch tensors).
        history: one record per evaluation: ``step``, ``train_loss``, ``val_loss``,
            ``wall_time_s`` (training time, s).
        snapshots: ``(step, M[pixel, row, col])`` mask transmittance (0-1) over training.
        elapsed: training time so far (s), across resumes.
        stopped_early: whether early stopping ended the run.

    """

    step: int = 0
    best_step: int = 0
    bad: int = 0
    lr_decays: int = 0
    best_loss: float = math.inf
    best_state: dict[str, torch.Tensor] = field(default_factory=dict)
    history: list[dict[str, float]] = field(default_factory=list)
    snapshots: list[tuple[int, np.ndarray]] = field(default_factory=list)
    elapsed: float = 0.0
    stopped_early: bool = False


def atomic_save(obj: Any, path: Path) -> None:
    """``torch.save`` of ``obj`` to ``path``: a kill or a full disk leaves the old file."""
    from mincam_render.data.dataset import atomic_write_bytes

    buf = io.BytesIO()
    torch.save(obj, buf)
    # temporary file, fsync, rename: a kill or a full disk leaves the old checkpoint
    atomic_write_bytes(path, buf.getvalue())


#: A checkpoint as ``torch.save`` writes it and ``torch.load`` returns it (torch's
#: format): the model's description, the config, the model's, optimiser's and
#: generator's state dicts, the batch source's state and :class:`TrainingState`'s fields.
Checkpoint = dict[str, Any]


def load_checkpoint(path: Path) -> Checkpoint:
    """``torch.load`` of a checkpoint; a damaged file is a one-line ValueError naming it."""
    try:
        return torch.load(path, weights_only=False)
    except (RuntimeError, EOFError, OSError, ValueError, pickle.UnpicklingError) as err:
        raise ValueError(
            f"{path}: checkpoint unreadable ({str(err).splitlines()[0][:120]}); delete it or "
            "train with --no-resume"
        ) from None


def save_checkpoint(
    path: Path,
    model: Model,
    config: TrainConfig,
    opt: torch.optim.Optimizer,
    generator: torch.Generator,
    source: DatasetBatches | RenderedBatches,
    state: TrainingState,
) -> None:
    """Write the checkpoint of a run at ``state`` to ``path`` (atomic)."""
    atomic_save(
        {
            "model_description": describe_model(model),
            "config": asdict(config),
            "model": model.state_dict(),
            "optimizer": opt.state_dict(),
            "generator": generator.get_state(),
            "source": source.state(),
            # every field of the state (not asdict: it would deep-copy the tensors)
            **{f.name: getattr(state, f.name) for f in fields(TrainingState)},
        },
        path,
    )


def restore_checkpoint(
    path: Path,
    model: Model,
    opt: torch.optim.Optimizer,
    generator: torch.Generator,
    source: DatasetBatches | RenderedBatches,
) -> TrainingState:
    """Load ``path`` into the model, optimiser, generator and source; the run's state.

    Raises:
        ValueError: the checkpoint is unreadable or was written for another model.

    """
    ck = load_checkpoint(path)
    if ck["model_description"] != describe_model(model):
        raise ValueError(
            f"{path} was written for {ck['model_description']}, not "
            f"{describe_model(model)}; use another --out or delete the checkpoint"
        )
    model.load_state_dict(ck["model"])
    opt.load_state_dict(ck["optimizer"])
    generator.set_state(ck["generator"])
    source.load_state(ck["source"])
    # a field the checkpoint's writer did not have yet takes its default (0 decays done)
    return TrainingState(**{f.name: ck[f.name] for f in fields(TrainingState) if f.name in ck})
