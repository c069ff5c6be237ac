"""The attacks: what a design's read-out gives away to a learned decoder and a classifier (torch).

The attacker knows the design (its masks, or the baseline's grid and exposure)
and owns episodes of the same room with their full views and who was present
(the design's training episodes); it never sees the test episodes it is scored
on. From the design's read-out of a frame (with sensor noise, as deployed) it
learns

* a **decoder** of what the people add to the view (:mod:`.decoders`, which
  trains with :func:`fit_adam` here), and
* a **re-identification** classifier: which of the roster's people are in the
  room (an MLP, one logit per person, binary cross-entropy), scored top-1.

Both keep the state of the lowest validation loss (the validation episode).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from mincam_render.learn.training_data import TrainingData
from mincam_render.studies.privacy.config import AttackConfig

#: Frames measured at once (bounds memory at 32 x 32 texels x 8 detectors).
MEASURE_CHUNK = 512


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """Torch on one intra-op thread inside the block (restored after).

    The attackers are tiny networks: on a small shared machine torch's spinning
    worker threads make them many times slower (as ``TrainConfig.torch_threads``).
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def design_camera(run_dir: str | os.PathLike, data: TrainingData) -> Any:
    """The trained camera (``MincamCamera`` or ``BaselineCamera``) of a finished run."""
    from mincam_render.learn.train import open_run, restore_model

    return restore_model(open_run(run_dir), data)


def measurements(camera: Any, data: TrainingData, *, seed: int) -> np.ndarray:
    """The read-out ``[frame, pixel]`` of every frame of ``data``, with sensor noise (numpy).

    Volts for a minimalist camera, 0-1 (DN / 255) for a baseline; the noise is
    drawn from ``seed`` so the attacker's data is reproducible.
    """
    gen = torch.Generator().manual_seed(int(seed))
    out = []
    with torch.no_grad(), one_thread():
        for start in range(0, len(data), MEASURE_CHUNK):
            idx = torch.arange(start, min(start + MEASURE_CHUNK, len(data)))
            frames = data.frames_w(idx)
            v = camera.measure(frames, noise=True, generator=gen)
            out.append(v.reshape(len(idx), -1).numpy())
    return np.concatenate(out).astype(np.float32)


class Standardise(nn.Module):
    """Fixed per-feature standardisation with the attacker's training statistics."""

    mean: torch.Tensor  # buffer: [feature]
    std: torch.Tensor  # buffer: [feature]

    def __init__(self, x: np.ndarray) -> None:
        super().__init__()
        self.register_buffer("mean", torch.from_numpy(x.mean(axis=0)).float())
        self.register_buffer("std", torch.from_numpy(x.std(axis=0) + 1e-6).float())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(x - mean) / std`` of inputs ``[frame, feature]``."""
        return (x - self.mean) / self.std


def mlp(x_train: np.ndarray, outputs: int, hidden: int) -> nn.Sequential:
    """Standardised inputs, two hidden ReLU layers of ``hidden`` units, ``outputs`` linear."""
    return nn.Sequential(
        Standardise(x_train),
        nn.Linear(x_train.shape[1], hidden),
        nn.ReLU(),
        nn.Linear(hidden, hidden),
        nn.ReLU(),
        nn.Linear(hidden, outputs),
    )


@dataclass
class Fitted:
    """A trained attacker: the model (best validation state), its history, its steps."""

    model: nn.Module
    history: list[dict[str, float]]
    best_step: int

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Raw outputs ``[frame, ...]`` (numpy) of inputs ``[frame, feature]``."""
        with torch.no_grad():
            return self.model(torch.from_numpy(np.asarray(x, np.float32))).numpy()


@one_thread()
def fit_adam(
    model: nn.Module,
    loss_of: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
    train: tuple[np.ndarray, np.ndarray],
    val: tuple[np.ndarray, np.ndarray],
    cfg: AttackConfig,
    seed: int,
) -> Fitted:
    """Adam on ``loss_of(outputs, targets)`` in batches; the state of the lowest validation loss."""
    gen = torch.Generator().manual_seed(int(seed))
    xt, yt = (torch.from_numpy(np.asarray(a, np.float32)) for a in train)
    xv, yv = (torch.from_numpy(np.asarray(a, np.float32)) for a in val)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    best, best_state, best_step, history = float("inf"), None, 0, []
    for step in range(1, cfg.max_steps + 1):
        idx = torch.randint(len(xt), (cfg.batch_size,), generator=gen)
        loss = loss_of(model(xt[idx]), yt[idx])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if step % cfg.eval_every == 0 or step == cfg.max_steps:
            with torch.no_grad():
                val_loss = float(loss_of(model(xv), yv))
            history.append({"step": step, "val_loss": val_loss})
            if val_loss < best:
                best, best_step = val_loss, step
                best_state = {k: v.clone() for k, v in model.state_dict().items()}
    if best_state is not None:
        model.load_state_dict(best_state)
    model.eval()
    return Fitted(model, history, best_step)


def seeded(seed: int, build: Callable[[], nn.Module]) -> nn.Module:
    """``build()`` with torch's generator at ``seed`` (the global one restored after)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(seed))
        return build()


def train_reid(
    train: tuple[np.ndarray, np.ndarray],
    val: tuple[np.ndarray, np.ndarray],
    cfg: AttackConfig,
    seed: int,
) -> Fitted:
    """Classifier from read-outs ``[frame, pixel]`` to who is present ``[frame, identity]``."""
    x, y = train
    model = seeded(seed, lambda: mlp(x, y.shape[1], cfg.hidden))
    return fit_adam(model, F.binary_cross_entropy_with_logits, train, val, cfg, seed)
