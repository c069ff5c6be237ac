"""Figures people look at instead of reading numbers (matplotlib, Agg backend)."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.colors  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes


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


def _series_name(design: str) -> str:
    """``mincam``, ``mincam-nosensor``, ``baseline`` (``-tcn`` heads apart) of a design name."""
    parts = design.split("-")
    return "-".join([parts[0], *(p for p in parts[2:] if p in ("nosensor", "tcn"))])


def plot_comparison(result: dict, path: str | os.PathLike) -> Path:
    """Save a PNG: the task's headline against pixel count, and every label with its interval.

    ``result`` is :func:`mincam_render.studies.comparison.study.run_comparison`'s
    output. Top: one point per design (mean over seeds, bootstrap interval as
    error bar, each seed as a faint dot), designs of one kind joined by a line
    (minimalist cameras, their no-sensor-model ablation, baselines, each head),
    and the trivial predictor as a band; an error-rate headline is shown as
    accuracy (lighting, like the paper's Fig. 8d). Below, when
    ``result["labels"]`` is present: one panel per label (people count RMSE,
    zone and door accuracy, ...), and one per element of a headline label of
    several (each light), with every design and the trivial predictor. Every
    axis starts at 0 (accuracy spans 0-1), so a small gap looks small.
    """
    panels = _label_panels(result)
    fig = plt.figure(figsize=(max(6.5, 3.3 * len(panels)), 7.6 if panels else 4))
    grid = fig.add_gridspec(2 if panels else 1, max(1, len(panels)))
    _plot_error_vs_pixels(fig.add_subplot(grid[0, :]), result)
    for i, (name, lab) in enumerate(panels):
        _plot_label(fig.add_subplot(grid[1, i]), name, lab)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _label_panels(result: dict[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """``(title, label figures)`` of every label, and of each element of a headline label."""
    labels = result.get("labels") or {}
    episodes: dict[str, Any] = result.get("trivial", {}).get("episodes") or {}
    first: dict[str, Any] = next(iter(episodes.values()), {})
    headline = first.get("headline", {}).get("labels", [])
    panels = list(labels.items())
    for label in headline:
        names = result.get("element_names", {}).get(label, [])
        for i, el in (labels.get(label, {}).get("elements") or {}).items():
            title = names[int(i)] if int(i) < len(names) else i
            panels.append((f"{label}: {title}", {"metric": "accuracy", "unit": "", **el}))
    return panels


def _as_array(v: Any) -> np.ndarray:
    return np.asarray(v, np.float64)


def _accuracy(v: Any) -> np.ndarray:
    return 1.0 - np.asarray(v, np.float64)


def _headline_axis(result: dict[str, Any]) -> tuple[Callable[[Any], np.ndarray], str]:
    """How the top panel shows the headline: accuracy (1 - error rate) or the error itself."""
    name = result["error_name"]
    if name.endswith(" error rate"):  # accuracy against pixels, as the paper's Fig. 8d
        return _accuracy, f"test {name.removesuffix(' error rate')} accuracy"
    return _as_array, f"test {name}"


def _plot_error_vs_pixels(ax: Axes, result: dict[str, Any]) -> None:
    shown, ylabel = _headline_axis(result)
    lo, hi = sorted(shown(result["trivial"]["error"]["ci95"]))
    ax.axhspan(lo, hi, color="0.85", label="trivial predictor (95 % CI)")
    ax.axhline(float(shown(result["trivial"]["error"]["mean"])), color="0.5", lw=1, ls="--")
    series: dict[str, list] = {}
    for name, d in result["designs"].items():
        series.setdefault(_series_name(name), []).append(d)
    for kind, ds in series.items():
        colour = f"C{_SERIES.index(kind)}"
        ds = sorted(ds, key=lambda d: d["model"]["pixels"])
        px = np.array([d["model"]["pixels"] for d in ds])
        mean = shown([d["error"]["mean"] for d in ds])
        ci = np.sort(shown([d["error"]["ci95"] for d in ds]), axis=1)
        ax.errorbar(
            px,
            mean,
            yerr=np.clip([mean - ci[:, 0], ci[:, 1] - mean], 0.0, None),
            fmt="o-",
            color=colour,
            capsize=4,
            label=kind,
        )
        for p, d in zip(px, ds, strict=True):
            seeds = shown(d["error_per_seed"])
            ax.plot([p] * len(seeds), seeds, ".", color=colour, alpha=0.4)
    ax.set_xscale("log", base=2)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("pixels")
    ax.set_ylabel(ylabel)
    n = len(result["designs"])
    what = result["verdict"] or f"{n} designs, mean over seeds, 95 % CI"
    ax.set_title(f"{result['task']}: {what}", fontsize=8)
    ax.legend(fontsize=7)


def _plot_label(ax: Axes, name: str, lab: dict[str, Any]) -> None:
    """One label's figure per configuration (the trivial predictor in grey), 95 % CIs."""
    configs = list(lab["configs"].items())
    x = np.arange(len(configs))
    mean = np.array([c["mean"] for _, c in configs])
    ci = np.array([c["ci95"] for _, c in configs])
    colours = [
        "0.5" if n == "trivial" else f"C{_SERIES.index(_series_name(n))}" for n, _ in configs
    ]
    for xi, m, c, colour in zip(x, mean, ci, colours, strict=True):
        ax.errorbar(
            xi,
            m,
            yerr=[[max(m - c[0], 0.0)], [max(c[1] - m, 0.0)]],
            fmt="o",
            color=colour,
            capsize=4,
        )
    ax.set_xticks(x, [n for n, _ in configs], rotation=45, ha="right", fontsize=7)
    ax.set_xlim(-0.6, len(configs) - 0.4)
    unit = f" ({lab['unit']})" if lab["unit"] else ""
    if lab["metric"] == "accuracy":
        ax.set_ylim(0.0, 1.0)
        ax.set_ylabel("accuracy (higher is better)", fontsize=8)
    else:
        ax.set_ylim(0.0, 1.1 * float(np.max(ci[:, 1])) or 1.0)
        ax.set_ylabel(f"RMSE{unit} (lower is better)", fontsize=8)
    ax.set_title(name, fontsize=9)


#: Design kinds, each drawn in its own colour (C0, C1, ...) in every panel.
_SERIES = (
    "mincam",
    "mincam-nosensor",
    "baseline",
    "mincam-tcn",
    "mincam-nosensor-tcn",
    "baseline-tcn",
)
