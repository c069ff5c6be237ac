"""Figures of a sim2real result (matplotlib): fits, time series, residuals, calibration, tasks.

Each function takes the result of
:func:`~mincam_render.studies.sim2real.study.run` and returns
``(figure, caption)``; voltages are plotted in millivolts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.studies.sim2real.fit import THRESHOLDS

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from mincam_render.studies.sim2real.result import (
        PixelComparison,
        Sim2RealResult,
        TaskMetrics,
    )


def figures(result: Sim2RealResult) -> list[tuple[Figure, str]]:
    """``[(figure, caption)]`` of the report, in page order (the task figure if tasks ran)."""
    figs = [
        _fit_scatter(result),
        _time_series(result),
        _residuals(result),
        _calibration(result),
    ]
    if result.tasks is not None:
        figs.append(_task_errors(result, result.tasks))
    return figs


def _series(result: Sim2RealResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(sim V[N, P], real V[N, P], time_s[N])`` of the result (V, s)."""
    series = result.series
    return np.asarray(series.sim_v), np.asarray(series.real_v), np.asarray(series.time_s)


def _tag(result: Sim2RealResult) -> str:
    return " [SURROGATE]" if result.surrogate else ""


def _pixel_panels(
    result: Sim2RealResult, height_in: float, draw: Callable[[Axes, int], None]
) -> Figure:
    """A figure of one 3.2 x ``height_in`` inch panel per pixel, up to 4 per row.

    ``draw(ax, j)`` fills pixel ``j``'s panel; spare panels of the last row are hidden.
    """
    from mincam_render.analysis.plots import plt

    p = len(result.pixels)
    cols = min(4, p)
    rows = math.ceil(p / cols)
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.2 * cols, height_in * rows), squeeze=False, constrained_layout=True
    )
    for j, ax in enumerate(axes.flat):
        if j >= p:
            ax.axis("off")
            continue
        draw(ax, j)
    return fig


def _fit_scatter(result: Sim2RealResult) -> tuple[Figure, str]:
    sim, real, _ = _series(result)
    pix = result.pixels

    def draw(ax: Axes, j: int) -> None:
        s, r = sim[:, j] * 1e3, real[:, j] * 1e3
        ax.scatter(s, r, s=4, alpha=0.5, label="samples")
        xs = np.linspace(s.min(), s.max(), 2)
        ax.plot(
            xs,
            pix[j].fit.gain * xs + pix[j].fit.offset_v * 1e3,
            "r-",
            lw=1,
            label=f"fit g={pix[j].fit.gain:.3f}",
        )
        ax.plot(xs, xs, "k:", lw=1, label="real = sim")
        ax.set_title(f"pixel {j}: r={pix[j].fit.correlation:.3f}", fontsize=9)
        ax.set_xlabel("simulated (mV)")
        ax.set_ylabel("measured (mV)")
        ax.legend(fontsize=6)

    fig = _pixel_panels(result, 3.0, draw)
    fig.suptitle("Simulated vs measured voltage per pixel" + _tag(result))
    return (
        fig,
        "Per pixel: measured against simulated voltage, least-squares fit "
        "(red) and identity (dotted).",
    )


def _time_series(result: Sim2RealResult) -> tuple[Figure, str]:
    from mincam_render.analysis.plots import plt

    sim, real, t = _series(result)
    pix = result.pixels
    p = len(pix)
    fig, axes = plt.subplots(
        p, 1, figsize=(10, 1.5 * p + 0.8), squeeze=False, sharex=True, constrained_layout=True
    )
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(t, real[:, j] * 1e3, lw=0.8, label="measured")
        ax.plot(t, sim[:, j] * 1e3, lw=0.8, label="simulated")
        ax.plot(
            t,
            (pix[j].fit.gain * sim[:, j] + pix[j].fit.offset_v) * 1e3,
            lw=0.8,
            ls="--",
            label="simulated, calibrated",
        )
        ax.set_ylabel(f"px {j} (mV)", fontsize=8)
        if j == 0:
            ax.legend(fontsize=7, ncol=3, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle("Time series: measured and simulated voltage" + _tag(result))
    return fig, "Time series overlay per pixel (raw simulation and after the gain/offset fit)."


def _residuals(result: Sim2RealResult) -> tuple[Figure, str]:
    sim, real, _ = _series(result)
    pix = result.pixels

    def draw(ax: Axes, j: int) -> None:
        resid = (real[:, j] - (pix[j].fit.gain * sim[:, j] + pix[j].fit.offset_v)) * 1e3
        ax.hist(resid, bins=30, color="tab:purple", label="residuals")
        ax.set_title(f"pixel {j}: std {pix[j].fit.residual_std_v * 1e3:.3g} mV", fontsize=9)
        ax.set_xlabel("measured - calibrated sim (mV)")
        ax.set_ylabel("samples")
        ax.legend(fontsize=6)

    fig = _pixel_panels(result, 2.6, draw)
    fig.suptitle("Residual distribution after the per-pixel fit" + _tag(result))
    return fig, "Residuals after the gain/offset fit."


def _calibration(result: Sim2RealResult) -> tuple[Figure, str]:
    from mincam_render.analysis.plots import plt

    pix = result.pixels
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(13, 3.6), constrained_layout=True)
    x = np.arange(len(pix))
    _fitted_gains(a1, x, pix)
    _fitted_offsets(a2, x, pix)
    a3.bar(x - 0.2, [q.ks_raw for q in pix], 0.4, label="raw")
    a3.bar(x + 0.2, [q.ks_calibrated for q in pix], 0.4, label="after fit")
    a3.axhline(THRESHOLDS.max_ks_calibrated, color="r", lw=0.8, ls="--", label="threshold")
    a3.set_xlabel("pixel")
    a3.set_ylabel("KS statistic (0-1)")
    a3.set_title("Distribution gap sim vs real")
    a3.legend(fontsize=7)
    fig.suptitle("Calibration and distribution gap" + _tag(result))
    return (
        fig,
        "Fitted gains and offsets (with the values a fit should find for SURROGATE "
        "data) and the per-pixel KS statistic.",
    )


def _fitted_gains(ax: Axes, x: np.ndarray, pix: Sequence[PixelComparison]) -> None:
    """Fitted gain per pixel with ±2 se, and the expected one of SURROGATE data."""
    g = np.array([q.fit.gain for q in pix])
    ax.errorbar(
        x, g, yerr=2 * np.array([q.fit.gain_se for q in pix]), fmt="o", label="fitted ±2 se"
    )
    injected = [q.injected for q in pix if q.injected is not None]
    if injected:
        ax.plot(x, [q.expected_gain for q in injected], "rx", label="expected (injected)")
    ax.axhline(1.0, color="k", lw=0.6)
    ax.set_xlabel("pixel")
    ax.set_ylabel("gain (measured / simulated)")
    ax.set_title("Fitted gain")
    ax.legend(fontsize=7)


def _fitted_offsets(ax: Axes, x: np.ndarray, pix: Sequence[PixelComparison]) -> None:
    """Fitted offset per pixel (mV) with ±2 se, and the expected one of SURROGATE data."""
    o = np.array([q.fit.offset_v for q in pix]) * 1e3
    ax.errorbar(
        x, o, yerr=2e3 * np.array([q.fit.offset_se_v for q in pix]), fmt="o", label="fitted ±2 se"
    )
    injected = [q.injected for q in pix if q.injected is not None]
    if injected:
        ax.plot(
            x,
            [q.expected_offset_v * 1e3 for q in injected],
            "rx",
            label="expected (injected offset + stray light + dark current)",
        )
    ax.set_xlabel("pixel")
    ax.set_ylabel("offset (mV)")
    ax.set_title("Fitted offset")
    ax.legend(fontsize=7)


def _task_errors(result: Sim2RealResult, tk: TaskMetrics) -> tuple[Figure, str]:
    from mincam_render.analysis.plots import plt

    evaluations = [tk.sim_on_sim, tk.sim_on_real, tk.sim_head_retrained_on_real, tk.real_on_real]
    fig, ax = plt.subplots(figsize=(7.5, 3.6), constrained_layout=True)
    vals = [e.error for e in evaluations]
    ax.bar(
        range(len(evaluations)),
        vals,
        color=["grey", "tab:red", "tab:orange", "tab:green"],
        label=tk.real_on_real.error_name,
    )
    ax.set_xticks(
        range(len(evaluations)),
        ["sim → sim", "sim → real", "sim head\nretrained → real", "real → real"],
    )
    unit = ""
    first = tk.real_on_real.labels
    if first:
        unit = next(iter(first.values())).unit
    ax.set_ylabel(f"{tk.real_on_real.error_name} {('(' + unit + ')') if unit else ''}")
    ax.set_title("Task error on the test segment (train → test)" + _tag(result))
    ax.legend(fontsize=7)
    return fig, "Task metrics: trained on simulation / real, tested on real."
