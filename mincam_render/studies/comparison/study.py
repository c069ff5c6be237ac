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
   :mod:`mincam_render.analysis.coverage`) and ``comparison.png``
   (:func:`~.report.write_report`).

:func:`run` takes the frozen :class:`~.config.ComparisonConfig` and returns the
frozen, typed :class:`~.result.ComparisonResult`.

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

from mincam_render.analysis.coverage import study_coverage
from mincam_render.analysis.mask_structure import (
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
from mincam_render.export.masks import MaskFiles, export_masks
from mincam_render.learn.evaluation import Evaluation
from mincam_render.learn.train import TrainingData, metrics, run_masks
from mincam_render.learn.train_config import ModelKind

# Design is re-exported: callers build designs and comparisons from this module
from mincam_render.studies.comparison.config import ComparisonConfig
from mincam_render.studies.comparison.config import Design as Design
from mincam_render.studies.comparison.figures import Paired
from mincam_render.studies.comparison.records import (
    Convergence,
    DesignRecord,
    EpisodeRecord,
    ErrorFigures,
    FolderOthers,
    KeptMasks,
    LabelFigures,
    TrivialFigures,
)
from mincam_render.studies.comparison.report import write_report
from mincam_render.studies.comparison.result import (
    CombinedCamera,
    ComparisonResult,
    DesignSummary,
    ReductionFactor,
    StudySummary,
    TaskComparison,
)
from mincam_render.studies.comparison.runs import (
    ComparisonRun,
    RunsByTask,
    Splits,
    task_splits,
    train_runs,
)

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
    tests_dir: Path | None = None,
) -> dict[str, TrainingData]:
    """Render (or resume) every episode into ``episodes_dir/<name>``; their training views.

    The views are at ``cfg.light_scale`` times the rendered light; for
    ``cfg.oracle_background`` every frame's converged background is replaced by
    one fixed background (the first episode's mean). ``ray_address``:
    render the shards as Ray tasks there (``workers`` is then ignored).
    ``tests_dir``: the test episodes' views are read from ``tests_dir/<name>``
    instead, finished renders of the same scenes at another fidelity
    (:func:`~mincam_render.data.render_job.rescale.same_scene`, checked).
    """
    from mincam_render.data.render_job.backgrounds import converged_backgrounds
    from mincam_render.data.render_job.rescale import same_scene

    data = {}
    fixed: np.ndarray | None = None
    for name, request in episode_requests(cfg).items():
        path = episodes_dir / name
        render_dataset(request, path, workers=workers, ray_address=ray_address, progress=progress)
        role = name.split("-")[0]
        if tests_dir is not None and role == "test":
            same_scene(path, tests_dir / name)
            path = tests_dir / name
        view = TrainingData.from_dataset(open_dataset(path), role)
        if cfg.oracle_background:  # one fixed background: the first episode's mean
            static = converged_backgrounds(path)[slice(*view.source["range"])]
            fixed = static.mean(axis=0) if fixed is None else fixed
            view = view.with_static_part(static, fixed)
        data[name] = view if cfg.light_scale == 1.0 else view.with_light_scaled(cfg.light_scale)
    return data


def comparison_splits(data: Mapping[str, TrainingData]) -> Splits:
    """The training episodes joined, and the validation and test episodes by name."""
    return Splits(
        train=TrainingData.concat([v for k, v in data.items() if k.startswith("train-")]),
        val={k: v for k, v in data.items() if k.startswith("val-")},
        tests={k: v for k, v in data.items() if k.startswith("test-")},
    )


def episode_record(data: TrainingData) -> EpisodeRecord:
    """Samples, provenance and the sha256 of the episode dataset's manifest."""
    path = Path(data.source["dataset"]) / MANIFEST_NAME
    return EpisodeRecord(samples=len(data), source=dict(data.source),
                         manifest_sha256=sha256_file(path))  # fmt: skip


def _pooling(error_name: str) -> Pooling:
    return Pooling.RMS if error_name.endswith("RMSE") else Pooling.MEAN


#: Per configuration, each seed's metrics on each episode: ``{name: [{episode: metrics}]}``.
PerConfig = Mapping[str, Sequence[Mapping[str, Evaluation]]]


def _intervals(
    per_config: PerConfig, figure: Callable[[Evaluation], float], pooling: Pooling, seed: int
) -> dict[str, Interval]:
    """``{configuration: figure(episode metrics) and its interval}`` per configuration."""
    configs = {}
    for name, per_seed in per_config.items():
        names = sorted(per_seed[0])
        errors = EpisodeErrors(
            error=np.array([[figure(s[e]) for e in names] for s in per_seed]),
            frames=np.array([per_seed[0][e].samples for e in names]),
            pooling=pooling,
        )
        configs[name] = bootstrap_interval(errors, seed=seed)
    return configs


def _figure(episode: Evaluation, *, label: str, key: str, element: int | None = None) -> float:
    """Label ``label``'s figure ``key`` on an episode (its ``element``-th entry if given)."""
    value = getattr(episode.labels[label], key)
    return float(value if element is None else value[element])


def label_intervals(per_config: PerConfig, seed: int) -> dict[str, LabelFigures]:
    """Every label's figure with its 95 % interval, per configuration.

    Args:
        per_config: ``{configuration: [per-seed {episode: metrics}]}`` (runs'
            ``episodes``, or the trivial predictor's as a one-seed list).
        seed: bootstrap seed.

    Returns:
        ``{label: its figures}``: RMSE pooled as a root mean square over test
        frames, accuracy as a mean (higher is better); intervals resample seeds
        and episodes. A BINARY label of several elements (lighting's five
        lights) also has each element's accuracy.
    """
    first = next(iter(per_config.values()))[0]
    some = first[next(iter(first))].labels
    out: dict[str, LabelFigures] = {}
    for label, m in some.items():
        metric = "rmse" if m.accuracy is None else "accuracy"
        pooling = Pooling.RMS if metric == "rmse" else Pooling.MEAN
        configs = _intervals(per_config, partial(_figure, label=label, key=metric), pooling, seed)
        elements = None
        if len(m.accuracy_per_element or ()) > 1:
            elements = {
                str(i): _intervals(
                    per_config,
                    partial(_figure, label=label, key="accuracy_per_element", element=i),
                    Pooling.MEAN,
                    seed,
                )
                for i in range(len(m.accuracy_per_element or ()))
            }
        out[label] = LabelFigures(metric=metric, unit=m.unit, configs=configs, elements=elements)
    return out


def trivial_metrics(train: TrainingData, test: TrainingData) -> Evaluation:
    """Test metrics of the trivial predictor: every label's training mean (mode if binary).

    Its loss is NaN: the trivial predictor has no training loss
    (:func:`~.records.trivial_episode_json` writes it null, with that reason).
    """
    n = len(test)
    lab = test.sample_labels()
    pred = {}
    for s in test.label_specs:
        mean = train.labels[s.name].mean(axis=0)
        if s.kind is LabelKind.BINARY:
            mean = (mean >= 0.5).astype(np.float32)
        pred[s.name] = np.broadcast_to(mean, (n, s.size)).astype(np.float32)
    return metrics(pred, lab, float("nan"), test)


def episode_errors(per_seed: Sequence[Mapping[str, Evaluation]]) -> EpisodeErrors:
    """``EpisodeErrors`` of runs' (or the trivial predictor's) per-episode metrics."""
    first = per_seed[0]
    names = sorted(first)
    return EpisodeErrors(
        error=np.array([[m[e].error for e in names] for m in per_seed]),
        frames=np.array([first[e].samples for e in names]),
        pooling=_pooling(first[names[0]].error_name),
    )


def paired_differences(
    errors: Mapping[str, EpisodeErrors], compared: Sequence[str], seed: int
) -> dict[str, Paired]:
    """Paired differences on the same test episodes, beside the separate intervals.

    ``compared`` (the first two designs) against each other when there are two,
    and every design against the trivial predictor (``errors["trivial"]``).

    Returns:
        ``{"A - B": the difference}``.
    """
    pairs = [(n, "trivial") for n in errors if n != "trivial"]
    if len(compared) == 2:
        pairs.insert(0, (compared[0], compared[1]))
    out: dict[str, Paired] = {}
    for a, b in pairs:
        p = Paired.between(a, errors[a], b, errors[b], seed)
        out[p.key] = p
    return out


def _validation_figures(runs: Sequence[ComparisonRun]) -> ErrorFigures | None:
    """The kept states' error on each validation episode, pooled like the test error.

    The interval is over seeds and validation episodes; None for runs
    without named validation episodes.
    """
    episodes = [r.validation_episodes for r in runs]
    if not all(episodes):
        return None
    errors = episode_errors([e for e in episodes if e])
    return ErrorFigures(error=bootstrap_interval(errors), episode_errors=errors)


def _convergence(run: ComparisonRun) -> Convergence:
    """Whether ``run`` converged (:func:`converged` of its history) and stopped early."""
    record = converged(run.metrics.history)
    return Convergence.from_json(record | {"stopped_early": run.metrics.stopped_early})


def _design_record(
    runs: Sequence[ComparisonRun],
    interval: Interval,
    errors: EpisodeErrors,
    view_map: tuple[np.ndarray, np.ndarray],
) -> DesignRecord:
    """A design's figures over its runs; a minimalist design's masks' structure too.

    ``structure`` (:mod:`~mincam_render.analysis.mask_structure`) is that of
    the run with the lowest validation loss, whose masks a comparison keeps.
    """
    structure = None
    model = runs[0].metrics.model
    if ModelKind(model["kind"]) is ModelKind.MINCAM:
        best = min(runs, key=lambda r: r.metrics.best_val_loss)
        labels = tuple(next(iter(best.episodes.values())).labels)
        structure = run_structure(best.run_dir, view_map, labels)
    return DesignRecord(
        model=model,
        error=interval,
        episode_errors=errors,
        error_per_seed=tuple(episode_errors([r.episodes]).point() for r in runs),
        val_error_per_seed=tuple(r.kept_val_error() for r in runs),
        validation=_validation_figures(runs),
        convergence=tuple(_convergence(r) for r in runs),
        train_wall_time_s=tuple(r.metrics.train_wall_time_s for r in runs),
        steps=tuple(r.metrics.steps for r in runs),
        runs=tuple(r.run_dir for r in runs),
        structure=structure,
    )


def keep_run_masks(
    run_dir: str | os.PathLike, out_dir: Path, task: str, figures: Mapping[str, Any]
) -> MaskFiles:
    """Export ``run_dir``'s masks into ``out_dir``; the sidecar holds ``figures`` too.

    The sidecar's provenance: the run, its data, recipe and detectors, the
    package versions, then ``figures`` (how the run was chosen, its errors;
    JSON-ready, free-form).
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
    signed = bool(run["model"].get("signed", False))
    return export_masks(m, camera, out_dir, task=task, provenance=provenance, signed=signed)


def _keep_masks(
    runs: Sequence[ComparisonRun],
    record: DesignRecord,
    episodes: Mapping[str, EpisodeRecord],
    out_dir: Path,
    task: str,
    view_map: tuple[np.ndarray, np.ndarray],
) -> KeptMasks:
    """Export into ``out_dir`` the masks of the run with the lowest validation loss.

    Beside them, ``looks_at.png``: the masks over the camera's view and the
    task's label map, with their structure figures (also in the sidecar).
    """
    best = min(runs, key=lambda r: r.metrics.best_val_loss)
    structure = record.structure
    if structure is None:
        raise ValueError(f"{out_dir.name}: a baseline has no masks to keep")
    figures = {
        "chosen_by": "lowest validation loss of the training seeds",
        "test_error_over_seeds": record.error.as_dict(),
        "test_episodes": {k: e.as_json() for k, e in best.episodes.items()},
        "episodes": {k: e.as_json() for k, e in episodes.items()},
        "structure": dataclasses.asdict(structure),
    }
    kept = keep_run_masks(best.run_dir, out_dir, task, figures)
    masks, _, _ = run_masks(best.run_dir)
    png = plot_mask_views(masks, *view_map, structure, out_dir / "looks_at.png", title=task)
    return KeptMasks(png=tuple(str(p) for p in kept.png), exr=str(kept.exr), svg=str(kept.svg),
                     pdf=None if kept.pdf is None else str(kept.pdf), json=str(kept.json),
                     looks_at=str(png))  # fmt: skip


def run(
    cfg: ComparisonConfig,
    out_dir: str | os.PathLike,
    *,
    workers: int = 2,
    train_workers: int = 1,
    ray_address: str | None = None,
    masks_dir: str | os.PathLike | None = None,
    episodes_dir: str | os.PathLike | None = None,
    progress: bool = True,
    test_episodes_dir: str | os.PathLike | None = None,
) -> ComparisonResult:
    """Render, train, test and compare (module docstring); write its report; its result.

    Writes the episodes into ``episodes_dir`` (default ``out_dir/episodes/``; a
    shared directory lets comparisons at other light scales reuse one render),
    ``out_dir/runs/``, and, unless ``masks_dir`` is None, every minimalist
    design's best masks into ``masks_dir/<task>/<design>/``; then the report
    (:func:`~.report.write_report`: ``out_dir/metrics.json``, its
    :meth:`~.result.ComparisonResult.as_json`, and ``out_dir/comparison.png``).
    With ``test_episodes_dir`` the designs are tested on the test episodes
    there instead: renders of the same scenes at another fidelity, rendered
    already (e.g. at more samples, so the figures carry less render noise).
    The plan's own test episodes are still rendered into ``episodes_dir``
    (their manifests are what the others are checked against); runs finished
    in ``out_dir/runs`` are read back and tested again, missing ones trained.

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
        return _run(
            cfg,
            Path(out_dir),
            workers=workers,
            train_workers=train_workers,
            ray_address=ray_address,
            masks_dir=masks_dir,
            episodes_dir=episodes_dir,
            progress=progress,
            test_episodes_dir=test_episodes_dir,
        )


def _run(
    cfg: ComparisonConfig,
    out: Path,
    *,
    workers: int,
    train_workers: int,
    ray_address: str | None,
    masks_dir: str | os.PathLike | None,
    episodes_dir: str | os.PathLike | None,
    progress: bool,
    test_episodes_dir: str | os.PathLike | None,
) -> ComparisonResult:
    out.mkdir(parents=True, exist_ok=True)
    episodes = Path(episodes_dir) if episodes_dir is not None else out / "episodes"
    tests = Path(test_episodes_dir) if test_episodes_dir is not None else None
    data = render_episodes(
        cfg, episodes, workers=workers, ray_address=ray_address, progress=progress,
        tests_dir=tests,
    )  # fmt: skip
    splits = comparison_splits(data)
    family = Path(str(data["val-0"].source.get("family") or cfg.family)).stem
    # before training: a split that misses part of the label space is logged at once
    coverage = study_coverage(
        {"train": splits.train, **{k: v for k, v in data.items() if not k.startswith("train-")}}
    )
    runs = train_runs(
        cfg, splits, out, train_workers=train_workers, ray_address=ray_address, progress=progress
    )
    task_labels = cfg.task_labels(label_tasks(splits.train.label_specs))
    task_data = {task: task_splits(splits, task_labels[task]) for task in runs}
    maps = {task: view_and_label_map(d.train) for task, d in task_data.items()}
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
        element_names={s.name: tuple(s.element_names) for s in splits.train.label_specs},
        coverage=coverage,
        figure=str(out / "comparison.png"),
        versions=package_versions(),
    )
    result.write(out / "metrics.json")  # the figures, before the masks are kept
    if masks_dir is not None:
        masks = _keep_all_masks(cfg, runs, result, Path(masks_dir) / family, maps)
        result = dataclasses.replace(result, masks=masks)
    run_dirs = [r.run_dir for designs in runs.values() for rs in designs.values() for r in rs]
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
    write_report(result, out)
    return result


def task_comparison(
    cfg: ComparisonConfig,
    runs: Mapping[str, Sequence[ComparisonRun]],
    splits: Splits,
    view_map: tuple[np.ndarray, np.ndarray],
) -> TaskComparison:
    """One task's figures: every design, the trivial predictor, verdicts, every label.

    Args:
        cfg: the comparison (its first two designs are compared; its seed seeds
            the bootstrap).
        runs: ``{design: [its runs, seed by seed]}`` of cameras trained for the task.
        splits: the task's splits (its labels only, :func:`task_splits`).
        view_map: the training view and the task's label map
            (:func:`~mincam_render.analysis.mask_structure.view_and_label_map`).

    Returns:
        The task's figures.
    """
    trivial = {k: trivial_metrics(splits.train, d) for k, d in splits.tests.items()}
    errors = {name: episode_errors([r.episodes for r in rs]) for name, rs in runs.items()}
    errors["trivial"] = episode_errors([trivial])
    intervals = {name: bootstrap_interval(e, seed=cfg.seed) for name, e in errors.items()}
    trivial_iv = intervals.pop("trivial")
    names = [d.name for d in cfg.designs]
    return TaskComparison(
        error_name=next(iter(trivial.values())).error_name,
        designs={
            name: _design_record(rs, intervals[name], errors[name], view_map)
            for name, rs in runs.items()
        },
        trivial=TrivialFigures(
            error=trivial_iv, episode_errors=errors["trivial"], episodes=trivial
        ),  # fmt: skip
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
            {name: [r.episodes for r in rs] for name, rs in runs.items()} | {"trivial": [trivial]},
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
        first = blocks[next(iter(blocks))].designs[d.name].pixels
        out[d.name] = CombinedCamera(
            pixels=first * len(blocks) if d.is_mincam else first,
            tasks={t: b.designs[d.name].error for t, b in blocks.items()},
        )
    return out


def _keep_all_masks(
    cfg: ComparisonConfig,
    runs: RunsByTask,
    result: ComparisonResult,
    family_dir: Path,
    maps: Mapping[str, tuple[np.ndarray, np.ndarray]],
) -> dict[str, KeptMasks]:
    """Every minimalist design's best masks per task; their records.

    Into ``family_dir/<design>/`` for a single task (or a joint camera), into
    ``family_dir/<design>/<task>/`` for each of several tasks.
    """
    kept: dict[str, KeptMasks] = {}
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


def reduction_factor(block: TaskComparison, reference: str) -> ReductionFactor:
    """Pixel reduction of design ``reference`` at equal error (the paper's 256x, 2048x).

    The smallest baseline (with the reference's head) whose 95 % interval
    overlaps or lies below the reference's (its lower bound at most the
    reference's upper bound); the factor is its pixel count over the
    reference's. None when no baseline of the study comes that close (the
    factor then exceeds the largest tried).

    Raises:
        ValueError: ``reference`` is not a design of ``block``.
    """
    designs = block.designs
    if reference not in designs:
        raise ValueError(f"reference design {reference!r} not in the study: {sorted(designs)}")
    ref = designs[reference]
    baselines = sorted(
        (d for d in designs.values() if d.is_baseline and d.head == ref.head),
        key=lambda d: d.pixels,
    )
    match = next((d for d in baselines if d.error.low <= ref.error.high), None)
    largest = baselines[-1].pixels if baselines else None
    return ReductionFactor(
        reference=reference,
        baseline=None if match is None else "x".join(map(str, match.model["grid"])),
        factor=None if match is None else match.pixels / ref.pixels,
        largest_tried_factor=None if largest is None else largest / ref.pixels,
    )


def study_summary(
    block: TaskComparison, labels: Mapping[str, LabelFigures]
) -> dict[str, DesignSummary]:
    """Per design: its headline error and interval, seeds and whether every run converged.

    An RMSE in a unit (the headline's labels' shared unit, from ``labels``)
    also gives that unit (traffic: mph).
    """
    rate = not block.error_name.endswith("RMSE")
    unit = "" if rate else _headline_unit(block, labels)
    return {
        name: DesignSummary(
            error=d.error,
            error_rate=rate,
            unit=unit,
            seeds=len(d.error_per_seed),
            converged=d.converged,
        )  # fmt: skip
        for name, d in block.designs.items()
    }


def _headline_unit(block: TaskComparison, labels: Mapping[str, LabelFigures]) -> str:
    """The unit of the headline's labels (``""`` when unknown or unitless)."""
    first = next(iter(block.trivial.episodes.values()), None)
    names = [] if first is None else first.headline.labels
    units = {labels[n].unit if n in labels else "" for n in names}
    return units.pop() if len(units) == 1 else ""


def reference_verdicts(
    designs: Mapping[str, DesignRecord], reference: str, seed: int = 0
) -> list[str]:
    """The reference design against every baseline: a verdict only where intervals separate.

    Each verdict is followed by the paired difference on the same test episodes
    (:func:`~mincam_render.analysis.statistics.paired_difference`, bootstrap
    ``seed``) where the records keep per-episode errors (studies from before
    it do not).
    """
    ref = designs[reference]
    lines = []
    for name, d in designs.items():
        if not d.is_baseline:
            continue
        lines.append(verdict(reference, ref.error, name, d.error))
        if ref.episode_errors is not None and d.episode_errors is not None:
            diff = paired_difference(ref.episode_errors, d.episode_errors, seed=seed)
            lines.append(paired_statement(reference, name, diff))
    return lines


def summarise_study(result: ComparisonResult, reference: str) -> ComparisonResult:
    """``result`` with a study's reduction factor, per-design summary and reference verdicts."""
    block = result.headline
    study = StudySummary(
        reduction_factor=reduction_factor(block, reference),
        configurations=study_summary(block, result.labels),
        reference_verdicts=tuple(reference_verdicts(block.designs, reference, result.seed)),
    )
    return dataclasses.replace(result, study=study)


def _hidden(path: Path) -> bool:
    return path.name.startswith(".")


def _entry_in(folder: Path, path: str | Path) -> str:
    """The name of the entry of ``folder`` that holds ``path`` (a run in ``runs/<task>/``)."""
    return Path(path).resolve().relative_to(folder.resolve()).parts[0]


def others_in_folders(folders: Mapping[str, tuple[Path, set[str]]]) -> FolderOthers:
    """What the comparison's folders hold besides its own entries (earlier comparisons' left).

    Args:
        folders: ``{kind: (folder, names of this comparison's entries in it)}``.

    Returns:
        The other entries' names of the kinds that hold others:
        ``metrics.json`` lists what its folder holds (with a note), so nobody
        prints the masks of another comparison's design for this one's.
    """
    others = {
        kind: tuple(sorted(p.name for p in folder.iterdir() if not (p.name in ours or _hidden(p))))
        for kind, (folder, ours) in folders.items()
        if folder.is_dir()
    }
    return FolderOthers({kind: names for kind, names in others.items() if names})
