"""The sim2real report: ``sim2real.json`` (all numbers) and ``sim2real.html`` (tables, figures)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mincam_render.studies.sim2real.figures import figures
from mincam_render.studies.sim2real.result import PixelVerdict

if TYPE_CHECKING:
    from mincam_render.analysis.report import Report
    from mincam_render.learn.evaluation import Evaluation
    from mincam_render.studies.sim2real.result import PixelComparison, Sim2RealResult, TaskMetrics

#: Per-pixel table: the columns of every recording.
_PIXEL_COLUMNS = [
    "pixel",
    "gain",
    "± se",
    "offset (mV)",
    "± se (mV)",
    "correlation",
    "residual std (mV)",
    "KS raw",
    "KS calibrated",
    "W1 raw (mV)",
    "verdict",
]
#: Task table: the row names, in the order of :func:`_task_rows`.
_TASK_ROWS = (
    "simulation → simulation",
    "simulation → real",
    "simulation, head retrained on real → real",
    "real → real",
)


def write_report(result: Sim2RealResult, out_dir: str | Path) -> dict[str, str]:
    """Write ``sim2real.json`` (all numbers) and ``sim2real.html`` to ``out_dir`` (created).

    ``sim2real.json`` is :meth:`Sim2RealResult.as_json`; :meth:`Sim2RealResult.from_json`
    reads it back.

    Returns:
        ``{"json": path, "html": path}``.
    """
    from mincam_render.analysis.report import Report
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    title = "Simulation against reality" + (" — SURROGATE data" if result.surrogate else "")
    page = Report(title, banner=result.banner)
    _verdict_section(page, result)
    _pixel_section(page, result)
    for fig, caption in figures(result):
        page.figure(fig, caption)
    _task_section(page, result)
    if result.injected:
        page.heading("Injected perturbations (SURROGATE)")
        page.preformatted(json.dumps(result.injected, indent=1)[:6000])
    json_path = atomic_write_bytes(out / "sim2real.json", json_bytes(result.as_json()))
    html_path = page.write(out / "sim2real.html")
    return {"json": str(json_path), "html": str(html_path)}


def _verdict_section(page: Report, result: Sim2RealResult) -> None:
    page.heading("Verdict")
    page.paragraph(result.verdict.summary)
    page.paragraph(
        "Thresholds: "
        + ", ".join(f"{k} = {v:g}" for k, v in result.thresholds.as_json().items())
        + ". A pixel 'agrees' when correlation >= min_correlation, |gain - 1| <= max_gain_error "
        "and |offset| <= max_offset_fraction x its mean simulated voltage; it 'agrees after "
        "calibration' when the correlation holds and the KS statistic after the fit is <= "
        "max_ks_calibrated; otherwise it 'disagrees'."
    )


def _pixel_section(page: Report, result: Sim2RealResult) -> None:
    """The per-pixel table (with the injected values of SURROGATE data, explained)."""
    has_inj = result.pixels[0].injected is not None
    cols = list(_PIXEL_COLUMNS)
    if has_inj:
        cols[1:1] = ["injected gain"]
        cols[3:3] = ["gain − injected (se)"]
        cols[6:6] = ["injected offset (mV)", "expected offset (mV)", "offset − expected (se)"]
    rows = [_pixel_row(p) for p in result.pixels]
    classes = [
        [None] * (len(row) - 1) + [_verdict_class(p.verdict)]
        for row, p in zip(rows, result.pixels, strict=True)
    ]
    page.heading("Per pixel")
    page.table(cols, rows, cell_classes=classes)
    if has_inj:
        page.paragraph(
            "Expected offset = injected offset + the stray light and dark current a fit sees "
            "as offset; expected gain = injected gain. Differences in standard errors (se):"
        )
        for p in result.pixels:
            if p.injected is not None:
                page.paragraph(p.injected.explanation)


def _pixel_row(p: PixelComparison) -> list[Any]:
    """One row of the per-pixel table (voltages in mV), columns as in ``_pixel_section``."""
    fit = p.fit
    row: list[Any] = [
        p.pixel,
        f"{fit.gain:.4f}",
        f"{fit.gain_se:.2g}",
        f"{fit.offset_v * 1e3:.3f}",
        f"{fit.offset_se_v * 1e3:.2g}",
        f"{fit.correlation:.4f}",
        f"{fit.residual_std_v * 1e3:.3g}",
        f"{p.ks_raw:.3f}",
        f"{p.ks_calibrated:.3f}",
        f"{p.wasserstein_raw_v * 1e3:.3g}",
        p.verdict.value,
    ]
    inj = p.injected
    if inj is not None:
        row[1:1] = [f"{inj.injected_gain:.4f}"]
        row[3:3] = [f"{inj.gain_z:+.1f}"]
        row[6:6] = [
            f"{inj.injected_offset_v * 1e3:.3f}",
            f"{inj.expected_offset_v * 1e3:.3f}",
            f"{inj.offset_z:+.1f}",
        ]
    return row


def _verdict_class(verdict: PixelVerdict) -> str:
    """The table cell's class of a pixel verdict: pass, warn or fail."""
    return {
        PixelVerdict.AGREES: "pass",
        PixelVerdict.AGREES_CALIBRATED: "warn",
        PixelVerdict.DISAGREES: "fail",
    }[verdict]


def _task_rows(tk: TaskMetrics) -> tuple[Evaluation, ...]:
    """The evaluations in the order of ``_TASK_ROWS``."""
    return (tk.sim_on_sim, tk.sim_on_real, tk.sim_head_retrained_on_real, tk.real_on_real)


def _task_section(page: Report, result: Sim2RealResult) -> None:
    page.heading("Task metrics")
    if result.tasks is not None:
        tk = result.tasks
        page.table(
            ["trained on → tested on", tk.real_on_real.error_name, "loss"],
            [
                [name, f"{e.error:.4g}", f"{e.loss:.4g}"]
                for name, e in zip(_TASK_ROWS, _task_rows(tk), strict=True)
            ],
        )
    else:
        page.paragraph("Task metrics were not computed (--no-tasks).")
    page.paragraph(
        "Video-based simulation (the paper's training-camera method): "
        + result.video_simulation_note
        + "."
    )
