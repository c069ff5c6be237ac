"""The robustness report: designs' error under each perturbation, tolerances, fabrication specs.

:func:`write_report` takes the :class:`~.result.DesignCurves` of
:mod:`mincam_render.studies.robustness.study` (one per run, or pooled over training
seeds) and writes ``robustness.json``, ``robustness.png`` (error increase
against magnitude, one panel per term and one for the mix) and
``robustness.html`` (the figure, tables of the increase at the default ranges
and of tolerances, and each design's fabrication spec).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

from mincam_render.analysis.report import Report, figure_png
from mincam_render.core import strict_json
from mincam_render.studies.robustness.config import CURVES, MIX
from mincam_render.studies.robustness.result import Curve, DesignCurves

#: Panel titles of the curves.
TITLES = {
    "mask_shift": "mask shift",
    "mask_rotation": "mask rotation",
    "tone": "print tone (gamma, dot gain)",
    "printable_range": "printable range",
    "mask_blur": "mask blur",
    "gain_mismatch": "detector gain mismatch",
    "dark_offset": "dark offset",
    "pose_orientation": "camera orientation (mount)",
    "pose_position": "camera position",
    MIX: "all at once (mix)",
}


def _default_text(curve: Curve) -> str:
    units = {"mm": " mm", "deg": " deg", "percent": " %", "_v": " V", "_cm": " cm", "_m": " m"}
    parts = []
    for name, value in curve.default.items():
        unit = next((u for k, u in units.items() if name.endswith(k)), "")
        parts.append(f"{name} {value:g}{unit}")
    return ", ".join(parts)


def robustness_figure(designs: Sequence[DesignCurves]) -> bytes:
    """PNG: mean error increase (%) with its 95 % interval against the magnitude, per curve."""
    from mincam_render.analysis.plots import plt

    cols = math.ceil(len(CURVES) / 2)
    fig, axes = plt.subplots(2, cols, figsize=(3.75 * cols, 7), sharex=True)
    allowed = 100 * designs[0].config.allowed_increase
    for ax, curve in zip(axes.ravel(), CURVES, strict=True):
        for d in designs:
            lv = d.curves[curve].levels
            x = [v.level for v in lv]
            y = [100 * v.mean_increase for v in lv]
            lo = [100 * v.ci95_increase[0] for v in lv]
            hi = [100 * v.ci95_increase[1] for v in lv]
            style = "-" if d.robust else "--"
            (line,) = ax.plot(x, y, style, marker="o", ms=3, label=d.name)
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
        ax.axhline(allowed, color="k", lw=0.8, ls=":")
        ax.set_title(TITLES[curve], fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("magnitude (x default range)")
    for ax in axes[:, 0]:
        ax.set_ylabel("error increase (%)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"Task error increase under perturbation (dotted: +{allowed:g} %)")
    fig.tight_layout()
    return figure_png(fig)


def _tables(page: Report, designs: Sequence[DesignCurves]) -> None:
    """Increase at the default ranges, and tolerances, one row per design."""
    levels = list(designs[0].config.levels)
    level_one = levels.index(1.0) if 1.0 in levels else None
    head = ["design", "training", "runs", "nominal error"] + [TITLES[c] for c in CURVES]
    if level_one is not None:
        rows = []
        for d in designs:
            cells = []
            for c in CURVES:
                v = d.curves[c].levels[level_one]
                lo, hi = (100 * x for x in v.ci95_increase)
                cells.append(f"{100 * v.mean_increase:+.1f} % [{lo:+.1f}, {hi:+.1f}]")
            rows.append(_lead(d) + cells)
        page.table(head, rows, caption="Error increase at the default ranges (95 % interval)")
        if all(d.curves[MIX].levels[level_one].mean_error is not None for d in designs):
            rows = [_lead(d) + _errors_at(d, level_one) for d in designs]
            page.table(head, rows, caption="Error at the default ranges (95 % interval)")
    rows = []
    for d in designs:
        cells = []
        for c in CURVES:
            tol = d.curves[c].tolerance
            cells.append(f"{'>= ' if not tol.bounded else ''}{tol.factor:.2g}x")
        rows.append(_lead(d) + cells)
    allowed = 100 * designs[0].config.allowed_increase
    page.table(head, rows, caption=f"Tolerance: magnitude (x default) within +{allowed:g} % error")


def _errors_at(d: DesignCurves, level: int) -> list[str]:
    """The error itself under each curve at level index ``level``, with its interval."""
    cells = []
    for c in CURVES:
        v = d.curves[c].levels[level]
        lo, hi = v.ci95_error or (float("nan"), float("nan"))
        cells.append(f"{v.mean_error:.4g} [{lo:.4g}, {hi:.4g}]")
    return cells


def _lead(d: DesignCurves) -> list[object]:
    kind = "robust" if d.robust else "nominal"
    return [d.name, kind, d.runs, f"{d.nominal_error:.4g}"]


def write_report(
    designs: Sequence[DesignCurves],
    out_dir: str | os.PathLike,
    *,
    notes: Sequence[str] = (),
) -> dict[str, Path]:
    """Write ``robustness.json``, ``robustness.png`` and ``robustness.html`` into ``out_dir``.

    Args:
        designs: designs' curves (:func:`~mincam_render.studies.robustness.study.robustness_curves`
            or :func:`~mincam_render.studies.robustness.study.pool_curves`), same configuration.
        out_dir: created if needed.
        notes: sentences shown under the title (data sizes, provenance).

    Returns:
        ``{"json": path, "png": path, "html": path}``.

    """
    from mincam_render.data.dataset import atomic_write_bytes

    if not designs:
        raise ValueError("no designs to report")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "robustness.json", "png": out / "robustness.png"}
    records = [d.as_json() for d in designs]
    atomic_write_bytes(paths["json"], (strict_json.dumps(records, indent=1) + "\n").encode())
    png = robustness_figure(designs)
    atomic_write_bytes(paths["png"], png)
    page = Report("Designs that survive the workshop: robustness to tolerances")
    cfg = designs[0].config
    page.paragraph(
        f"Each perturbation alone, and all at once, at {', '.join(f'{v:g}' for v in cfg.levels)}"
        f" x its default range; {cfg.draws} built cameras drawn per level (the same draws "
        "for every design), task error pooled over the test episodes; intervals resample "
        "runs and draws. Camera pose error is approximated in the mask plane "
        "(mincam_render.optics.pose: exact for orientation, for position at the "
        "model's pose depth; measured against re-renders by bench_pose_error.py)."
    )
    for note in notes:
        page.paragraph(note)
    page.heading("Default ranges")
    page.bullets([f"{TITLES[c]}: {_default_text(designs[0].curves[c])}" for c in CURVES[:-1]])
    page.figure_png(
        png,
        "Mean error increase against magnitude, 95 % bootstrap intervals; "
        "solid: robust-trained, dashed: nominal.",
    )
    _tables(page, designs)
    page.heading("Fabrication specs (each term alone keeps the error within the limit)")
    for d in designs:
        page.heading(d.name, level=3)
        page.bullets([d.curves[c].spec for c in CURVES])
    paths["html"] = page.write(out / "robustness.html")
    return paths
