"""Mask snapshots during training and their figure (``mask_evolution.png``)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from mincam_render.learn.evaluation import even_indices
from mincam_render.learn.models import MincamCamera, Model


def mask_snapshot(model: Model) -> np.ndarray | None:
    """Mask transmittance ``M[pixel, row, col]`` (0-1, numpy copy); None for a baseline camera."""
    if isinstance(model, MincamCamera):
        with torch.no_grad():
            return model.transmittance().numpy().copy()
    return None


def plot_mask_evolution(
    snapshots: Sequence[tuple[int, np.ndarray]], path: str | os.PathLike, max_rows: int = 6
) -> Path:
    """Grid of mask transmittance (rows: training steps, columns: pixels), saved as PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pick = even_indices(len(snapshots), max_rows)
    rows = [snapshots[i] for i in pick]
    k = rows[0][1].shape[0]
    cols = min(k, 16)
    fig, axes = plt.subplots(
        len(rows), cols, figsize=(1.3 * cols + 0.8, 1.3 * len(rows) + 0.4), squeeze=False
    )
    for r, (step, m) in enumerate(rows):
        for c in range(cols):
            ax = axes[r, c]
            ax.imshow(m[c], cmap="gray", vmin=0.0, vmax=1.0, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"pixel {c}", fontsize=8)
            if c == 0:
                ax.set_ylabel(f"step {step}", fontsize=8)
    fig.suptitle("mask transmittance during training (0 black, 1 white)", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
