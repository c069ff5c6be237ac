"""Figures of a privacy audit (matplotlib): the privacy-utility curve, example reconstructions.

Each function takes a :class:`~.result.PrivacyResult` (and the examples written
beside it) and returns ``(figure, caption)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.studies.comparison.config import Design
from mincam_render.studies.privacy.curve import audit_designs
from mincam_render.studies.privacy.result import PrivacyResult

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: Attack figures on the curve's x axes: (key, axis label).
CURVE_AXES = (
    ("fg_psnr_db", "PSNR of the people's pixels (dB, higher = more revealed)"),
    ("reid_top1", "re-identification top-1 accuracy"),
)


def _style(design: Design) -> tuple[str, str]:
    """``(colour, marker)`` of a design's point."""
    if design.privacy_weight:
        return "C2", "D"
    return ("C0", "o") if design.is_mincam else ("C1", "s")


def _plot_curve(ax: Axes, privacy: PrivacyResult, key: str, label: str) -> None:
    kinds = audit_designs(privacy)
    for name, d in privacy.designs.items():
        x, y = d.figure(key), d.task_error
        color, marker = _style(kinds[name])
        ax.errorbar(
            x.mean, y.mean, xerr=[[x.mean - x.low], [x.high - x.mean]],
            yerr=[[y.mean - y.low], [y.high - y.mean]], ls="none", capsize=2, color=color,
            marker=marker,
        )  # fmt: skip
        ax.annotate(name.replace("baseline-", "").replace("mincam-", ""), (x.mean, y.mean),
                    fontsize=7, xytext=(3, 3), textcoords="offset points")  # fmt: skip
    t = privacy.trivial
    ax.axvline(t.figures.figure(key).mean, color="0.4", ls="--", lw=1, label="trivial attacker")
    prior = getattr(privacy.prior.figures, key)
    if prior is not None:
        ax.axvline(prior.mean, color="C3", ls="-.", lw=1, label="prior")
    ax.axhline(t.task_error.mean, color="0.4", ls=":", lw=1, label="trivial task predictor")
    ax.set_xlabel(label)
    ax.set_ylabel(f"task error ({privacy.error_name})")
    ax.legend(fontsize=7, loc="upper right")


def curve_figure(privacy: PrivacyResult) -> tuple[Figure, str]:
    """Task error against attack success for every design (95 % intervals as bars)."""
    from mincam_render.analysis.plots import plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (key, label) in zip(axes, CURVE_AXES, strict=True):
        _plot_curve(ax, privacy, key, label)
    fig.suptitle("privacy-utility: the private, useful corner is bottom left", fontsize=10)
    fig.tight_layout()
    return fig, (
        "Task error (test people-count RMSE) against the attacker's success: left, the PSNR of "
        "the view decoded from the design's read-out on its foreground (the pixels the people "
        "change; the attacker is given the empty room, so the trivial attacker, the dashed "
        "line, sees no one; dash-dotted, the prior: where people usually are, read-out "
        "ignored); right, how often the attacker's top guess of who is in the room is right. "
        "Blue: minimalist cameras; green: trained with the privacy term; orange: conventional "
        "baselines (grid size). Bars: 95 % intervals (task: training seeds x test episodes; "
        "attacks: attacker seeds x test episodes)."
    )


def matched_baseline(privacy: PrivacyResult, design: str) -> str | None:
    """The baseline whose mean task error is closest to ``design``'s (None without baselines)."""
    designs = privacy.designs
    target = designs[design].task_error.mean
    kinds = audit_designs(privacy)
    names = [n for n in designs if not kinds[n].is_mincam]
    return min(names, key=lambda n: abs(designs[n].task_error.mean - target), default=None)


def _design_order(
    privacy: PrivacyResult, examples: Mapping[str, np.ndarray]
) -> tuple[list[str], list[str]]:
    """``(names in the file's order, names to show: minimalist, then baselines)``."""
    kinds = audit_designs(privacy)
    names = [str(n) for n in examples["designs"]]
    order = sorted(names, key=lambda n: not kinds[n].is_mincam)  # stable: the file's order
    return names, order


def _short(name: str) -> str:
    return name.replace("baseline-", "").replace("mincam-", "")


def _grid(
    columns: list[tuple[str, list[np.ndarray]]], frames: int, **imshow: Any
) -> tuple[Figure, np.ndarray]:
    """One row per frame, one titled column per ``(title, images)``: images without ticks."""
    from mincam_render.analysis.plots import plt

    cols = len(columns)
    fig, axes = plt.subplots(frames, cols, figsize=(1.25 * cols, 1.35 * frames), squeeze=False)
    for c, (title, images) in enumerate(columns):
        for r in range(frames):
            ax = axes[r][c]
            ax.imshow(images[r], interpolation="nearest", **imshow)
            ax.set_xticks([])
            ax.set_yticks([])
        axes[0][c].set_title(title, fontsize=7)
    fig.tight_layout(pad=0.3)
    return fig, axes


def examples_figure(
    privacy: PrivacyResult, examples: Mapping[str, np.ndarray]
) -> tuple[Figure, str]:
    """Rows: test frames; columns: the true view, each design's reconstruction (first seed)."""
    names, order = _design_order(privacy, examples)
    columns = [("true view", list(examples["true"]))] + [
        (_short(n), list(examples["recon"][names.index(n)])) for n in order
    ]
    fig, _ = _grid(columns, len(examples["frames"]), cmap="gray", vmin=0, vmax=1)
    kinds = audit_designs(privacy)
    pairs = ", ".join(f"{n} ~ {matched_baseline(privacy, n)}" for n in order if kinds[n].is_mincam)
    return fig, (
        f"Test frames {', '.join(map(str, examples['frames']))} of the first test episode: "
        "the true view (display image) and what the first attacker seed decodes from each "
        "design's read-out (the room's background given, the people decoded). Baselines "
        f"closest in task error: {pairs}."
    )


#: Display difference shown at full colour in the foreground figure.
DIFFERENCE_RANGE = 0.4


def foreground_figure(
    privacy: PrivacyResult, examples: Mapping[str, np.ndarray]
) -> tuple[Figure, str]:
    """The same frames as :func:`examples_figure`, as differences from the frame's background."""
    names, order = _design_order(privacy, examples)
    bg = examples["background"]
    columns = [("people (true)", list(examples["true"] - bg))] + [
        (_short(n), list(examples["recon"][names.index(n)] - bg)) for n in order
    ]
    frames = len(examples["frames"])
    lim = DIFFERENCE_RANGE
    fig, axes = _grid(columns, frames, cmap="RdBu_r", vmin=-lim, vmax=lim)
    for r in range(frames):
        axes[r][0].contour(examples["mask"][r], levels=[0.5], colors="k", linewidths=0.4)
    return fig, (
        "What the people add to each view: the true view minus the frame's background (the "
        "same frame with its people removed; black outline: the foreground mask the PSNR and "
        "SSIM of the people are scored on) and each design's decoded difference (first "
        f"attacker seed). Red brighter, blue darker than the empty room; full colour at "
        f"+-{lim:g} display units."
    )
