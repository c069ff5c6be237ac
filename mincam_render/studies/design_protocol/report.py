"""The design protocol's report: JSON, a Markdown page of tables, the learning-curve figure."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from mincam_render.studies.comparison.figures import DesignFigure
from mincam_render.studies.design_protocol.study import DesignProtocolResult, LadderPoint


def write_report(result: DesignProtocolResult, out: str | Path, *, stem: str) -> dict[str, Path]:
    """``<stem>.md`` (the tables) and ``<stem>.png`` (the learning curves, if run) in ``out``.

    The figures themselves are :meth:`DesignProtocolResult.as_json`.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"md": out / f"{stem}.md"}
    paths["md"].write_text(markdown(result) + "\n")
    if result.ladder:
        paths["png"] = plot_learning_curves(result.ladder, result.error_name, out / f"{stem}.png")
    return paths


#: The separator of two figures inside one markdown table cell (an escaped bar).
IN_CELL = " \\| "


def _cell(f: DesignFigure, sep: str = " | ") -> str:
    """Validation error ``sep`` test error [95 % CI] (two cells, or one with :data:`IN_CELL`)."""
    val = "" if f.val_error is None else f"{f.val_error:.3f}"
    return f"{val}{sep}{f.error:.3f} [{f.ci95[0]:.3f}, {f.ci95[1]:.3f}]"


def _interval(mean: float, ci95: tuple[float, float], sign: str = "") -> str:
    return f"{mean:{sign}.3f} [{ci95[0]:{sign}.3f}, {ci95[1]:{sign}.3f}]"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(r) + " |" for r in rows]


def markdown(result: DesignProtocolResult) -> str:
    """Every section as Markdown tables (validation and test beside each other)."""
    lines = [f"# Design protocol: {result.task} ({result.error_name})", ""]
    factor = result.config["episodes"]["fidelity"].get("samples_factor")
    if factor is not None:
        lines += [f"Every episode rendered at {factor:g}x the plan's samples.", ""]
    lines += _floor_lines(result)
    lines += _protocol_lines(result) + _recipe_lines(result) + _ladder_lines(result)
    lines += _reference_lines(result) + _oracle_lines(result) + _restart_lines(result)
    if result.selection is not None:
        s = result.selection
        lines += [
            "## Selection",
            "",
            f"Spearman rank correlation of pooled validation error with test error: "
            f"{s.runs_spearman:.2f} over {s.runs} runs, {s.designs_spearman:.2f} over "
            f"{s.designs} designs.",
            "",
        ]
    return "\n".join(lines)


def _floor_lines(result: DesignProtocolResult) -> list[str]:
    if not result.floors:
        return []
    rows = [
        [
            f"{c.floor.design} - {c.floor.baseline} < {c.floor.margin:g}",
            str(c.episodes),
            "the plan's" if c.test_factor == 1 else f"{c.test_factor:g}x samples",
            _interval(c.paired.mean, c.paired.ci95, "+"),
            c.verdict.value,
        ]
        for c in result.floors
    ]
    header = ["floor", "training episodes", "test renders", "paired difference [95 % CI]",
              "verdict"]  # fmt: skip
    return ["## Floors (paired on the same test episodes)", "", *_table(header, rows), ""]


def _protocol_lines(result: DesignProtocolResult) -> list[str]:
    if not result.protocol:
        return []
    cameras = list(result.protocol[0].figures)
    rows = [
        [f"{r.label} ({r.metric})", *(_interval(m, ci) for m, ci in r.figures.values())]
        for r in result.protocol
    ]
    title = "## Per task against joint (each label's figure, mean [95 % CI])"
    return [title, "", *_table(["label", *cameras], rows), ""]


def _recipe_lines(result: DesignProtocolResult) -> list[str]:
    if not result.recipes:
        return []
    names = list(result.recipes[0].designs)
    header = ["variant", *(f"{n}: val \\| test; paired vs base" for n in names)]
    rows = []
    for r in result.recipes:
        cells = [r.variant]
        for n in names:
            f, p = r.designs.get(n), r.versus_base.get(n)
            cells.append(
                ""
                if f is None or p is None
                else f"{_cell(f, IN_CELL)}; {_interval(p.mean, p.ci95, '+')}"
            )
        rows.append(cells)
    chosen = ", ".join(f"{d}: {v}" for d, v in result.chosen_recipe.items())
    title = "## Recipes (pooled validation error | test error [95 % CI]; paired test change)"
    return [title, "", *_table(header, rows), "", f"Chosen on validation: {chosen}.", ""]


def _ladder_lines(result: DesignProtocolResult) -> list[str]:
    if not result.ladder:
        return []
    names = list(result.ladder[0].designs)
    rows = [
        [
            str(p.episodes),
            str(p.frames),
            f"{p.render_s:.0f}",
            *(f"{_interval(f.error, f.ci95)} {f.state}" for f in p.designs.values()),
            f"{p.trivial:.3f}",
        ]
        for p in result.ladder
    ]
    for level, p in result.retested.items():  # the largest point's runs on tests rendered again
        rows.append(
            [f"{p.episodes}, tested at {level} samples", str(p.frames), "",
             *(f"{_interval(f.error, f.ci95)} {f.state}" for f in p.designs.values()),
             f"{p.trivial:.3f}"]
        )  # fmt: skip
    header = ["episodes", "frames", "render (s)", *names, "trivial"]
    lines = ["## Learning curves (test error [95 % CI], training state)", ""]
    lines += [
        *_table(header, rows),
        "",
        "What each doubling bought (paired, same test episodes):",
        "",
    ]
    for d in result.doublings:
        gain = (
            ""
            if d.pays
            else ", measurably worse"
            if d.change.ci95[0] > 0
            else ", no measurable change"
        )
        lines.append(
            f"- {d.design}, {d.episodes[0]} -> {d.episodes[1]} episodes: "
            f"{_interval(d.change.mean, d.change.ci95, '+')} ({d.relative:+.1%}){gain}"
        )
    return [*lines, ""]


def _oracle_lines(result: DesignProtocolResult) -> list[str]:
    if result.oracle is None:
        return []
    o = result.oracle
    same = {p.episodes: p for p in result.ladder}.get(o.episodes)
    rows = [
        [name, _interval(f.error, f.ci95), _interval(same.designs[name].error,
                                                     same.designs[name].ci95) if same else ""]
        for name, f in o.designs.items()
    ]  # fmt: skip
    title = f"## Oracle: the background known exactly ({o.episodes} training episodes)"
    header = ["design", "oracle test error", "camera test error (same episodes)"]
    return [title, "", *_table(header, rows), ""]


def _restart_lines(result: DesignProtocolResult) -> list[str]:
    if not result.restarts:
        return []
    rows = []
    for r in result.restarts:
        c = r.chosen
        rows.append([
            r.design,
            f"{_interval(r.plain.error, r.plain.ci95)} (spread {r.spread_plain:.3f}; "
            f"{r.train_s_per_camera[0]:.0f} s)",
            f"{_interval(c.error, c.ci95)} (spread {r.spread_chosen:.3f}; "
            f"{r.train_s_per_camera[1]:.0f} s)",
        ])  # fmt: skip
    r0 = result.restarts[0]
    title = f"## Seed spread: plain seeds against the best of {r0.restarts} restarts on validation"
    header = ["design", "plain seeds (std over seeds; training per camera)", "chosen on validation"]
    return [title, "", *_table(header, rows), ""]


def _reference_lines(result: DesignProtocolResult) -> list[str]:
    if not result.references:
        return []
    lines = ["## End-to-end masks against references (validation | test [95 % CI])", ""]
    for ref in result.references:
        rows = []
        for name, f in ref.designs.items():
            p = ref.versus_end_to_end.get(name)
            rows.append([name, _cell(f), p.statement if p else ""])
        lines += [
            f"### {ref.pixels} px ({ref.recipe} recipe)",
            "",
            *_table(["design", "val", "test", "paired"], rows),
            "",
        ]
    return lines


def plot_learning_curves(points: Sequence[LadderPoint], error_name: str, path: Path) -> Path:
    """Error against training episodes and against render + training seconds, per design."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for name in points[0].designs:
        err = [p.designs[name].error for p in points]
        lo = [p.designs[name].ci95[0] for p in points]
        hi = [p.designs[name].ci95[1] for p in points]
        n = [p.episodes for p in points]
        cost = [p.render_s + p.designs[name].train_s_per_run for p in points]
        for ax, x in zip(axes, (n, cost), strict=True):
            line = ax.plot(x, err, marker="o", label=name)[0]
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.12)
    for ax in axes:
        ax.axhline(points[0].trivial, color="grey", ls="--", lw=1, label="trivial (1 episode)")
        ax.set_xscale("log", base=2)
        ax.set_ylabel(f"test {error_name}")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0].set_xlabel(
        f"training episodes ({points[0].frames // points[0].episodes:,} frames each)"
    )
    axes[1].set_xlabel("render + training wall time of one run (s)")
    axes[0].legend(fontsize=8)
    fig.suptitle("How much synthetic data a design needs (mean over seeds, 95 % CI)")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
