"""Nominal against robust training: the runs, their curves, the verdict and the kept masks.

For one task and an 8-pixel minimalist camera on a comparison's episodes,
:func:`train_kinds` trains nominal designs and as many robust-trained ones
(``TrainConfig.perturbation = PerturbationModel()``), :func:`run_curves`
measures every run under the perturbations (kept in ``robustness.json`` of its
run directory), :func:`verdict` states the issue's done-when beside the
trivial predictor (:func:`trivial_error`) and :func:`keep_robust_masks` keeps
the best robust run's masks. ``benchmarks/bench_robustness.py`` calls them.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from mincam_render.core import strict_json
from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.learn import train as tr
from mincam_render.optics.perturbation import PerturbationModel
from mincam_render.studies.comparison.config import ComparisonConfig
from mincam_render.studies.comparison.study import episode_record, keep_run_masks, trivial_metrics
from mincam_render.studies.robustness.config import MIX, RobustnessConfig
from mincam_render.studies.robustness.result import CurveLevel, DesignCurves
from mincam_render.studies.robustness.study import (
    pool_curves,
    pool_episode_metrics,
    robustness_curves,
)

log = logging.getLogger(__name__)

#: Freeform pixels of the designs compared.
PIXELS = 8
#: The two kinds of training compared.
KINDS = ("nominal", "robust")


def in_memory(data: tr.TrainingData) -> tr.TrainingData:
    """A test episode as float32 watts in memory: evaluated hundreds of times."""
    return dataclasses.replace(data, transport=data.frames_np(0, len(data.transport)), scales=None)


def training_split(episodes: dict) -> tr.TrainingData:
    """The training episodes as one split."""
    return tr.TrainingData.concat([d for n, d in episodes.items() if n.startswith("train")])


def config_json(config: RobustnessConfig) -> Any:
    """``config`` as it reads back from a JSON file (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(config)))


def train_kinds(
    cfg: ComparisonConfig,
    episodes: dict,
    runs_dir: Path,
    seeds: int,
    report: Callable[[str], None] = log.info,
) -> dict[str, list[Path]]:
    """``{kind: [run directory]}``: nominal and robust runs in ``runs_dir``, one per seed.

    ``report`` receives a line per finished run (its steps and training time).
    """
    train = training_split(episodes)
    tests = {n: d for n, d in episodes.items() if n.startswith("test")}
    runs: dict[str, list[Path]] = {k: [] for k in KINDS}
    for i in range(seeds):
        seed = stream_seed(cfg.seed, f"train/mincam-{PIXELS}px", i)
        for kind in KINDS:
            pert = PerturbationModel() if kind == "robust" else None
            run_dir = runs_dir / f"{kind}-seed{i}"
            m = tr.train_run(
                train,
                episodes["val-0"],
                None,
                run_dir,
                pixels=PIXELS,
                config=dataclasses.replace(cfg.train, seed=seed, perturbation=pert),
                episodes=tests,
            )
            report(f"{kind} seed {i}: {m.steps} steps, {m.train_wall_time_s:.0f} s")
            runs[kind].append(run_dir)
    return runs


def run_curves(run_dir: Path, tests: dict, config: RobustnessConfig, kind: str) -> DesignCurves:
    """The run's curves, measured or read back from ``run_dir/robustness.json``."""
    path = run_dir / "robustness.json"
    if path.is_file():
        record = json.loads(path.read_text())
        if record["config"] == config_json(config):
            return DesignCurves.from_json(record)
    model = tr.restore_mincam(tr.open_run(run_dir), next(iter(tests.values())), "robustness")
    curves = robustness_curves(model, tests, config, name=run_dir.name, robust=kind == "robust")
    path.write_text(strict_json.dumps(curves.as_json(), indent=None) + "\n")
    return curves


def summary(design: DesignCurves) -> JsonObject:
    """A design's record without the raw per-draw increases."""
    return design.as_json(increases=False)


def verdict(designs: Mapping[str, DesignCurves], allowed: float, trivial: float) -> str:
    """The issue's done-when, then which built camera is better, beside the trivial predictor.

    Done-when: robust designs within ``allowed`` under the default mix where nominal
    ones lose more. A relative figure alone favours a design that learned little.
    """
    mix = {kind: d.curves[MIX].level_at(1.0) for kind, d in designs.items()}
    r, n = mix["robust"], mix["nominal"]
    text = (
        f"under the default mix, nominal designs lose {_pct(n)}, robust designs "
        f"{_pct(r)} (limit {100 * allowed:g} %)"
    )
    text += (
        "; done-when met"
        if r.mean_increase <= allowed < n.mean_increase
        else ("; done-when NOT met as stated (see note)")
    )
    errors = {k: designs[k].nominal_error for k in KINDS}
    text += (
        f". Error as designed: nominal {errors['nominal']:.4g}, robust {errors['robust']:.4g}; "
        f"under the mix: nominal {_abs(n)}, robust {_abs(r)}; trivial predictor {trivial:.4g}"
    )
    r_error, n_error = _error_interval(r), _error_interval(n)
    if r_error[0] > n_error[1]:
        text += " (the nominal design is better under the mix: intervals separate)"
    elif n_error[0] > r_error[1]:
        text += " (the robust design is better under the mix: intervals separate)"
    return text


def _error_interval(level: CurveLevel) -> tuple[float, float]:
    """The level's error interval (NaN for a record measured before it was kept)."""
    return level.ci95_error or (float("nan"), float("nan"))


def _pct(level: CurveLevel) -> str:
    """The mean increase and its interval, in percent."""
    lo, hi = level.ci95_increase
    return f"{100 * level.mean_increase:+.1f} % [{100 * lo:+.1f}, {100 * hi:+.1f}]"


def _abs(level: CurveLevel) -> str:
    """The error itself and its interval."""
    lo, hi = _error_interval(level)
    return f"{level.mean_error:.4g} [{lo:.4g}, {hi:.4g}]"


def trivial_error(episodes: dict) -> float:
    """The trivial predictor's error (training-label mean, mode if binary) on the test episodes."""
    train = training_split(episodes)
    tests = [d for n, d in episodes.items() if n.startswith("test")]
    return pool_episode_metrics([trivial_metrics(train, d).as_json() for d in tests])


def keep_robust_masks(runs: list[Path], episodes: dict, entry: dict, task: str, out: Path) -> None:
    """The best robust run's masks (lowest robust-validation loss) into ``out``.

    The sidecar holds the run's own test error as designed, the robust design's
    error as designed and under the default mix (pooled over its seeds), its
    specs and the verdict, with the episodes' manifest hashes.
    """
    best = min(runs, key=lambda r: json.loads((r / "metrics.json").read_text())["best_val_loss"])
    design = entry["designs"]["robust"]
    own = next(r["nominal_error"] for r in entry["runs"]["robust"] if r["run"] == best.name)
    levels = design["config"]["levels"]
    as_designed, mix = (design["curves"][MIX]["levels"][levels.index(x)] for x in (0.0, 1.0))
    figures = {
        "chosen_by": (
            "lowest validation loss of the robust seeds (each under its own built cameras)"
        ),
        "test_error": own,
        "test_error_over_seeds": {
            "mean": as_designed["mean_error"],
            "ci95": as_designed["ci95_error"],
            "resampled": "training seeds (the test episodes pooled per run)",
        },
        "robustness": {
            "under_default_mix": mix,
            "specs": {name: c["spec"] for name, c in design["curves"].items()},
            "verdict": entry["verdict"],
        },
        "episodes": {n: episode_record(d).as_json() for n, d in episodes.items()},
    }
    keep_run_masks(best, out, task, figures)


@dataclasses.dataclass(frozen=True)
class KindsResult:
    """Nominal against robust designs: runs, per-run records, pooled designs, verdict.

    Args:
        runs: ``{kind: [run directory per seed]}``.
        records: ``{kind: [each run's robustness record]}``.
        designs: ``{kind: the runs' records pooled}`` (:func:`~.study.pool_curves`).
        trivial: the trivial predictor's error on the test episodes.
        verdict: :func:`verdict`'s sentence.
    """

    runs: Mapping[str, list[Path]]
    records: Mapping[str, list[DesignCurves]]
    designs: Mapping[str, DesignCurves]
    trivial: float
    verdict: str


def compare_kinds(
    cfg: ComparisonConfig,
    episodes: dict,
    runs_dir: Path,
    config: RobustnessConfig,
    *,
    seeds: int,
    name: str,
    report: Callable[[str], None] = log.info,
) -> KindsResult:
    """Train (or read back) both kinds, measure every run, pool them and state the verdict.

    Args:
        cfg: the episodes' comparison (its recipe and seed).
        episodes: ``{episode: TrainingData}``
            (:func:`~mincam_render.studies.comparison.study.render_episodes`).
        runs_dir: where the runs go (resumed).
        config: what is measured.
        seeds: runs per kind.
        name: the task's name in the designs' names.
        report: receives a line per finished run.
    """
    runs = train_kinds(cfg, episodes, runs_dir, seeds, report)
    tests = {n: in_memory(d) for n, d in episodes.items() if n.startswith("test")}
    records = {k: [run_curves(r, tests, config, k) for r in runs[k]] for k in KINDS}
    designs = {k: pool_curves(records[k], f"{name}, mincam {PIXELS} px, {k}") for k in KINDS}
    trivial = trivial_error(episodes)
    text = verdict(designs, config.allowed_increase, trivial)
    return KindsResult(runs=runs, records=records, designs=designs, trivial=trivial, verdict=text)
