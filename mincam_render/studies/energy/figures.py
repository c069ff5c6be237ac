"""Figures of an energy result (matplotlib): the day's light and storage, frame rates, margins.

Each function takes the result of
:func:`~mincam_render.studies.energy.study.run` and returns
``(figure, caption)``. :func:`summary_figure` is the one-image summary saved as
``energy.png``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mincam_render.studies.energy.result import EnergyResult


def figures(result: EnergyResult) -> list[tuple[Figure, str]]:
    """``[(figure, caption)]`` of the report, in page order."""
    return [_day_figure(result), _fps_figure(result), _threshold_figure(result)]


def _day_figure(result: EnergyResult) -> tuple[Figure, str]:
    from mincam_render.analysis.plots import plt

    fig, (ax_lux, ax_e) = plt.subplots(1, 2, figsize=(11, 3.8))
    _plot_lux(ax_lux, result)
    for name, fam in result.families.items():
        ax_e.plot(fam.storage_trace.hours, fam.storage_trace.stored_j, label=name)
    s = result.config.storage
    e_bo = 0.5 * s.capacitance_f * s.brownout_voltage_v**2
    ax_e.axhline(e_bo, color="0.4", ls="--", lw=1, label="brown-out")
    ax_e.set_xlabel("local solar time (h)")
    ax_e.set_ylabel("stored energy (J)")
    ax_e.set_title(f"capacitor, {result.config.max_pixels} px at {result.config.fps:g} fps")
    ax_e.set_xlim(0, 24)
    ax_e.legend(fontsize=8)
    fig.tight_layout()
    return fig, (
        "Left: illuminance on the panel over the simulated day (rendered in each scene's own "
        "light; office lights on the schedule). Right: energy in the supercapacitor with the "
        "camera at the configured frame rate (the second of two simulated days)."
    )


def _plot_lux(ax: Axes, result: EnergyResult) -> None:
    for name, fam in result.families.items():
        ax.plot(fam.hours, fam.lux, label=name)
    th = result.threshold
    ax.axhline(th.budget.threshold_lux, color="C3", ls="--", lw=1, label="needed: this model")
    ax.axhline(th.paper_lux, color="0.3", ls=":", lw=1, label="paper: ~600 lx")
    ax.set_xlabel("local solar time (h)")
    ax.set_ylabel("panel illuminance (lx)")
    ax.set_xlim(0, 24)
    ax.set_title("light on the panel")
    ax.legend(fontsize=8)


def _fps_figure(result: EnergyResult) -> tuple[Figure, str]:
    from matplotlib.colors import LogNorm

    from mincam_render.analysis.plots import plt

    fams = list(result.families.items())
    fig, axes = plt.subplots(1, len(fams), figsize=(5.5 * len(fams), 3.8), squeeze=False)
    for ax, (name, fam) in zip(axes[0], fams, strict=True):
        fps = np.array([fam.sustainable_fps[k] for k in _pixels(result)])
        hours = np.asarray(fam.hours)
        half = 0.5 * (hours[1] - hours[0])  # each column centred on its sample hour
        im = ax.imshow(
            np.maximum(fps, 0.1),
            aspect="auto",
            origin="lower",
            extent=(hours[0] - half, hours[-1] + half, 0.5, len(fps) + 0.5),
            norm=LogNorm(vmin=0.1, vmax=max(float(fps.max()), 1.0)),
            cmap="viridis",
        )
        if len(fps) > 1 and fps.min() < result.config.fps < fps.max():
            ax.contour(hours, _pixels(result), fps, levels=[result.config.fps], colors="w")
        ax.set_xlabel("local solar time (h)")
        ax.set_ylabel("freeform pixels K")
        ax.set_title(f"{name}: sustainable frame rate (white: {result.config.fps:g} fps)")
        fig.colorbar(im, ax=ax, label="frames per second")
    fig.tight_layout()
    return fig, (
        "Sustainable frame rate (what the panel's harvest pays for, after leakage and the "
        "converter) for K = 1..max pixels through the day; the white line is the configured rate."
    )


def _pixels(result: EnergyResult) -> list[int]:
    return list(range(1, result.config.max_pixels + 1))


def _threshold_figure(result: EnergyResult) -> tuple[Figure, str]:
    from mincam_render.analysis.plots import plt

    fig, ax = plt.subplots(figsize=(7, 3.8))
    budgets = next(iter(result.families.values())).budgets
    ax.plot(
        [b.pixels for b in budgets],
        [b.threshold_lux for b in budgets],
        "o-",
        ms=3,
        label="minimalist camera",
    )
    for i, (name, comp) in enumerate(result.comparisons.items()):
        for key, module, marker in (
            ("module", comp.module, "s"),
            ("module_outputs_only", comp.module_outputs_only, "^"),
        ):
            ax.plot(
                comp.mincam.budget.pixels,
                module.budget.threshold_lux,
                marker,
                color=f"C{i + 1}",
                label=f"{module.name} {comp.match.grid[0]}x"
                f"{comp.match.grid[1]} ({name}{', outputs only' if key != 'module' else ''})",
            )
    ax.axhline(result.threshold.paper_lux, color="0.3", ls=":", lw=1, label="paper: ~600 lx")
    ax.set_yscale("log")
    ax.set_xlabel("freeform pixels K (module: at the K of equal task error)")
    ax.set_ylabel(f"panel lux for {result.config.fps:g} fps")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig, (
        "Panel illuminance needed to run at the configured frame rate indefinitely, against the "
        "pixel count; a conventional module at equal task error (from the study tables, else the "
        "paper's matches) needs the marked illuminance."
    )


def summary_figure(result: EnergyResult) -> Figure:
    """One image: the day's lux beside the threshold, and the lux needed per pixel count."""
    from mincam_render.analysis.plots import plt

    fig, (ax_lux, ax_th) = plt.subplots(1, 2, figsize=(11, 3.8))
    _plot_lux(ax_lux, result)
    budgets = next(iter(result.families.values())).budgets
    ax_th.plot([b.pixels for b in budgets], [b.threshold_lux for b in budgets], "o-", ms=3)
    ax_th.axhline(result.threshold.paper_lux, color="0.3", ls=":", lw=1, label="paper")
    ax_th.set_xlabel("freeform pixels K")
    ax_th.set_ylabel(f"panel lux for {result.config.fps:g} fps")
    ax_th.set_title("illuminance needed")
    ax_th.set_ylim(bottom=0)
    ax_th.legend(fontsize=8)
    fig.tight_layout()
    return fig
