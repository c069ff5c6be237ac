"""Figures people look at instead of reading numbers (matplotlib, Agg backend).

Importing this module selects the Agg backend; studies draw their figures with
its ``plt`` (a comparison's is :func:`~mincam_render.studies.comparison.report.plot_comparison`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def plot_transport_grid(
    transport_w: np.ndarray,
    path: str | os.PathLike,
    *,
    title: str,
    board_positions_m: np.ndarray | None = None,
) -> Path:
    """Save a PNG of every detector's transport image ``T[detector, row, col]`` (W).

    One shared colour scale, so brightness differences between detectors
    (parallax, vignetting) stay visible; each panel is oriented as a photo
    seen from the camera (row 0 at the top).
    """
    t = np.asarray(transport_w, dtype=np.float64)
    k = t.shape[0]
    cols = (
        min(k, 6)
        if board_positions_m is None
        else len(np.unique(np.round(board_positions_m[:, 0], 6)))
    )
    cols = max(1, min(cols, k))
    rows = math.ceil(k / cols)
    fig, axes = plt.subplots(
        rows,
        cols,
        figsize=(1.9 * cols + 1.2, 1.9 * rows + 0.8),
        squeeze=False,
        constrained_layout=True,
    )
    vmax = float(np.percentile(t, 99.5)) or 1.0
    # a power-law scale keeps dim walls visible next to a bright lamp
    norm = matplotlib.colors.PowerNorm(gamma=0.4, vmin=0.0, vmax=vmax * 1e9)
    im = None
    for i, ax in enumerate(axes.flat):
        ax.set_xticks([])
        ax.set_yticks([])
        if i >= k:
            ax.axis("off")
            continue
        im = ax.imshow(t[i] * 1e9, cmap="inferno", norm=norm, interpolation="nearest")
        ax.set_title(f"detector {i}", fontsize=8)
    fig.suptitle(title, fontsize=10)
    if im is not None:
        fig.colorbar(im, ax=axes, shrink=0.8, label="power per texel at M=1 (nW, power-law scale)")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
