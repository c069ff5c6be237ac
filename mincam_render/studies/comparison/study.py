"""The main job: a minimalist camera against a conventional one, with a verdict that holds.

1. Render independent scene episodes (:func:`episode_requests`): training
   episodes (joined into one training set), one validation episode and several
   test episodes, each its own
   dataset with its own scene seed (other schedules of people, other door and
   lamp events), derived from the root seed by
   :func:`mincam_render.core.seeds.stream_seed`. All episodes of one length
   share one fidelity plan (measured on the planning episode).
2. Train the minimalist camera and the baseline with several training seeds
   (same recipe and budget), early stopping on the validation episode: in
   this process, in local worker processes or as Ray tasks, with the same
   result per run (:mod:`mincam_render.data.run_dispatch`).
3. Test every run on every test episode with the paper's post-processing;
   also the trivial predictor (the training mean of every label; the mode for
   binary labels).
4. Report each design's error as mean over seeds with a 95 % bootstrap interval
   over seeds and test episodes (:mod:`mincam_render.analysis.statistics`), whether
   each run converged, and a verdict only where intervals separate.
5. Keep the masks of each minimalist design's best run (lowest validation
   loss) with a sidecar holding the figures above; write ``metrics.json``
   (with the label coverage of every split and what each misses,
   :mod:`mincam_render.analysis.coverage`) and ``comparison.png``.

The main job compares two designs (:class:`Design`); a study passes more (a
pixel-count sweep against baselines of several resolutions).

Everything resumes: finished episodes and runs are found on disk and kept.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from mincam_render.analysis.coverage import coverage_table, study_coverage
from mincam_render.analysis.mask_structure import (
    MaskStructure,
    plot_mask_views,
    run_structure,
    view_and_label_map,
)
from mincam_render.analysis.statistics import (
    EpisodeErrors,
    Interval,
    Pooling,
    bootstrap_interval,
    converged,
    paired_difference,
    paired_statement,
    verdict,
)
from mincam_render.core.labels import LabelKind, label_tasks
from mincam_render.core.seeds import stream_seed
from mincam_render.data.dataset import MANIFEST_NAME, open_dataset, sha256_file
from mincam_render.data.ray_cluster import ray_session
from mincam_render.data.render_job import RenderRequest, package_versions, render_dataset
from mincam_render.data.run_dispatch import check_executor
from mincam_render.export.masks import export_masks
from mincam_render.learn.train import TrainingData, metrics, run_masks
from mincam_render.learn.train_config import ModelKind

# Design is re-exported: callers build designs and comparisons from this module
from mincam_render.studies.comparison.config import ComparisonConfig
from mincam_render.studies.comparison.config import Design as Design
from mincam_render.studies.comparison.result import (
    CombinedCamera,
    ComparisonResult,
    ReductionFactor,
    StudySummary,
    TaskComparison,
)
from mincam_render.studies.comparison.runs import task_splits, train_runs

#: Shards of every episode dataset (balanced on 1, 2 or 4 render workers).
SHARDS_PER_EPISODE = 4
#: Episode roles and the split each episode's dataset puts all its frames in.
ROLE_SPLITS = {"train": (1.0, 0.0, 0.0), "val": (0.0, 1.0, 0.0), "test": (0.0, 0.0, 1.0)}


def episode_requests(cfg: ComparisonConfig) -> dict[str, RenderRequest]:
    """``{"train-i" | "val-i" | "test-i": RenderRequest}``: one dataset per episode.

    Each episode's seed is ``stream_seed(cfg.seed, "episode/<role>", i)``, its
    description the family's with ``cfg.overrides`` and ``cfg.fps``; every
    episode has :data:`SHARDS_PER_EPISODE` shards whatever the worker count (so
    a run resumes with any ``--workers``, and 1, 2 or 4 workers share them evenly).
    """
    counts = {
        "train": (cfg.train_episodes, cfg.train_frames),
        "val": (cfg.val_episodes, cfg.val_frames),
        "test": (cfg.test_episodes, cfg.test_frames),
    }
    requests = {}
    for role, (episodes, frames) in counts.items():
        for i in range(episodes):
            requests[f"{role}-{i}"] = RenderRequest(
                family=cfg.family,
                num_frames=frames,
                seed=stream_seed(cfg.seed, f"episode/{role}", i),
                overrides={**cfg.overrides, "fps": cfg.fps},
                splits=ROLE_SPLITS[role],
                shard_frames=-(-frames // SHARDS_PER_EPISODE),
                mask_res=cfg.mask_res,
                **dict(cfg.fidelity),
            )
    return requests


def render_episodes(
    cfg: ComparisonConfig,
    episodes_dir: Path,
    *,
    workers: int = 2,
    ray_address: str | None = None,
    progress: bool = True,
) -> dict[str, TrainingData]:
    """Render (or resume) every episode into ``episodes_dir/<name>``; their training views.

    The views are at ``cfg.light_scale`` times the rendered light; for
    ``cfg.oracle_background`` every frame's converged background is replaced by
    one fixed background (the first episode's mean). ``ray_address``:
    render the shards as Ray tasks there (``workers`` is then ignored).
    """
    from mincam_render.data.render_job.backgrounds import converged_backgrounds

    data = {}
    fixed: np.ndarray | None = None
    for name, request in episode_requests(cfg).items():
        path = episodes_dir / name
        render_dataset(request, path, workers=workers, ray_address=ray_address, progress=progress)
        role = name.split("-")[0]
        view = TrainingData.from_dataset(open_dataset(path), role)
        if cfg.oracle_background:  # one fixed background: the first episode's mean
            static = converged_backgrounds(path)[slice(*view.source["range"])]
            fixed = static.mean(axis=0) if fixed is None else fixed
            view = view.with_static_part(static, fixed)
        data[name] = view if cfg.light_scale == 1.0 else view.with_light_scaled(cfg.light_scale)
    return data


def comparison_splits(data: Mapping[str, TrainingData]) -> dict[str, Any]:
    """``{"train": the training episodes joined, "val" and "tests": {name: episode}}``."""
    return {
        "train": TrainingData.concat([v for k, v in data.items() if k.startswith("train-")]),
        "val": {k: v for k, v in data.items() if k.startswith("val-")},
        "tests": {k: v for k, v in data.items() if k.startswith("test-")},
    }


def episode_record(data: TrainingData) -> dict[str, Any]:
    """Samples, provenance and the sha256 of the episode dataset's manifest."""
    path = Path(data.source["dataset"]) / MANIFEST_NAME
    return {"samples": len(data), **data.source, "manifest_sha256": sha256_file(path)}


def _pooling(error_name: str) -> Pooling:
    return Pooling.RMS if error_name.endswith("RMSE") else Pooling.MEAN


def _intervals(
    per_config: Mapping[str, list[Mapping[str, Mapping[str, Any]]]],
    figure: Callable[[Mapping[str, Any]], float],
    pooling: Pooling,
    seed: int,
) -> dict[str, dict[str, Any]]:
    """``{configuration: {"mean", "ci95"}}`` of ``figure(episode metrics)`` per configuration."""
    configs = {}
    for name, per_seed in per_config.items():
        names = sorted(per_seed[0])
        errors = EpisodeErrors(
            error=np.array([[figure(s[e]) for e in names] for s in per_seed]),
            frames=np.array([per_seed[0][e]["samples"] for e in names]),
            pooling=pooling,
        )
        configs[name] = bootstrap_interval(errors, seed=seed).as_dict()
    return configs


def _figure(
    episode: Mapping[str, Any], *, label: str, key: str, element: int | None = None
) -> float:
    """``episode["labels"][label][key]`` (its ``element``-th entry if given)."""
    value = episode["labels"][label][key]
    return float(value if element is None else value[element])


def label_intervals(
    per_config: Mapping[str, list[Mapping[str, Mapping[str, Any]]]], seed: int
) -> dict[str, dict[str, Any]]:
    """Every label's figure with its 95 % interval, per configuration.

    Args:
        per_config: ``{configuration: [per-seed {episode: metrics}]}`` (runs'
            ``episodes``, or the trivial predictor's as a one-seed list).
        seed: bootstrap seed.

    Returns:
        ``{label: {"metric": "rmse"|"accuracy", "unit": str, "configs": {name:
        {"mean", "ci95"}}}}``: RMSE pooled as a root mean square over test frames,
        accuracy as a mean (higher is better); intervals resample seeds and episodes.
        A BINARY label of several elements (lighting's five lights) also has
        ``"elements": {index: {"configs": ...}}``: each element's accuracy.
    """
    first = next(iter(per_config.values()))[0]
    some = first[next(iter(first))]["labels"]
    out: dict[str, dict[str, Any]] = {}
    for label, m in some.items():
        metric = "rmse" if "rmse" in m else "accuracy"
        pooling = Pooling.RMS if metric == "rmse" else Pooling.MEAN
        configs = _intervals(per_config, partial(_figure, label=label, key=metric), pooling, seed)
        out[label] = {"metric": metric, "unit": m.get("unit", ""), "configs": configs}
        if len(m.get("accuracy_per_element", ())) > 1:
            out[label]["elements"] = {
                str(i): {
                    "configs": _intervals(
                        per_config,
                        partial(_figure, label=label, key="accuracy_per_element", element=i),
                        Pooling.MEAN,
                        seed,
                    )
                }
                for i in range(len(m["accuracy_per_element"]))
            }
    return out


def trivial_metrics(train: TrainingData, test: TrainingData) -> dict[str, Any]:
    """Test metrics of the trivial predictor: every label's training mean (mode if binary)."""
    n = len(test)
    lab = {k: v[test.history - 1 :] for k, v in test.labels.items()}
    pred = {}
    for s in test.label_specs:
        mean = train.labels[s.name].mean(axis=0)
        if s.kind is LabelKind.BINARY:
            mean = (mean >= 0.5).astype(np.float32)
        pred[s.name] = np.broadcast_to(mean, (n, s.size)).astype(np.float32)
    scored = metrics(pred, lab, float("nan"), test).as_json()
    return scored | {"loss": None, "loss_null_reason": "the trivial predictor has no training loss"}


def episode_errors(per_seed: list[Mapping[str, Mapping[str, Any]]]) -> EpisodeErrors:
    """``EpisodeErrors`` of runs' (or the trivial predictor's) per-episode metrics."""
    first = per_seed[0]
    names = sorted(first)
    return EpisodeErrors(
        error=np.array([[m[e]["error"] for e in names] for m in per_seed]),
        frames=np.array([first[e]["samples"] for e in names]),
        pooling=_pooling(first[names[0]]["error_name"]),
    )


def paired_differences(
    errors: Mapping[str, EpisodeErrors], compared: Sequence[str], seed: int
) -> dict[str, dict[str, Any]]:
    """Paired differences on the same test episodes, beside the separate intervals.

    ``compared`` (the first two designs) against each other when there are two,
    and every design against the trivial predictor (``errors["trivial"]``).

    Returns:
        ``{"A - B": {"mean", "ci95", "statement"}}``.
    """
    pairs = [(n, "trivial") for n in errors if n != "trivial"]
    if len(compared) == 2:
        pairs.insert(0, (compared[0], compared[1]))
    out: dict[str, dict[str, Any]] = {}
    for a, b in pairs:
        diff = paired_difference(errors[a], errors[b], seed=seed)
        out[f"{a} - {b}"] = diff.as_dict() | {"statement": paired_statement(a, b, diff)}
    return out


def training_state(convergence: Sequence[Mapping[str, Any]]) -> str:
    """``converged`` (every run: last doubling of steps < 2 % better); else why not.

    ``early-stopped, not converged``: validation stopped improving for the
    patience window after the last learning-rate decay, yet the last doubling
    of steps still gained >= 2 % (noisy or slow); ``budget-limited``: some run
    used every step.
    """
    if all(c["converged"] for c in convergence):
        return "converged"
    if all(c["converged"] or c["stopped_early"] for c in convergence):
        return "early-stopped, not converged"
    return "budget-limited"


def _validation_figures(runs: Sequence[Mapping[str, Any]]) -> dict[str, Any] | None:
    """The kept states' error on each validation episode, pooled like the test error.

    ``{"error": {"mean", "ci95"}, "episode_errors"}`` (the interval over seeds
    and validation episodes); None for runs without named validation episodes.
    """
    if not all(r.get("validation_episodes") for r in runs):
        return None
    errors = episode_errors([r["validation_episodes"] for r in runs])
    return {"error": bootstrap_interval(errors).as_dict(), "episode_errors": errors.as_dict()}


def kept_val_error(run: Mapping[str, Any]) -> float | None:
    """A run's pooled validation error at its kept (best) step; None if not recorded."""
    best = [h for h in run["history"] if h["step"] == run["best_step"]]
    return best[0].get("val_error") if best else None


def _design_summary(
    runs: list[dict[str, Any]],
    interval: Interval,
    errors: EpisodeErrors,
    view_map: tuple[np.ndarray, np.ndarray],
) -> dict[str, Any]:
    """A design's figures over its runs; a minimalist design's masks' structure too.

    ``structure`` (:mod:`~mincam_render.analysis.mask_structure`) is that of
    the run with the lowest validation loss, whose masks a comparison keeps.
    """
    conv = [dict(converged(r["history"]), stopped_early=r["stopped_early"]) for r in runs]
    structure = None
    if ModelKind(runs[0]["model"]["kind"]) is ModelKind.MINCAM:
        best = min(runs, key=lambda r: r["best_val_loss"])
        labels = tuple(next(iter(best["episodes"].values()))["labels"])
        structure = dataclasses.asdict(run_structure(best["run_dir"], view_map, labels))
    return {
        "model": runs[0]["model"],
        "error": interval.as_dict(),
        "episode_errors": errors.as_dict(),
        "error_per_seed": [episode_errors([r["episodes"]]).point() for r in runs],
        "val_error_per_seed": [kept_val_error(r) for r in runs],
        "validation": _validation_figures(runs),
        "converged": all(c["converged"] for c in conv),
        "state": training_state(conv),
        "convergence": conv,
        "train_wall_time_s": [r["train_wall_time_s"] for r in runs],
        "steps": [r["steps"] for r in runs],
        "runs": [r["run_dir"] for r in runs],
        "structure": structure,
    }


def keep_run_masks(
    run_dir: str | os.PathLike, out_dir: Path, task: str, figures: Mapping[str, Any]
) -> dict[str, Any]:
    """Export ``run_dir``'s masks into ``out_dir``; the sidecar holds ``figures`` too.

    Returns the written files' paths as strings (``"png"``: a list).

    The sidecar's provenance: the run, its data, recipe and detectors, the
    package versions, then ``figures`` (how the run was chosen, its errors).
    """
    m, camera, run = run_masks(run_dir)
    provenance = {
        "run": str(run_dir),
        "data": run["data"],
        "config": run["config"],
        "detectors": run["model"]["detectors"],
        "versions": package_versions(),
        **figures,
    }
    exported = export_masks(m, camera, out_dir, task=task, provenance=provenance)
    return exported.as_json()


def _keep_masks(
    runs: list[dict[str, Any]],
    summary: Mapping[str, Any],
    episodes: Mapping[str, Any],
    out_dir: Path,
    task: str,
    view_map: tuple[np.ndarray, np.ndarray],
) -> dict[str, Any]:
    """Export into ``out_dir`` the masks of the run with the lowest validation loss.

    Beside them, ``looks_at.png``: the masks over the camera's view and the
    task's label map, with their structure figures (also in the sidecar).
    """
    best = min(runs, key=lambda r: r["best_val_loss"])
    figures = {
        "chosen_by": "lowest validation loss of the training seeds",
        "test_error_over_seeds": summary["error"],
        "test_episodes": best["episodes"],
        "episodes": episodes,
        "structure": summary["structure"],
    }
    kept = keep_run_masks(best["run_dir"], out_dir, task, figures)
    masks, _, _ = run_masks(best["run_dir"])
    structure = MaskStructure(**summary["structure"])
    png = plot_mask_views(masks, *view_map, structure, out_dir / "looks_at.png", title=task)
    return kept | {"looks_at": str(png)}


def run_comparison(
    cfg: ComparisonConfig,
    out_dir: str | os.PathLike,
    *,
    workers: int = 2,
    train_workers: int = 1,
    ray_address: str | None = None,
    masks_dir: str | os.PathLike | None = None,
    episodes_dir: str | os.PathLike | None = None,
    progress: bool = True,
) -> ComparisonResult:
    """Render, train, test and compare (module docstring); ``metrics.json`` is its JSON.

    Writes the episodes into ``episodes_dir`` (default ``out_dir/episodes/``; a
    shared directory lets comparisons at other light scales reuse one render),
    ``out_dir/runs/``, ``out_dir/metrics.json``, ``out_dir/comparison.png`` and,
    unless ``masks_dir`` is None, every minimalist design's best masks into
    ``masks_dir/<task>/<design>/``.

    Episodes render in ``workers`` processes; the training runs in this process
    (``train_workers=1``) or ``train_workers`` worker processes
    (:mod:`~mincam_render.data.run_dispatch`). With ``ray_address``
    (``"local"`` starts a cluster) both render and train as Ray tasks.

    Raises:
        ValueError: invalid ``train_workers`` or ``ray_address`` (before anything is written).
        mincam_render.data.ray_cluster.RayError: Ray is missing or unreachable.
        mincam_render.data.run_dispatch.TrainingError: a training worker died or
            stalled, or a Ray run failed.
    """
    check_executor(train_workers, ray_address)
    with ray_session(ray_address) if ray_address is not None else contextlib.nullcontext():
        return _run_comparison(
            cfg,
            Path(out_dir),
            workers=workers,
            train_workers=train_workers,
            ray_address=ray_address,
            masks_dir=masks_dir,
            episodes_dir=episodes_dir,
            progress=progress,
        )


def _run_comparison(
    cfg: ComparisonConfig,
    out: Path,
    *,
    workers: int,
    train_workers: int,
    ray_address: str | None,
    masks_dir: str | os.PathLike | None,
    episodes_dir: str | os.PathLike | None,
    progress: bool,
) -> ComparisonResult:
    from mincam_render.analysis.plots import plot_comparison

    out.mkdir(parents=True, exist_ok=True)
    episodes = Path(episodes_dir) if episodes_dir is not None else out / "episodes"
    data = render_episodes(
        cfg, episodes, workers=workers, ray_address=ray_address, progress=progress
    )
    splits = comparison_splits(data)
    train = splits["train"]
    family = Path(str(data["val-0"].source.get("family") or cfg.family)).stem
    # before training: a split that misses part of the label space is logged at once
    coverage = study_coverage(
        {"train": train, **{k: v for k, v in data.items() if not k.startswith("train-")}}
    )
    runs = train_runs(
        cfg, splits, out, train_workers=train_workers, ray_address=ray_address, progress=progress
    )
    task_labels = cfg.task_labels(label_tasks(train.label_specs))
    task_data = {task: task_splits(splits, task_labels[task]) for task in runs}
    maps = {task: view_and_label_map(d["train"]) for task, d in task_data.items()}
    blocks = {
        task: task_comparison(cfg, by_design, task_data[task], maps[task])
        for task, by_design in runs.items()
    }
    result = ComparisonResult(
        family=family,
        protocol=cfg.protocol,
        config=json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        episodes={k: episode_record(d) for k, d in data.items()},
        labels={label: lab for b in blocks.values() for label, lab in b.labels.items()},
        tasks=blocks,
        combined=combined_cameras(cfg, blocks),
        element_names={s.name: tuple(s.element_names) for s in train.label_specs},
        coverage=coverage,
        figure=str(out / "comparison.png"),
        versions=package_versions(),
    )
    result.write(out / "metrics.json")
    plot_comparison(result.as_json(), out / "comparison.png")
    if masks_dir is not None:
        masks = _keep_all_masks(cfg, runs, result, Path(masks_dir) / family, maps)
        result = dataclasses.replace(result, masks=masks)
    run_dirs = [r["run_dir"] for designs in runs.values() for rs in designs.values() for r in rs]
    others = others_in_folders(
        {
            "episodes": (episodes, set(data)),
            "runs": (out / "runs", {_entry_in(out / "runs", d) for d in run_dirs}),
            "masks": (
                Path(masks_dir or out / "masks") / family,
                {name.split("/")[0] for name in result.masks or {}},
            ),
        }
    )
    result = dataclasses.replace(result, not_of_this_comparison=others)
    result.write(out / "metrics.json")
    return result


def task_comparison(
    cfg: ComparisonConfig,
    runs: Mapping[str, list[dict[str, Any]]],
    splits: Mapping[str, Any],
    view_map: tuple[np.ndarray, np.ndarray],
) -> TaskComparison:
    """One task's figures: every design, the trivial predictor, verdicts, every label.

    Args:
        cfg: the comparison (its first two designs are compared; its seed seeds
            the bootstrap).
        runs: ``{design: [run metrics per seed]}`` of cameras trained for the task.
        splits: the task's splits (its labels only, :func:`task_splits`).
        view_map: the training view and the task's label map
            (:func:`~mincam_render.analysis.mask_structure.view_and_label_map`).

    Returns:
        The task's figures.
    """
    train, tests = splits["train"], splits["tests"]
    trivial = {k: trivial_metrics(train, d) for k, d in tests.items()}
    errors = {name: episode_errors([r["episodes"] for r in rs]) for name, rs in runs.items()}
    errors["trivial"] = episode_errors([trivial])
    intervals = {name: bootstrap_interval(e, seed=cfg.seed) for name, e in errors.items()}
    trivial_iv = intervals.pop("trivial")
    names = [d.name for d in cfg.designs]
    return TaskComparison(
        error_name=next(iter(trivial.values()))["error_name"],
        designs={
            name: _design_summary(rs, intervals[name], errors[name], view_map)
            for name, rs in runs.items()
        },
        trivial={
            "error": trivial_iv.as_dict(),
            "episode_errors": errors["trivial"].as_dict(),
            "episodes": trivial,
        },
        verdict=(
            verdict(names[0], intervals[names[0]], names[1], intervals[names[1]])
            if len(names) == 2
            else None
        ),
        versus_trivial={
            name: verdict(name, iv, "trivial", trivial_iv) for name, iv in intervals.items()
        },
        paired=paired_differences(errors, names[:2], cfg.seed),
        labels=label_intervals(
            {name: [r["episodes"] for r in rs] for name, rs in runs.items()}
            | {"trivial": [trivial]},
            seed=cfg.seed,
        ),
    )


def combined_cameras(
    cfg: ComparisonConfig, blocks: Mapping[str, TaskComparison]
) -> dict[str, CombinedCamera]:
    """Each design as one camera for every task trained: its pixels and each task's figure.

    A minimalist camera for several tasks is the union of its tasks' freeform
    pixels (paper Sec. 7: two for each task), so its pixels add up; a
    conventional camera is one sensor whatever the number of heads reading it.
    """
    out = {}
    for d in cfg.designs:
        first = blocks[next(iter(blocks))].designs[d.name]["model"]["pixels"]
        out[d.name] = CombinedCamera(
            pixels=first * len(blocks) if d.is_mincam else first,
            tasks={t: b.designs[d.name]["error"] for t, b in blocks.items()},
        )
    return out


def _keep_all_masks(
    cfg: ComparisonConfig,
    runs: Mapping[str, Mapping[str, list[dict[str, Any]]]],
    result: ComparisonResult,
    family_dir: Path,
    maps: Mapping[str, tuple[np.ndarray, np.ndarray]],
) -> dict[str, Any]:
    """Every minimalist design's best masks per task; their records.

    Into ``family_dir/<design>/`` for a single task (or a joint camera), into
    ``family_dir/<design>/<task>/`` for each of several tasks.
    """
    kept: dict[str, Any] = {}
    for task, by_design in runs.items():
        block = result.tasks[task]
        for d in (d for d in cfg.designs if d.is_mincam):
            several = len(runs) > 1
            where = family_dir / d.name / task if several else family_dir / d.name
            title = f"{result.family} {task}" if several else result.family
            record = _keep_masks(
                by_design[d.name], block.designs[d.name], result.episodes, where, title,
                maps[task],
            )  # fmt: skip
            kept[f"{d.name}/{task}" if len(runs) > 1 else d.name] = record
    return kept


def _is_baseline(design: Mapping[str, Any]) -> bool:
    """A study's design record is a baseline's (its ``model.kind``, never its name)."""
    return ModelKind(design["model"]["kind"]) is ModelKind.BASELINE


def reduction_factor(result: Mapping[str, Any], reference: str) -> dict[str, Any]:
    """Pixel reduction of design ``reference`` at equal error (the paper's 256x, 2048x).

    The smallest baseline (with the reference's head) whose 95 % interval
    overlaps or lies below the reference's (its lower bound at most the
    reference's upper bound); the factor is its pixel count over the
    reference's. None when no baseline of the study comes that close (the
    factor then exceeds the largest tried).
    """
    designs = result["designs"]
    if reference not in designs:
        raise ValueError(f"reference design {reference!r} not in the study: {sorted(designs)}")
    ref = designs[reference]
    head = ref["model"].get("head", "mlp")  # baselines with the reference's head
    baselines = sorted(
        (
            d
            for n, d in designs.items()
            if _is_baseline(d) and d["model"].get("head", "mlp") == head
        ),
        key=lambda d: d["model"]["pixels"],
    )
    match = next((d for d in baselines if d["error"]["ci95"][0] <= ref["error"]["ci95"][1]), None)
    px = ref["model"]["pixels"]
    largest = baselines[-1]["model"]["pixels"] if baselines else None
    return {
        "reference": reference,
        "baseline": None if match is None else "x".join(map(str, match["model"]["grid"])),
        "factor": None if match is None else match["model"]["pixels"] / px,
        "largest_tried_factor": None if largest is None else largest / px,
    }


def study_summary(result: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """Per design: ``rmse_mean``/``rmse_ci95`` (or ``error_rate_*``), ``seeds``, ``converged``.

    An error rate also gives ``accuracy_mean``/``accuracy_ci95`` (one minus it);
    an RMSE in a unit also ``rmse_<unit>_mean``/``rmse_<unit>_ci95`` (traffic: mph).
    """
    kind = "rmse" if result["error_name"].endswith("RMSE") else "error_rate"
    unit = _headline_unit(result) if kind == "rmse" else ""
    out = {}
    for name, d in result["designs"].items():
        mean, (lo, hi) = d["error"]["mean"], d["error"]["ci95"]
        row: dict[str, Any] = {f"{kind}_mean": mean, f"{kind}_ci95": [lo, hi]}
        if kind == "error_rate":
            row |= {"accuracy_mean": 1.0 - mean, "accuracy_ci95": [1.0 - hi, 1.0 - lo]}
        elif unit:
            row |= {f"rmse_{unit}_mean": mean, f"rmse_{unit}_ci95": [lo, hi]}
        out[name] = row | {"seeds": len(d["error_per_seed"]), "converged": d["converged"]}
    return out


def _headline_unit(result: Mapping[str, Any]) -> str:
    """The unit of the headline's labels (``""`` when unknown or unitless)."""
    episodes: Mapping[str, Any] = result.get("trivial", {}).get("episodes") or {}
    first: Mapping[str, Any] = next(iter(episodes.values()), {})
    names = first.get("headline", {}).get("labels", [])
    units = {result.get("labels", {}).get(n, {}).get("unit", "") for n in names}
    return units.pop() if len(units) == 1 else ""


def label_table(result: Mapping[str, Any], element_names: Mapping[str, Sequence[str]]) -> str:
    """Markdown: every label's figure per design (mean [95 % CI]), per element where several.

    Args:
        result: :func:`run_comparison`'s output with ``labels``.
        element_names: ``{label: names}`` for the element columns (lighting's lights);
            missing: element indices.
    """
    columns: list[tuple[str, Mapping[str, Any], str]] = []
    for label, lab in result["labels"].items():
        what = (
            "RMSE" + (f" ({lab['unit']})" if lab["unit"] else "")
            if lab["metric"] == "rmse"
            else "accuracy"
        )
        columns.append((f"{label} {what}", lab["configs"], label))
        names = list(element_names.get(label, ()))
        for i, el in (lab.get("elements") or {}).items():
            title = names[int(i)] if int(i) < len(names) else i
            columns.append((f"{label}: {title}", el["configs"], label))
    lines = [
        "## Every label (mean over seeds [95 % CI])",
        "",
        "| design | " + " | ".join(c[0] for c in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for name in [*result["designs"], "trivial"]:
        cells = []
        for _, configs, _ in columns:
            c = configs.get(name)
            cells.append(
                "" if c is None else f"{c['mean']:.3f} [{c['ci95'][0]:.3f}, {c['ci95'][1]:.3f}]"
            )
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def study_table(result: Mapping[str, Any]) -> str:
    """Markdown tables of a comparison: per task, every design, the trivial predictor, verdicts.

    The headline task's table also has the reference's verdicts and reduction
    factor; every label's table and the label coverage follow.
    """
    tasks = result.get("tasks") or {result["task"]: result}
    sections = []
    for i, (task, block) in enumerate(tasks.items()):
        title = result["task"] if len(tasks) == 1 else f"{result['task']}, task {task}"
        sections.append(_design_table(block, title, result if i == 0 else {}))
    lines = ["\n\n".join(sections)]
    if len(tasks) > 1:
        lines += ["", _combined_table(result)]
    if "labels" in result:
        lines += ["", label_table(result, result.get("element_names", {}))]
    if "coverage" in result:
        lines += ["", coverage_table(result["coverage"])]
    return "\n".join(lines)


def _design_table(block: Mapping[str, Any], title: str, headline: Mapping[str, Any]) -> str:
    """One task's table; ``headline``: the result whose reference verdicts follow (or ``{}``)."""
    lines = [
        f"## {title}: test {block['error_name']} (mean over seeds, 95 % CI over "
        "seeds and test episodes)",
        "",
        "| design | pixels | error [95 % CI] | per seed | converged | steps | training (s) |",
        "|---|---:|---|---|---|---|---:|",
    ]
    for name, d in block["designs"].items():
        e = d["error"]
        lines.append(
            f"| {name} | {d['model']['pixels']} | {e['mean']:.3f} [{e['ci95'][0]:.3f}, "
            f"{e['ci95'][1]:.3f}] | {', '.join(f'{v:.3f}' for v in d['error_per_seed'])} | "
            f"{d['state']} | "
            f"{', '.join(map(str, d['steps']))} | {sum(d['train_wall_time_s']):.0f} |"
        )
    t = block["trivial"]["error"]
    lines += [
        f"| trivial predictor | 0 | {t['mean']:.3f} [{t['ci95'][0]:.3f}, {t['ci95'][1]:.3f}] "
        "| | | | |",
        "",
    ]
    if block.get("verdict"):
        lines.append(f"Verdict: {block['verdict']}.")
    for line in headline.get("reference_verdicts", []):
        lines.append(f"- {line}")
    rf = headline.get("reduction_factor")
    if rf is not None:
        lines.append(
            f"Reduction factor of {rf['reference']}: "
            + (
                f"{rf['factor']:g}x (matches baseline {rf['baseline']})"
                if rf["factor"] is not None
                else f"above {rf['largest_tried_factor']:g}x (no baseline tried matches it)"
            )
        )
    return "\n".join(lines)


def _combined_table(result: Mapping[str, Any]) -> str:
    """Each design as one camera for every task: its pixels and each task's figure."""
    tasks = list(result["tasks"])
    lines = [
        "## One camera for every task (a minimalist camera's pixels add up per task)",
        "",
        "| design | pixels | " + " | ".join(tasks) + " |",
        "|---|---:|" + "---|" * len(tasks),
    ]
    for name, c in result["combined"].items():
        cells = [
            f"{c['tasks'][t]['mean']:.3f} [{c['tasks'][t]['ci95'][0]:.3f}, "
            f"{c['tasks'][t]['ci95'][1]:.3f}]"
            for t in tasks
        ]
        lines.append(f"| {name} | {c['pixels']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def reference_verdicts(result: Mapping[str, Any], reference: str) -> list[str]:
    """The reference design against every baseline: a verdict only where intervals separate.

    Each verdict is followed by the paired difference on the same test episodes
    (:func:`~mincam_render.analysis.statistics.paired_difference`) where the
    result keeps per-episode errors (studies from before it do not).
    """
    designs = result["designs"]
    ref = designs[reference]
    iv = Interval(ref["error"]["mean"], *ref["error"]["ci95"])
    seed = int(result.get("config", {}).get("seed", 0))
    lines = []
    for name, d in designs.items():
        if not _is_baseline(d):
            continue
        other = Interval(d["error"]["mean"], *d["error"]["ci95"])
        lines.append(verdict(reference, iv, name, other))
        if "episode_errors" in ref and "episode_errors" in d:
            diff = paired_difference(
                EpisodeErrors.from_dict(ref["episode_errors"]),
                EpisodeErrors.from_dict(d["episode_errors"]),
                seed=seed,
            )
            lines.append(paired_statement(reference, name, diff))
    return lines


def summarise_study(result: ComparisonResult, reference: str) -> ComparisonResult:
    """``result`` with a study's reduction factor, per-design summary and reference verdicts."""
    figures = result.as_json()
    study = StudySummary(
        reduction_factor=ReductionFactor(**reduction_factor(figures, reference)),
        configurations=study_summary(figures),
        reference_verdicts=tuple(reference_verdicts(figures, reference)),
    )
    return dataclasses.replace(result, study=study)


def _hidden(path: Path) -> bool:
    return path.name.startswith(".")


def _entry_in(folder: Path, path: str | Path) -> str:
    """The name of the entry of ``folder`` that holds ``path`` (a run in ``runs/<task>/``)."""
    return Path(path).resolve().relative_to(folder.resolve()).parts[0]


def others_in_folders(folders: Mapping[str, tuple[Path, set[str]]]) -> dict[str, Any]:
    """What the comparison's folders hold besides its own entries (earlier comparisons' left).

    Args:
        folders: ``{kind: (folder, names of this comparison's entries in it)}``.

    Returns:
        ``{kind: [other entries' names]}`` of the kinds that hold others, and a
        ``note`` when any does: ``metrics.json`` lists what its folder holds, so
        nobody prints the masks of another comparison's design for this one's.
    """
    others = {
        kind: sorted(p.name for p in folder.iterdir() if not (p.name in ours or _hidden(p)))
        for kind, (folder, ours) in folders.items()
        if folder.is_dir()
    }
    listed: dict[str, Any] = {kind: names for kind, names in others.items() if names}
    if listed:
        listed["note"] = (
            "left in these folders by an earlier comparison with other options: not of this "
            "one, and not in its figures"
        )
    return listed
