"""A comparison's report: ``metrics.json``, ``comparison.png`` and, for a study, ``study.md``.

The tables are Markdown of a :class:`~.result.ComparisonResult` (per task,
every design and the trivial predictor; the combined cameras; every label; the
label coverage); the figure puts the headline against pixel count and each
label beside it (matplotlib, Agg backend).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mincam_render.analysis.coverage import coverage_table
from mincam_render.analysis.statistics import Interval
from mincam_render.studies.comparison.records import LabelFigures
from mincam_render.studies.comparison.result import ComparisonResult, TaskComparison

if TYPE_CHECKING:
    from matplotlib.axes import Axes


def write_report(result: ComparisonResult, out: str | os.PathLike) -> dict[str, Path]:
    """Write ``out/metrics.json`` (:meth:`ComparisonResult.as_json`) and ``out/comparison.png``.

    A study's result (with :attr:`ComparisonResult.study`) also gets
    ``out/study.md`` (:func:`study_table`).

    Returns:
        ``{"json", "png"[, "md"]}``: the written paths.
    """
    out = Path(out)
    paths = {"json": out / "metrics.json", "png": out / "comparison.png"}
    result.write(paths["json"])
    plot_comparison(result.headline, result, paths["png"])
    if result.study is not None:
        paths["md"] = out / "study.md"
        paths["md"].write_text(study_table(result) + "\n")
    return paths


def study_table(result: ComparisonResult) -> str:
    """Markdown tables of a comparison: per task, every design, the trivial predictor, verdicts.

    The headline task's table also has a study's reference verdicts and
    reduction factor; every label's table and the label coverage follow.
    """
    tasks = result.tasks
    sections = []
    for i, (task, block) in enumerate(tasks.items()):
        title = result.family if len(tasks) == 1 else f"{result.family}, task {task}"
        sections.append(_design_table(block, title, result if i == 0 else None))
    lines = ["\n\n".join(sections)]
    if len(tasks) > 1:
        lines += ["", _combined_table(result)]
    lines += ["", label_table(result.headline, result.labels, result.element_names)]
    lines += ["", coverage_table(result.coverage)]
    return "\n".join(lines)


def label_table(
    block: TaskComparison,
    labels: Mapping[str, LabelFigures],
    element_names: Mapping[str, Sequence[str]],
) -> str:
    """Markdown: every label's figure per design (mean [95 % CI]), per element where several.

    Args:
        block: the headline task (its designs are the rows, then the trivial predictor).
        labels: every label's figures.
        element_names: ``{label: names}`` for the element columns (lighting's lights);
            missing: element indices.
    """
    columns: list[tuple[str, Mapping[str, Interval]]] = []
    for label, lab in labels.items():
        unit = f" ({lab.unit})" if lab.unit else ""
        what = "RMSE" + unit if lab.metric == "rmse" else "accuracy"
        columns.append((f"{label} {what}", lab.configs))
        names = list(element_names.get(label, ()))
        for i, configs in (lab.elements or {}).items():
            title = names[int(i)] if int(i) < len(names) else i
            columns.append((f"{label}: {title}", configs))
    lines = [
        "## Every label (mean over seeds [95 % CI])",
        "",
        "| design | " + " | ".join(c[0] for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for name in [*block.designs, "trivial"]:
        cells = []
        for _, configs in columns:
            c = configs.get(name)
            cells.append("" if c is None else f"{c.mean:.3f} [{c.low:.3f}, {c.high:.3f}]")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _design_table(block: TaskComparison, title: str, headline: ComparisonResult | None) -> str:
    """One task's table; ``headline``: the result whose study's verdicts follow (or None)."""
    lines = [
        f"## {title}: test {block.error_name} (mean over seeds, 95 % CI over "
        "seeds and test episodes)",
        "",
        "| design | pixels | error [95 % CI] | per seed | converged | steps | training (s) |",
        "|---|---:|---|---|---|---|---:|",
    ]
    for name, d in block.designs.items():
        e = d.error
        lines.append(
            f"| {name} | {d.pixels} | {e.mean:.3f} [{e.low:.3f}, {e.high:.3f}] | "
            f"{', '.join(f'{v:.3f}' for v in d.error_per_seed)} | {d.state} | "
            f"{', '.join(map(str, d.steps))} | {sum(d.train_wall_time_s):.0f} |"
        )
    t = block.trivial.error
    lines += [f"| trivial predictor | 0 | {t.mean:.3f} [{t.low:.3f}, {t.high:.3f}] | | | | |", ""]
    if block.verdict:
        lines.append(f"Verdict: {block.verdict}.")
    study = None if headline is None else headline.study
    if study is not None:
        lines += [f"- {line}" for line in study.reference_verdicts]
        rf = study.reduction_factor
        lines.append(
            f"Reduction factor of {rf.reference}: "
            + (
                f"{rf.factor:g}x (matches baseline {rf.baseline})"
                if rf.factor is not None
                else f"above {rf.largest_tried_factor:g}x (no baseline tried matches it)"
            )
        )
    return "\n".join(lines)


def _combined_table(result: ComparisonResult) -> str:
    """Each design as one camera for every task: its pixels and each task's figure."""
    tasks = list(result.tasks)
    lines = [
        "## One camera for every task (a minimalist camera's pixels add up per task)",
        "",
        "| design | pixels | " + " | ".join(tasks) + " |",
        "|---|---:|" + "---|" * len(tasks),
    ]
    for name, c in result.combined.items():
        cells = [
            f"{c.tasks[t].mean:.3f} [{c.tasks[t].low:.3f}, {c.tasks[t].high:.3f}]" for t in tasks
        ]
        lines.append(f"| {name} | {c.pixels} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _series_name(design: str) -> str:
    """``mincam``, ``mincam-nosensor``, ``baseline`` (``-tcn`` heads apart) of a design name."""
    parts = design.split("-")
    return "-".join([parts[0], *(p for p in parts[2:] if p in ("nosensor", "tcn"))])


def plot_comparison(
    block: TaskComparison, result: ComparisonResult, path: str | os.PathLike
) -> Path:
    """Save a PNG: the task's headline against pixel count, and every label with its interval.

    Top: one point per design of ``block`` (mean over seeds, bootstrap interval as
    error bar, each seed as a faint dot), designs of one kind joined by a line
    (minimalist cameras, their no-sensor-model ablation, baselines, each head),
    and the trivial predictor as a band; an error-rate headline is shown as
    accuracy (lighting, like the paper's Fig. 8d). Below: one panel per label
    of ``result`` (people count RMSE, zone and door accuracy, ...), and one per
    element of a headline label of several (each light), with every design and
    the trivial predictor. Every axis starts at 0 (accuracy spans 0-1), so a
    small gap looks small.
    """
    from mincam_render.analysis.plots import plt

    panels = _label_panels(block, result)
    fig = plt.figure(figsize=(max(6.5, 3.3 * len(panels)), 7.6 if panels else 4))
    grid = fig.add_gridspec(2 if panels else 1, max(1, len(panels)))
    _plot_error_vs_pixels(fig.add_subplot(grid[0, :]), block, result.family)
    for i, (name, lab) in enumerate(panels):
        _plot_label(fig.add_subplot(grid[1, i]), name, lab)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    return out


def _label_panels(
    block: TaskComparison, result: ComparisonResult
) -> list[tuple[str, LabelFigures]]:
    """``(title, label figures)`` of every label, and of each element of a headline label."""
    labels = result.labels
    first = next(iter(block.trivial.episodes.values()), None)
    headline = () if first is None else first.headline.labels
    panels = list(labels.items())
    for label in headline:
        names = result.element_names.get(label, ())
        lab = labels.get(label)
        for i, configs in ((lab.elements if lab is not None else None) or {}).items():
            title = names[int(i)] if int(i) < len(names) else i
            panels.append((f"{label}: {title}", LabelFigures(metric="accuracy", unit="",
                                                              configs=configs)))  # fmt: skip
    return panels


def _as_array(v: Any) -> np.ndarray:
    return np.asarray(v, np.float64)


def _accuracy(v: Any) -> np.ndarray:
    return 1.0 - np.asarray(v, np.float64)


def _headline_axis(error_name: str) -> tuple[Callable[[Any], np.ndarray], str]:
    """How the top panel shows the headline: accuracy (1 - error rate) or the error itself."""
    if error_name.endswith(" error rate"):  # accuracy against pixels, as the paper's Fig. 8d
        return _accuracy, f"test {error_name.removesuffix(' error rate')} accuracy"
    return _as_array, f"test {error_name}"


def _plot_error_vs_pixels(ax: Axes, block: TaskComparison, family: str) -> None:
    shown, ylabel = _headline_axis(block.error_name)
    t = block.trivial.error
    lo, hi = sorted(shown([t.low, t.high]))
    ax.axhspan(lo, hi, color="0.85", label="trivial predictor (95 % CI)")
    ax.axhline(float(shown(t.mean)), color="0.5", lw=1, ls="--")
    series: dict[str, list] = {}
    for name, d in block.designs.items():
        series.setdefault(_series_name(name), []).append(d)
    for kind, ds in series.items():
        colour = f"C{_SERIES.index(kind)}"
        ds = sorted(ds, key=lambda d: d.pixels)
        px = np.array([d.pixels for d in ds])
        mean = shown([d.error.mean for d in ds])
        ci = np.sort(shown([[d.error.low, d.error.high] for d in ds]), axis=1)
        ax.errorbar(
            px,
            mean,
            yerr=np.clip([mean - ci[:, 0], ci[:, 1] - mean], 0.0, None),
            fmt="o-",
            color=colour,
            capsize=4,
            label=kind,
        )
        for p, d in zip(px, ds, strict=True):
            seeds = shown(d.error_per_seed)
            ax.plot([p] * len(seeds), seeds, ".", color=colour, alpha=0.4)
    ax.set_xscale("log", base=2)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel("pixels")
    ax.set_ylabel(ylabel)
    what = block.verdict or f"{len(block.designs)} designs, mean over seeds, 95 % CI"
    ax.set_title(f"{family}: {what}", fontsize=8)
    ax.legend(fontsize=7)


def _plot_label(ax: Axes, name: str, lab: LabelFigures) -> None:
    """One label's figure per configuration (the trivial predictor in grey), 95 % CIs."""
    configs = list(lab.configs.items())
    x = np.arange(len(configs))
    mean = np.array([c.mean for _, c in configs])
    ci = np.array([[c.low, c.high] for _, c in configs])
    colours = [
        "0.5" if n == "trivial" else f"C{_SERIES.index(_series_name(n))}" for n, _ in configs
    ]
    for xi, m, c, colour in zip(x, mean, ci, colours, strict=True):
        ax.errorbar(
            xi,
            m,
            yerr=[[max(m - c[0], 0.0)], [max(c[1] - m, 0.0)]],
            fmt="o",
            color=colour,
            capsize=4,
        )
    ax.set_xticks(x, [n for n, _ in configs], rotation=45, ha="right", fontsize=7)
    ax.set_xlim(-0.6, len(configs) - 0.4)
    unit = f" ({lab.unit})" if lab.unit else ""
    if lab.metric == "accuracy":
        ax.set_ylim(0.0, 1.0)
        ax.set_ylabel("accuracy (higher is better)", fontsize=8)
    else:
        ax.set_ylim(0.0, 1.1 * float(np.max(ci[:, 1])) or 1.0)
        ax.set_ylabel(f"RMSE{unit} (lower is better)", fontsize=8)
    ax.set_title(name, fontsize=9)


#: Design kinds, each drawn in its own colour (C0, C1, ...) in every panel.
_SERIES = (
    "mincam",
    "mincam-nosensor",
    "baseline",
    "mincam-tcn",
    "mincam-nosensor-tcn",
    "baseline-tcn",
)
