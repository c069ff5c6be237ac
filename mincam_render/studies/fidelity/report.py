"""The fidelity benchmark's report: statements, Pareto plots and tables, fidelity.json and .html."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from mincam_render.studies.fidelity.config import KNOBS, NEGLIGIBLE_EFFECT, REFERENCE_DEPTH

if TYPE_CHECKING:
    import os

    from mincam_render.studies.fidelity.result import (
        BaseRun,
        FamilyFidelity,
        FidelityBenchResult,
        FidelityRow,
        ReferenceRun,
    )

_EFFECTS = {
    ("max_depth", 2): "indirect light (direct light only, depth 2)",
    ("max_depth", 3): "light after more than one bounce (depth 3)",
    ("render", "shared"): "parallax between detectors (one shared render)",
    ("detector", "point"): "the diode's area (point detector: no detector blur)",
    ("storage", "float16"): "float32 storage (float16 instead)",
    ("paper", "centre pinhole"): "what the paper's training camera approximates "
    "(centre pinhole image)",
    ("auto", None): "the automatic fidelity choice",
}


def fidelity_statements(
    family: str, rows: Sequence[FidelityRow], base: BaseRun, reference: ReferenceRun
) -> list[str]:
    """One sentence per effect: can it be left out, and at what error (plain text)."""
    out = []
    floor, base_error, base_s = reference.reference_noise, base.error, base.seconds
    for r in rows:
        what = _EFFECTS.get((r.knob, None if r.knob == "auto" else r.level))
        if r.knob == "mask_res":
            what = f"mask detail finer than {r.level}x{r.level} texels"
        if what is None:
            continue
        what = what[0].upper() + what[1:]
        # float16 re-encodes the base's own samples, so its difference is not noise
        resolved = base_error < NEGLIGIBLE_EFFECT or r.knob == "storage"
        if r.knob == "auto":
            decision = (
                "within the bound"
                if r.effect < NEGLIGIBLE_EFFECT
                else "adds more than the bound against the full-depth reference"
            )
        elif r.effect >= NEGLIGIBLE_EFFECT:
            decision = "can NOT be left out"
        elif resolved:
            decision = "CAN be left out"
        else:
            decision = (
                "UNRESOLVED (its effect is below the base's own Monte Carlo error; "
                "rerun with a higher --base-spp)"
            )
        speed = f", {r.seconds / base_s:.2g}x the base render time" if base_s and r.seconds else ""
        out.append(
            f"{family}: {what}: {decision}; estimated effect {r.effect:.2%} "
            f"(total error {r.error:.2%} vs base {base_error:.2%}, reference noise "
            f"{floor:.2%}, bound {NEGLIGIBLE_EFFECT:.0%}){speed}."
        )
    return out


def pareto_front(rows: Sequence[FidelityRow]) -> list[FidelityRow]:
    """Rows not dominated in (seconds, error): nothing else is both faster and more accurate."""
    front: list[FidelityRow] = []
    for r in sorted(rows, key=lambda r: (r.seconds, r.error)):
        if not front or r.error < front[-1].error:
            front.append(r)
    return front


def plot_pareto(result: FamilyFidelity, path: str | os.PathLike) -> Path:
    """Save the error-vs-seconds plot (log axes) of one family; returns the path."""
    from mincam_render.analysis.plots import plt

    rows = result.rows
    fig, ax = plt.subplots(figsize=(7.5, 5.2), constrained_layout=True)
    markers = dict(zip(KNOBS, "o s D ^ v P X *".split(), strict=True))
    cmap = plt.get_cmap("tab10")
    for i, knob in enumerate(KNOBS):
        sel = [r for r in rows if r.knob == knob]
        if not sel:
            continue
        auto = knob == "auto"
        ax.scatter(
            [r.seconds for r in sel],
            [max(r.error, 1e-7) for r in sel],
            marker=markers[knob],
            s=240 if auto else 50,
            color="gold" if auto else cmap(i),
            edgecolor="black" if auto else "none",
            zorder=4 if auto else 3,
            label="auto-fidelity choice" if auto else knob,
        )
        for r in sel:
            ax.annotate(
                "auto" if auto else str(r.level),
                (r.seconds, max(r.error, 1e-7)),
                textcoords="offset points",
                xytext=(4, 3),
                fontsize=7,
            )
    front = pareto_front(rows)
    ax.plot(
        [r.seconds for r in front],
        [max(r.error, 1e-7) for r in front],
        color="grey",
        lw=1,
        ls="--",
        zorder=2,
        label="Pareto front",
    )
    noise = result.reference.reference_noise
    ax.axhline(noise, color="black", lw=0.8, ls=":", label="reference noise")
    ax.axhline(NEGLIGIBLE_EFFECT, color="red", lw=0.8, ls="-.", label="1 % error")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("render time per frame (s)")
    ax.set_ylabel("relative measurement error vs reference (RMS)")
    ax.set_title(f"{result.family}: measurement error against run time per fidelity knob")
    ax.legend(fontsize=7, loc="best")
    ax.grid(True, which="both", alpha=0.3)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _optional(value: float | None) -> str:
    return "" if value is None else f"{value:.3f}"


def _signal_columns(r: FidelityRow) -> tuple[str, str]:
    """The row's errors relative to the label signal (blank where not measured)."""
    signal = r.errors.signal
    if signal is None:
        return "", ""
    return f"{signal.random:.3f}", _optional(signal.finest_box)


def pareto_table(result: FamilyFidelity) -> str:
    """The rows as a plain-text table (knob, level, error, effect, vs signal, seconds)."""
    lines = [
        f"{'knob':<10} {'level':<40} {'error':>9} {'effect':>9} {'/signal':>8} "
        f"{'/texel':>8} {'s/frame':>9}"
    ]
    for r in result.rows:
        random, box = _signal_columns(r)
        lines.append(
            f"{r.knob:<10} {str(r.level):<40} {r.error:>9.3%} {r.effect:>9.3%} "
            f"{random:>8} {box:>8} {r.seconds:>9.3f}"
        )
    return "\n".join(lines)


_TABLE_HEADER = [
    "knob",
    "level",
    "error (RMS)",
    "random masks",
    "trained-like masks",
    "effect",
    "vs label signal (random masks)",
    "vs label signal (1 texel)",
    "s / frame",
]


def _table_row(r: FidelityRow) -> list[str]:
    return [
        r.knob,
        str(r.level),
        f"{r.error:.3%}",
        f"{r.errors.error_random:.3%}",
        f"{r.errors.error_trained:.3%}",
        f"{r.effect:.3%}",
        *_signal_columns(r),
        f"{r.seconds:.3f}",
    ]


def _reference_paragraph(res: FamilyFidelity) -> str:
    ref, base = res.reference, res.base
    return (
        f"Reference: {ref.spp} spp, depth {ref.max_depth}, {ref.seconds:.2f} "
        f"s/frame, its own noise {ref.reference_noise:.3%}. Base: "
        f"{base.settings.spp} spp, depth {base.settings.max_depth} (scene integrator "
        f"depth {res.scene_max_depth} is a level of max_depth), "
        f"error {base.error:.3%}."
    )


def write_report(result: FidelityBenchResult, out: str | os.PathLike) -> dict[str, Path]:
    """Write ``fidelity.json``, ``pareto_<family>.png`` and ``fidelity.html`` to ``out``.

    Returns:
        ``{"json", "html", "pareto_<family>" for each family}``: the files written.
    """
    from mincam_render.analysis.report import Report
    from mincam_render.data.dataset import atomic_write_bytes, json_bytes

    out_dir = Path(out)
    out_dir.mkdir(parents=True, exist_ok=True)
    page = Report("Fidelity: measurement error against run time")
    page.paragraph(
        "Each point changes one fidelity knob away from the base setting and compares "
        "detector measurements (P = sum T M, random printable and trained-like masks) with "
        "a converged reference: per-detector, area-sampled diode, path depth "
        f"{REFERENCE_DEPTH}. 'effect' removes the base setting's Monte Carlo error in "
        "quadrature. The gold star is the automatic fidelity choice."
    )
    paths: dict[str, Path] = {}
    for res in result.families:
        png = plot_pareto(res, out_dir / f"pareto_{res.family}.png")
        paths[f"pareto_{res.family}"] = png
        page.heading(res.family)
        page.figure_file(png, f"{res.family}: error against run time")
        page.table(_TABLE_HEADER, [_table_row(r) for r in res.rows])
        page.paragraph(_reference_paragraph(res))
        page.bullets(list(res.statements))
    paths["json"] = atomic_write_bytes(out_dir / "fidelity.json", json_bytes(result.as_json()))
    paths["html"] = page.write(out_dir / "fidelity.html")
    return paths
