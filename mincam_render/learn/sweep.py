"""Sweeps: minimalist cameras and baselines trained at several pixel counts; error vs pixels."""

from __future__ import annotations

import functools
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mincam_render.core import strict_json
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.builders import (
    ModelRecord,
    build_baseline,
    build_mincam,
    describe_model,
)
from mincam_render.learn.evaluation import Evaluation, evaluate
from mincam_render.learn.loop import TrainResult, train_model
from mincam_render.learn.models import Model
from mincam_render.learn.train_config import ModelKind, TrainConfig
from mincam_render.learn.training_data import TrainingData

log = logging.getLogger(__name__)


def _parse_grid(g: Any) -> tuple[int, int]:
    if isinstance(g, str):
        r, c = g.lower().split("x")
        return int(r), int(c)
    if isinstance(g, int):
        return g, g
    return int(g[0]), int(g[1])


def default_pixel_counts(num_detectors: int) -> list[int]:
    """Pixel counts of a sweep: 1, 2, 4, ... up to ``num_detectors`` (and it, if not a power)."""
    out = [1 << i for i in range(num_detectors.bit_length()) if 1 << i <= num_detectors]
    return out if out[-1] == num_detectors else [*out, num_detectors]


@dataclass(frozen=True, kw_only=True)
class SweepPoint:
    """One point of an error-vs-pixel-count plot (:func:`plot_sweep`).

    Attributes:
        kind: minimalist or baseline camera.
        pixels: the camera's pixel count.
        error: its test error (headline).
        error_name: the error's name.
    """

    kind: ModelKind
    pixels: int
    error: float
    error_name: str


@dataclass(frozen=True, kw_only=True)
class SweepRow:
    """One camera of a sweep: its description, test metrics and training (``sweep.json``).

    Attributes:
        name: ``mincam_<k>px`` or ``baseline_<r>x<c>``.
        model: the model's description.
        metrics: its test metrics.
        steps: training steps taken.
        best_step: the step of the best validation loss.
        train_wall_time_s: training's wall time (s).
        train_samples: samples of the training split.
    """

    name: str
    model: ModelRecord
    metrics: Evaluation
    steps: int
    best_step: int
    train_wall_time_s: float
    train_samples: int

    @property
    def point(self) -> SweepPoint:
        """The row's point of the sweep plot."""
        return SweepPoint(
            kind=ModelKind(self.model["kind"]),
            pixels=self.model["pixels"],
            error=self.metrics.error,
            error_name=self.metrics.error_name,
        )

    def as_json(self) -> JsonObject:
        """The row in ``sweep.json``: the model's keys inline, then the figures."""
        return {
            "name": self.name,
            **self.model,
            "error": self.metrics.error,
            "error_name": self.metrics.error_name,
            "metrics": self.metrics.as_json(),
            "steps": self.steps,
            "best_step": self.best_step,
            "train_wall_time_s": self.train_wall_time_s,
            "train_samples": self.train_samples,
        }


def sweep(
    train: TrainingData,
    val: TrainingData,
    test: TrainingData,
    *,
    pixel_counts: Sequence[int] | None = None,
    baseline_grids: Sequence[Any] = ((1, 1), (2, 2), (4, 4), (8, 8), (16, 16)),
    config: TrainConfig = TrainConfig(),
    out_dir: str | os.PathLike | None = None,
    progress: bool = False,
    on_result: Callable[[SweepRow], None] | None = None,
) -> list[SweepRow]:
    """Train minimalist cameras and baselines at several pixel counts; error vs pixels.

    ``pixel_counts`` None: :func:`default_pixel_counts` of the rendered detectors.
    Every model gets the same ``config`` (equal training budget). With
    ``out_dir``, each run trains in ``out_dir/<name>/`` (resumable) and
    ``sweep.json``, ``sweep.md`` and ``sweep.png`` (log-x axis) are written.
    """
    rows: list[SweepRow] = []
    out = Path(out_dir) if out_dir is not None else None
    jobs = _sweep_jobs(train, pixel_counts, baseline_grids, config)
    for name, make in jobs:
        model = make()
        res = train_model(
            model,
            train,
            val,
            config,
            out_dir=(out / name) if out is not None else None,
            progress=progress,
            desc=name,
        )
        metrics = evaluate(model, test)
        row = _sweep_row(name, model, res, metrics, len(train))
        rows.append(row)
        if on_result is not None:
            on_result(row)
        log.info(
            "%s: %s = %.4g after %d steps (%.1f s)",
            name,
            metrics.error_name,
            metrics.error,
            res.steps,
            res.wall_time_s,
        )
    if out is not None:
        write_sweep(rows, out, title=str(train.source.get("family", "")))
    return rows


def _sweep_jobs(
    train: TrainingData,
    pixel_counts: Sequence[int] | None,
    baseline_grids: Sequence[Any],
    config: TrainConfig,
) -> list[tuple[str, Callable[[], Model]]]:
    """``(name, build the camera)`` of every camera of a sweep, minimalist cameras first.

    The minimalist cameras take the recipe's mask blocks and signed pixels
    (``_signed`` in their names; by default up to half the detectors' pairs).
    """
    jobs: list[tuple[str, Callable[[], Model]]] = []
    signed = config.signed_pixels
    detectors = train.transport.shape[1] // (2 if signed else 1)
    for k in pixel_counts or default_pixel_counts(detectors):
        build = functools.partial(
            build_mincam,
            train,
            k,
            mask_block=config.mask_block,
            signed=signed,
            **config.head_options(),
        )
        jobs.append((f"mincam_{k}px" + ("_signed" if signed else ""), build))
    for g in baseline_grids:
        grid = _parse_grid(g)
        jobs.append(
            (
                f"baseline_{grid[0]}x{grid[1]}",
                functools.partial(build_baseline, train, grid, **config.head_options()),
            )
        )
    return jobs


def _sweep_row(
    name: str, model: Model, res: TrainResult, metrics: Evaluation, train_samples: int
) -> SweepRow:
    """A sweep row: the camera, its test error and metrics, its training."""
    return SweepRow(
        name=name,
        model=describe_model(model),
        metrics=metrics,
        steps=res.steps,
        best_step=res.best_step,
        train_wall_time_s=res.wall_time_s,
        train_samples=train_samples,
    )


def sweep_table(rows: Sequence[SweepRow]) -> str:
    """A Markdown table of sweep rows."""
    lines = [
        "| camera | pixels | test error | steps | train time (s) |",
        "|---|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r.name} | {r.model['pixels']} | {r.metrics.error:.4f} | {r.steps} | "
            f"{r.train_wall_time_s:.1f} |"
        )
    return "\n".join(lines)


def write_sweep(
    rows: Sequence[SweepRow], out_dir: str | os.PathLike, title: str = ""
) -> dict[str, Path]:
    """Write ``sweep.json``, ``sweep.md`` and ``sweep.png`` (error vs pixel count, log x)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(strict_json.dumps([r.as_json() for r in rows]))
    (out / "sweep.md").write_text(sweep_table(rows) + "\n")
    plot_sweep([r.point for r in rows], out / "sweep.png", title)
    return {"json": out / "sweep.json", "table": out / "sweep.md", "figure": out / "sweep.png"}


def plot_sweep(points: Sequence[SweepPoint], path: str | os.PathLike, title: str = "") -> None:
    """Save test error vs pixel count (log x) of ``points``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.5))
    for kind, style, label in (
        (ModelKind.MINCAM, "o-", "minimalist camera"),
        (ModelKind.BASELINE, "s--", "baseline camera"),
    ):
        pts = sorted((p.pixels, p.error) for p in points if p.kind is kind)
        if pts:
            ax.plot(*zip(*pts, strict=True), style, label=label)
    ax.set_xscale("log", base=2)
    ax.set_xlabel("pixel count")
    ax.set_ylabel(points[0].error_name if points else "test error")
    ax.set_title(f"{title} test error vs pixel count".strip())
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
