"""The task-level check's report: a Markdown page of tables and the two Paretos side by side."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from mincam_render.studies.comparison.figures import DesignFigure, Paired
from mincam_render.studies.task_fidelity.study import (
    Acceptance,
    CrossFigures,
    LevelFigures,
    TaskFidelityResult,
)

#: ``NoiseFigures.ratio`` arguments of the frame steps' error over their label signal.
STEP_FIGURES = ("step_error_rms_w", "step_signal_rms_w")


def write_report(result: TaskFidelityResult, out: str | Path, *, stem: str) -> dict[str, Path]:
    """``<stem>.md`` (the tables) and ``<stem>.png`` (error against render time) in ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"md": out / f"{stem}.md", "png": out / f"{stem}.png"}
    paths["md"].write_text(markdown(result) + "\n")
    plot_paretos(result.levels, result.error_name, paths["png"])
    return paths


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(r) + " |" for r in rows]


def markdown(result: TaskFidelityResult) -> str:
    """Task figures per level, render error against the label signal, acceptance."""
    names = list(result.levels[0].designs)
    rows = [
        [
            lv.level,
            f"{lv.factor:g}",
            lv.difference_seeds,
            f"{lv.render_s_per_frame:.3f}",
            *(_figure_cell(f) for f in lv.designs.values()),
        ]
        for lv in result.levels
    ]
    lines = [f"# Task-level fidelity check: {result.task} ({result.error_name})", ""]
    lines += _table(["level", "samples", "seeds", "render s/frame", *names], rows) + [""]
    paired = [lv for lv in result.levels if lv.between]
    if paired:
        lines += ["Between designs at each level, trained and tested there (paired):", ""]
        lines += [f"- {lv.level}: {_pairs(lv.between)}" for lv in paired]
        lines.append("")
    lines += ["## Render error against the label signal (test episodes)", ""]
    lines += _table(
        [
            "level",
            "reference",
            "error/signal: random masks / 4x4 box / 1 texel",
            "noise/signal (mean over frames out): the same three",
            "frame steps' error/signal: the same three",
            "autocorrelation (random masks): lag 1 frame / 1 window",
        ],
        [_noise_row(lv) for lv in result.levels if lv.noise is not None],
    )
    lines += ["", "## Against the reference (moved, its share of the 95 % half-width)", ""]
    lines += [
        "Paired: level - reference on the same test episodes, training seeds resampled. "
        "Replicate: the same renders, other training seeds (how far seeds alone move it).",
        "",
    ]
    for level, checks in result.acceptance.items():
        v = result.verdict(level)
        said = ", ".join(k.replace("_", " ") for k, held in v.items() if held) or "none"
        lines.append(f"- **{level}** ({said}):")
        lines += [f"  - {_acceptance_cell(a)}" for a in checks]
    lines += ["", f"Chosen (cheapest supported level with the plan's seeds): {result.chosen}."]
    if result.cross:
        lines += ["", *_cross_lines(result.cross, names)]
    return "\n".join(lines)


def _cross_lines(cross: Sequence[CrossFigures], names: Sequence[str]) -> list[str]:
    """Runs tested on another level's test episodes: figures, test and training noise moves."""
    lines = [
        "## Trained at one level, tested at another (same scene seeds)",
        "",
        "Test noise: the same runs on these test renders less on their own level's "
        "(paired by episode). Training noise: these runs less those trained at the "
        "tested level, on the same test episodes.",
        "",
    ]
    rows = []
    for c in cross:
        pair = f"{c.trained} on {c.tested}"
        rows.append([pair, "figure", *(_figure_cell(c.designs[n]) for n in names)])
        moves = {"test noise": c.test_noise, "training noise": c.train_noise}
        for kind, paired in moves.items():
            if paired is not None:  # no training noise against a test level
                rows.append([pair, kind, *(_paired_cell(paired[n]) for n in names)])
    lines += _table(["trained on tested", "", *names], rows)
    lines += ["", "Between designs on those test episodes (paired):", ""]
    return lines + [f"- {c.trained} on {c.tested}: {_pairs(c.between)}" for c in cross]


def _figure_cell(f: DesignFigure) -> str:
    return f"{f.error:.3f} [{f.ci95[0]:.3f}, {f.ci95[1]:.3f}]"


def _paired_cell(p: Paired) -> str:
    return f"{p.mean:+.3f} [{p.ci95[0]:+.3f}, {p.ci95[1]:+.3f}]"


def _pairs(between: Mapping[str, Paired]) -> str:
    """Every pair of designs on one line: ``a - b +0.010 [...]; a - c ...``."""
    return "; ".join(f"{key} {_paired_cell(p)}" for key, p in between.items())


def _acceptance_cell(a: Acceptance) -> str:
    share = abs(a.moved) / a.half_width if a.half_width > 0 else float("inf")
    rep = "" if a.replicate_moved is None else f"; replicate {a.replicate_moved:+.3f}"
    lo, hi = a.paired.ci95
    return (
        f"{a.design}: {a.moved:+.3f} ({share:.2f} of {a.half_width:.3f}), "
        f"paired {a.paired.mean:+.3f} [{lo:+.3f}, {hi:+.3f}]{rep}"
    )


def _noise_row(lv: LevelFigures) -> list[str]:
    assert lv.noise is not None  # rows are made for measured levels only
    err, noise = lv.noise.ratio(), lv.noise.ratio("noise_rms_w")
    steps = lv.noise.ratio(*STEP_FIGURES)
    acf = lv.noise.autocorrelation["random_masks"]
    kinds = ("random_masks", "box_4", "box_1")
    return [
        lv.level,
        lv.noise.reference,
        " / ".join(f"{err[k]:.3f}" for k in kinds),
        " / ".join(f"{noise[k]:.3f}" for k in kinds),
        " / ".join(f"{steps[k]:.3f}" for k in kinds),
        f"{acf['lag_1_frame']:.2f} / {_lag(acf['lag_1_window'])}",
    ]


def plot_paretos(levels: Sequence[LevelFigures], error_name: str, path: Path) -> Path:
    """Measurement error (left) and task error (right) against render seconds per frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    measured = [lv for lv in levels if lv.noise is not None]
    for kind, label in (
        ("random_masks", "random masks"),
        ("box_4", "4x4 box"),
        ("box_1", "1 texel"),
    ):
        x = [lv.render_s_per_frame for lv in measured]
        y = [lv.noise.ratio()[kind] for lv in measured if lv.noise is not None]
        steps = [lv.noise.ratio(*STEP_FIGURES)[kind] for lv in measured if lv.noise is not None]
        (dots,) = left.plot(x, y, marker="o", ls="", label=label)
        left.plot(x, steps, marker="x", ls="", color=dots.get_color(), label=f"{label}, steps")
        for lv, xi, yi in zip(measured, x, y, strict=True):
            left.annotate(lv.level, (xi, yi), textcoords="offset points", xytext=(3, 3), fontsize=7)
    left.set_xscale("log")
    left.set_yscale("log")
    left.set_xlabel("render seconds per frame")
    left.set_ylabel("render error / label signal (RMS; x: frame steps)")
    left.set_title("measurement error against run time")
    for name in levels[0].designs:
        x = [lv.render_s_per_frame for lv in levels]
        err = [lv.designs[name].error for lv in levels]
        lo = [e - lv.designs[name].ci95[0] for e, lv in zip(err, levels, strict=True)]
        hi = [lv.designs[name].ci95[1] - e for e, lv in zip(err, levels, strict=True)]
        right.errorbar(x, err, yerr=[lo, hi], marker="o", ls="", capsize=3, label=name)
    for lv in levels:
        right.annotate(
            lv.level,
            (lv.render_s_per_frame, min(f.error for f in lv.designs.values())),
            textcoords="offset points",
            xytext=(3, -10),
            fontsize=7,
        )
    right.set_xscale("log")
    right.set_xlabel("render seconds per frame")
    right.set_ylabel(f"test {error_name} (mean over seeds, 95 % CI)")
    right.set_title("task error against run time")
    for ax in (left, right):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _lag(rho: float | None) -> str:
    """An autocorrelation as the table shows it; None: not measured (episodes of one window)."""
    return "n/a (episodes of one window)" if rho is None else f"{rho:.2f}"
