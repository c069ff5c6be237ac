"""The sim2real report: ``sim2real.json`` (all numbers) and ``sim2real.html`` (tables, figures)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mincam_render.studies.sim2real.figures import figures

if TYPE_CHECKING:
    from mincam_render.analysis.report import Report

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
#: Task table: (row name, key of result["tasks"]).
_TASK_ROWS = (
    ("simulation → simulation", "sim_on_sim"),
    ("simulation → real", "sim_on_real"),
    ("simulation, head retrained on real → real", "sim_head_retrained_on_real"),
    ("real → real", "real_on_real"),
)


def write_sim2real_report(result: dict, out_dir: str | Path) -> dict[str, str]:
    """Write ``sim2real.json`` (all numbers) and ``sim2real.html`` to ``out_dir``."""
    from mincam_render.analysis.report import Report
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    title = "Simulation against reality" + (" — SURROGATE data" if result["surrogate"] else "")
    page = Report(title, banner=result["banner"])
    _verdict_section(page, result)
    _pixel_section(page, result)
    for fig, caption in figures(result):
        page.figure(fig, caption)
    _task_section(page, result)
    if result.get("injected"):
        page.heading("Injected perturbations (SURROGATE)")
        page.preformatted(json.dumps(result["injected"], indent=1)[:6000])
    json_path = atomic_write_bytes(out / "sim2real.json", json_bytes(result))
    html_path = page.write(out / "sim2real.html")
    return {"json": str(json_path), "html": str(html_path)}


def _verdict_section(page: Report, result: dict[str, Any]) -> None:
    page.heading("Verdict")
    page.paragraph(result["verdict"]["summary"])
    page.paragraph(
        "Thresholds: "
        + ", ".join(f"{k} = {v:g}" for k, v in result["thresholds"].items())
        + ". A pixel 'agrees' when correlation >= min_correlation, |gain - 1| <= max_gain_error "
        "and |offset| <= max_offset_fraction x its mean simulated voltage; it 'agrees after "
        "calibration' when the correlation holds and the KS statistic after the fit is <= "
        "max_ks_calibrated; otherwise it 'disagrees'."
    )


def _pixel_section(page: Report, result: dict[str, Any]) -> None:
    """The per-pixel table (with the injected values of SURROGATE data, explained)."""
    has_inj = "expected_gain" in result["pixels"][0]
    cols = list(_PIXEL_COLUMNS)
    if has_inj:
        cols[1:1] = ["injected gain"]
        cols[3:3] = ["gain − injected (se)"]
        cols[6:6] = ["injected offset (mV)", "expected offset (mV)", "offset − expected (se)"]
    rows = [_pixel_row(p, has_inj) for p in result["pixels"]]
    classes = [
        [None] * (len(row) - 1) + [_verdict_class(p["verdict"])]
        for row, p in zip(rows, result["pixels"], strict=True)
    ]
    page.heading("Per pixel")
    page.table(cols, rows, cell_classes=classes)
    if has_inj:
        page.paragraph(
            "Expected offset = injected offset + the stray light and dark current a fit sees "
            "as offset; expected gain = injected gain. Differences in standard errors (se):"
        )
        for p in result["pixels"]:
            page.paragraph(p["explanation"])


def _pixel_row(p: dict, has_inj: bool) -> list[Any]:
    """One row of the per-pixel table (voltages in mV), columns as in ``_pixel_section``."""
    row = [
        p["pixel"],
        f"{p['gain']:.4f}",
        f"{p['gain_se']:.2g}",
        f"{p['offset_v'] * 1e3:.3f}",
        f"{p['offset_se_v'] * 1e3:.2g}",
        f"{p['correlation']:.4f}",
        f"{p['residual_std_v'] * 1e3:.3g}",
        f"{p['ks_raw']:.3f}",
        f"{p['ks_calibrated']:.3f}",
        f"{p['wasserstein_raw_v'] * 1e3:.3g}",
        p["verdict"],
    ]
    if has_inj:
        row[1:1] = [f"{p['injected_gain']:.4f}"]
        row[3:3] = [f"{p['gain_z']:+.1f}"]
        row[6:6] = [
            f"{p['injected_offset_v'] * 1e3:.3f}",
            f"{p['expected_offset_v'] * 1e3:.3f}",
            f"{p['offset_z']:+.1f}",
        ]
    return row


def _verdict_class(verdict: str) -> str:
    """The table cell's class of a pixel verdict: pass, warn or fail."""
    return "pass" if verdict == "agrees" else "warn" if "calibration" in verdict else "fail"


def _task_section(page: Report, result: dict[str, Any]) -> None:
    page.heading("Task metrics")
    if result.get("tasks"):
        tk = result["tasks"]
        page.table(
            ["trained on → tested on", tk["real_on_real"]["error_name"], "loss"],
            [
                [name, f"{tk[key]['error']:.4g}", f"{tk[key]['loss']:.4g}"]
                for name, key in _TASK_ROWS
            ],
        )
    else:
        page.paragraph("Task metrics were not computed (--no-tasks).")
    page.paragraph(
        "Video-based simulation (the paper's training-camera method): "
        + result["video_simulation_note"]
        + "."
    )
