"""The energy report: ``energy.json`` (numbers), ``energy.html`` (tables, figures) and a PNG."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from mincam_render.studies.energy.figures import figures, summary_figure

if TYPE_CHECKING:
    from mincam_render.analysis.report import Report
    from mincam_render.studies.energy.config import EnergyConfig
    from mincam_render.studies.energy.result import EnergyResult

#: Pixel counts shown in the per-family table (the rest are in the JSON).
_TABLE_PIXELS = (1, 2, 4, 8, 16, 24)


def write_report(result: EnergyResult, out_dir: str | Path) -> dict[str, str]:
    """Write ``energy.json``, ``energy.html`` and ``energy.png`` to ``out_dir`` (created).

    ``energy.json`` is :meth:`EnergyResult.as_json`; :meth:`EnergyResult.from_json` reads it back.

    Returns:
        ``{"json": path, "html": path, "png": path}``.
    """
    from mincam_render.analysis.report import Report, figure_png
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    page = Report("Self-powered budget: can this camera run from the light it sees?")
    _headline(page, result)
    figs = figures(result)
    page.figure(*figs[0])
    _family_table(page, result)
    for fig, caption in figs[1:]:
        page.figure(fig, caption)
    _budget_table(page, result)
    _comparison_table(page, result)
    page.heading("Configuration")
    page.preformatted(_config_text(result.config))
    png = atomic_write_bytes(out / "energy.png", figure_png(summary_figure(result)))
    json_path = atomic_write_bytes(out / "energy.json", json_bytes(result.as_json()))
    html_path = page.write(out / "energy.html")
    return {"json": str(json_path), "html": str(html_path), "png": str(png)}


def headline(result: EnergyResult) -> str:
    """One line: the threshold illuminance beside the paper's, and the hours at the frame rate."""
    th, cfg = result.threshold, result.config
    hours = ", ".join(
        f"{name} {fam.hours_at_fps[cfg.max_pixels]:.1f} h" for name, fam in result.families.items()
    )
    return (
        f"{cfg.max_pixels} px at {cfg.fps:g} fps need {th.budget.threshold_lux:.0f} lx on the "
        f"panel ({th.budget.power_at_fps_w * 1e3:.2f} mW at the rail; "
        f"paper: ~{th.paper_lux:.0f} lx); "
        f"hours at {cfg.fps:g} fps over the day: {hours}"
    )


def _headline(page: Report, result: EnergyResult) -> None:
    page.heading("Answer")
    page.paragraph(headline(result))
    page.bullets(
        [
            f"{name}: panel {max(fam.lux):.0f} lx at most, render error "
            f"{100 * fam.render.max_relative_error_total:.2f} % (1 standard error of the "
            f"day's total, {fam.render.spp} samples per component, depth "
            f"{fam.render.max_depth})"
            for name, fam in result.families.items()
        ]
    )


def _family_table(page: Report, result: EnergyResult) -> None:
    fps = result.config.fps
    rows = []
    for name, fam in result.families.items():
        for k in _TABLE_PIXELS:
            if k not in fam.hours_at_fps:
                continue
            rate = fam.sustainable_fps[k]
            rows.append(
                [
                    name,
                    k,
                    f"{fam.hours_at_fps[k]:.1f}",
                    f"{max(rate):.0f}",
                    f"{fam.day_mean_sustainable_fps[k]:.1f}",
                    f"{sum(r >= fps for r in rate) * 24 / len(rate):.1f}",
                ]
            )
    page.table(
        [
            "scene",
            "pixels",
            f"hours at {fps:g} fps (storage)",
            "peak fps",
            "day-mean fps",
            f"hours light alone pays {fps:g} fps",
        ],
        rows,
        caption="Per scene and pixel count: hours of operation at the configured frame rate with "
        "the supercapacitor (cumulative: below the threshold light the camera runs down to "
        "brown-out, recharges to the restart voltage and runs again), the peak sustainable rate, "
        "the rate the day's mean harvest pays for, and the hours whose light alone pays for the "
        "configured rate.",
    )


def _budget_table(page: Report, result: EnergyResult) -> None:
    th = result.threshold.budget
    rows: list[list[Any]] = [
        [label, f"{energy_j * 1e6:.2f}"]
        for label, energy_j in (
            ("wake-up", th.wake_j),
            ("readout (MCU + ADC)", th.readout_j),
            ("inference head", th.compute_j),
            ("BLE radio", th.radio_j),
            ("per frame", th.energy_per_frame_j),
        )
    ]
    rows.append(["static power (µW)", f"{th.static_w * 1e6:.1f}"])
    rows.append([f"at {result.config.fps:g} fps (µW)", f"{th.power_at_fps_w * 1e6:.0f}"])
    page.heading(f"Frame budget, {th.pixels} pixels")
    page.table(
        ["part", "energy (µJ)"],
        rows,
        caption=f"Head: {th.head_flops} FLOPs; payload {th.payload_bytes} B in "
        f"{th.packets} packet(s); the MCU is awake {1e3 / th.max_fps:.2f} ms a frame.",
    )


def _comparison_table(page: Report, result: EnergyResult) -> None:
    rows: list[list[Any]] = []
    for name, comp in result.comparisons.items():
        m = comp.match
        labels = (
            f"minimalist {comp.mincam.budget.pixels} px",
            f"{comp.module.name} → {m.grid[0]}x{m.grid[1]}",
            "same, head outputs only sent",
        )
        for (_, b), label in zip(comp.cameras(), labels, strict=True):
            rows.append(
                [
                    name,
                    label,
                    f"{b.budget.power_at_fps_w * 1e3:.3f}",
                    f"{b.budget.threshold_lux:.0f}",
                    "" if b.hours_at_fps is None else f"{b.hours_at_fps:.1f}",
                    f"{1.0 if b.power_ratio is None else b.power_ratio:.1f}x",
                    m.source,
                ]
            )
    fps = result.config.fps
    page.heading("Against a conventional module at equal task error")
    page.table(
        [
            "task",
            "camera",
            f"power at {fps:g} fps (mW)",
            "lux needed",
            f"hours at {fps:g} fps",
            "power ratio",
            "match from",
        ],
        rows,
        caption="The module is read at its smallest mode, binned to the grid whose task error "
        "matches the minimalist design (within its 95 % interval), and runs the same head.",
    )


def _config_text(config: EnergyConfig) -> str:
    """The description as TOML-like lines: ``[section]`` then ``key = value``."""
    from mincam_render.core.config import to_dict

    lines = []
    for section, values in to_dict(config).items():
        if isinstance(values, dict):
            lines.append(f"[{section}]")
            lines += [f"{k} = {v!r}" for k, v in values.items()]
        else:
            lines.append(f"{section} = {values!r}")
    return "\n".join(lines)
