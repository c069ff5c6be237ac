"""Decoders of the people: from a design's read-out to what they add to the view (torch, numpy).

The attacker is given each frame's background (the room as it is at that
moment with nobody in it, :mod:`mincam_render.data.views`): an attacker who
photographed the empty room under each light gets it for free. What it must
learn from the read-out is the rest, the *difference* ``view - background``
(display units, in [-1, 1]: the people, their shadows, their light on the
room); its reconstruction of a frame is ``clip(background + difference, 0, 1)``.
A decoder that predicts no difference reconstructs the background: the trivial
attacker that sees no one.

Three decoders, trained on the attacker's episodes (mean squared error of the
difference, the state of the lowest validation loss kept):

* ``mlp``: two hidden layers, one linear output per view pixel;
* ``conv``: a linear map to a coarse grid of feature maps, then transposed
  convolutions, each doubling the grid, up to the view (:class:`ConvDecoder`):
  images are local, so it needs far fewer weights per output than the MLP;
* ``ridge``: a linear map in closed form, its penalty chosen on the validation
  episode (for a conventional camera, whose read-out is a downsampled image,
  the natural attacker).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from mincam_render.studies.privacy.attacks import Fitted, Standardise, fit_adam, mlp, seeded
from mincam_render.studies.privacy.config import DECODERS, AttackConfig, DecoderKind

#: The coarsest grid of the convolutional decoder: it halves the view while the
#: side stays even and the half at least this many pixels.
CONV_MIN_GRID = 8


class Decoder(Protocol):
    """What every trained decoder offers: the difference images of read-outs."""

    @property
    def history(self) -> Sequence[Mapping[str, float]] | None:
        """Its validation checks ``{"step", "val_loss"}`` (None: solved in closed form)."""
        ...

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Differences ``[frame, row, col]`` (display units) of read-outs ``[frame, pixel]``."""
        ...


def coarse_grid(width: int) -> tuple[int, int]:
    """``(side, doublings)`` of the convolutional decoder's coarsest grid for a view ``width``.

    ``side * 2**doublings == width``: halve while even and the half stays at
    least :data:`CONV_MIN_GRID` (64 -> 8 and 3 doublings; 48 -> 12 and 2).
    """
    side, doublings = int(width), 0
    while side % 2 == 0 and side // 2 >= CONV_MIN_GRID:
        side, doublings = side // 2, doublings + 1
    return side, doublings


class ConvDecoder(nn.Module):
    """Read-outs ``[frame, pixel]`` -> images ``[frame, width, width]`` (torch).

    Standardised read-out, a hidden layer of ``hidden`` units, a linear map to
    ``channels`` feature maps on the coarse grid (:func:`coarse_grid`), then per
    doubling a transposed convolution (4 x 4, stride 2: the grid doubles exactly)
    halving the channels (at least 4) with a ReLU; the last one gives the image
    (one linear channel; a 3 x 3 convolution when the view is the coarse grid).
    """

    def __init__(self, x_train: np.ndarray, width: int, hidden: int, channels: int) -> None:
        super().__init__()
        side, doublings = coarse_grid(width)
        self.inputs = nn.Sequential(
            Standardise(x_train),
            nn.Linear(x_train.shape[1], hidden),
            nn.ReLU(),
            nn.Linear(hidden, channels * side * side),
            nn.ReLU(),
            nn.Unflatten(1, (channels, side, side)),
        )
        layers: list[nn.Module] = []
        c = channels
        for _ in range(doublings - 1):
            layers += [nn.ConvTranspose2d(c, max(c // 2, 4), 4, stride=2, padding=1), nn.ReLU()]
            c = max(c // 2, 4)
        # the last doubling gives the image itself (one linear channel)
        last = (
            nn.ConvTranspose2d(c, 1, 4, stride=2, padding=1)
            if doublings
            else nn.Conv2d(c, 1, 3, padding=1)
        )
        self.upsample = nn.Sequential(*layers, last)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Images ``[frame, width, width]`` of read-outs ``[frame, pixel]``."""
        return self.upsample(self.inputs(x))[:, 0]


def train_decoder(
    kind: DecoderKind | str,
    train: tuple[np.ndarray, np.ndarray],
    val: tuple[np.ndarray, np.ndarray],
    cfg: AttackConfig,
    seed: int,
) -> Decoder:
    """A decoder (``kind`` of :data:`DECODERS`) from read-outs to differences ``[frame, row, col]``.

    Args:
        kind: a :class:`DecoderKind` (or its value).
        train: ``(read-outs [frame, pixel], differences [frame, row, col])``.
        val: the same of the validation episode (early stopping, ridge penalty).
        cfg: the attacker's settings (steps, batch, hidden units, channels).
        seed: initial weights and batches.

    Raises:
        ValueError: an unknown ``kind``; a non-square view.
    """
    x, y = train
    try:
        kind = DecoderKind(kind)
    except ValueError:
        raise ValueError(f"decoder {kind!r}: allowed {', '.join(DECODERS)}") from None
    if y.ndim != 3 or y.shape[1] != y.shape[2]:
        raise ValueError(f"differences {y.shape}: need [frame, row, col] with rows == cols")
    if kind is DecoderKind.RIDGE:
        return fit_ridge(train, val)
    model = seeded(seed, lambda: _network(kind, x, y.shape[1], cfg))
    fitted: Fitted = fit_adam(model, F.mse_loss, train, val, cfg, seed)
    return fitted


def _network(kind: DecoderKind, x_train: np.ndarray, width: int, cfg: AttackConfig) -> nn.Module:
    """The untrained ``mlp`` or ``conv`` decoder to ``width`` x ``width`` images."""
    if kind is DecoderKind.CONV:
        return ConvDecoder(x_train, width, cfg.hidden, cfg.conv_channels)
    return nn.Sequential(*mlp(x_train, width * width, cfg.hidden), nn.Unflatten(1, (width, width)))


def reconstruct(decoder: Decoder, x: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Display images ``[frame, row, col]``: ``clip(background + decoded difference, 0, 1)``."""
    diff = decoder.predict(x)
    return np.clip(np.asarray(background, np.float32) + diff, 0.0, 1.0).astype(np.float32)


#: Ridge penalties tried by :func:`fit_ridge` (times the number of training frames).
#: The largest shrink the map to the mean training image (the read-out ignored):
#: a read-out that tells little about the people is best decoded near there.
RIDGE_PENALTIES = (1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1000.0)


@dataclass
class RidgeDecoder:
    """A linear decoder (ridge regression, closed form) from read-outs to images."""

    mean: np.ndarray  # [feature]
    std: np.ndarray  # [feature]
    weights: np.ndarray  # [feature + 1, pixel]
    penalty: float
    shape: tuple[int, int]  # (row, col) of the images
    history: None = None  # closed form: no training steps

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Images ``[frame, row, col]`` (float32) of read-outs ``[frame, feature]``."""
        z = (np.asarray(x, np.float64) - self.mean) / self.std
        y = np.hstack([z, np.ones((len(z), 1))]) @ self.weights
        return y.reshape(len(x), *self.shape).astype(np.float32)


def fit_ridge(
    train: tuple[np.ndarray, np.ndarray], val: tuple[np.ndarray, np.ndarray]
) -> RidgeDecoder:
    """Ridge regression from read-outs to images ``[frame, row, col]``, penalty chosen on ``val``.

    The bias is not penalised; the penalty of the lowest validation mean
    squared error among :data:`RIDGE_PENALTIES` is kept (numpy, float64).
    """
    x, y = np.asarray(train[0], np.float64), np.asarray(train[1], np.float64)
    mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
    a = np.hstack([(x - mean) / std, np.ones((len(x), 1))])
    gram, rhs = a.T @ a, a.T @ y.reshape(len(y), -1)
    shape = (int(y.shape[1]), int(y.shape[2]))
    best: RidgeDecoder | None = None
    best_mse = np.inf
    for penalty in RIDGE_PENALTIES:
        reg = penalty * len(x) * np.eye(len(gram))
        reg[-1, -1] = 0.0  # the bias is not penalised
        cand = RidgeDecoder(mean, std, np.linalg.solve(gram + reg, rhs), penalty, shape)
        mse = float(np.mean((cand.predict(val[0]) - val[1]) ** 2))
        if mse < best_mse:
            best, best_mse = cand, mse
    assert best is not None
    return best
