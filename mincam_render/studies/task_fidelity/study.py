"""The task-level check of a fidelity plan: do the task figures move with more samples?

A plan's render error is judged where it matters, in task units. The plan's
episodes (train, validation and test: the same scene seeds) are rendered again
at other fidelities (:class:`~.config.SampleLevel`: a factor on the plan's
samples of frames and backgrounds, the full path depth, per-window or per-frame
seeds of ``X - C``); at every level the same designs are trained *and* tested
with the same seeds (noise in training data can be learned, so testing alone
on better renders does not settle it):

1. **Figures per level** (:func:`level_figures`): each design's test figure
   with its 95 % interval over seeds and test episodes, render seconds per
   frame (the Pareto in task units), and the level's render error against the
   reference (or a test level above it: :func:`noise_reference`) beside the
   label signal (:mod:`.noise`), with its autocorrelation at lags of one frame
   and one background window.
2. **Acceptance** (:func:`acceptance`): a level is *accepted* against the
   reference when every design's figure moves by less than ``acceptance_share``
   of the half-width of its own 95 % interval; the paired difference on the
   same test episodes (training seeds resampled) is reported beside it, and a
   *replicate* (the same renders, other training seeds) measures how far
   training seeds alone move a figure: where the replicate itself would not be
   accepted, the quarter-interval criterion cannot tell fidelities apart at
   this size. A design's move is *within seed noise* when its paired interval
   holds 0; a level is *supported* when every design is accepted or within
   seed noise (:meth:`TaskFidelityResult.verdict`).
3. **The target** (:func:`chosen_level`): the cheapest supported level with the
   plan's seeds; its error relative to the label signal (random masks) is the
   loosest target the task check supports.
4. **Training noise or test noise** (:func:`cross_figures`, ``cfg.cross``):
   runs trained at one level tested on another's test episodes, paired with
   the same runs on their own tests (what test-data noise changes) and with the
   runs trained at the other level (what training-data noise changes). A test
   level (``cfg.test_levels``) has only its test episodes rendered: what better
   test renders alone would change, for a fraction of a level's render.

Everything resumes: training runs are kept on disk.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
from collections.abc import Callable, Mapping
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.comparison.figures import DesignFigure, Paired
from mincam_render.studies.comparison.runs import copy_runs_afresh
from mincam_render.studies.task_fidelity.config import SampleLevel, TaskFidelityConfig
from mincam_render.studies.task_fidelity.noise import NoiseFigures, noise_figures

if TYPE_CHECKING:
    from mincam_render.data.render_job import RenderRequest


@dataclass(frozen=True)
class LevelFigures:
    """One level's task figures, render cost and render error.

    ``designs`` are trained with the comparison's seeds, ``replicate`` with the
    replicate's (None without): the same renders, other training seeds.
    ``between``: every two designs paired on the level's test episodes.
    """

    level: str
    factor: float
    difference_seeds: str
    render_s_per_frame: float
    designs: Mapping[str, DesignFigure]
    trivial: float
    noise: NoiseFigures | None
    replicate: Mapping[str, DesignFigure] | None = None
    between: Mapping[str, Paired] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class Acceptance:
    """One design at one level against the reference: how far its figure moved.

    Args:
        design: the design.
        moved: its figure at the level less at the reference.
        half_width: half the width of its 95 % interval at the level.
        share: the acceptance share of ``half_width``.
        passes: ``|moved|`` below ``share`` of ``half_width``.
        paired: the paired difference (level - reference) on the same test
            episodes, training seeds resampled on both sides.
        replicate_moved: at the level, the replicate's figure less the
            design's: how far other training seeds alone move it (None without).
    """

    design: str
    moved: float
    half_width: float
    share: float
    passes: bool
    paired: Paired
    replicate_moved: float | None = None

    @property
    def within_seed_noise(self) -> bool:
        """No change the data resolve: the paired interval (seeds resampled) holds 0."""
        lo, hi = self.paired.ci95
        return lo <= 0.0 <= hi


@dataclass(frozen=True)
class CrossFigures:
    """Runs trained at one level tested on another level's test episodes (same scene seeds).

    Args:
        trained: the level the runs were trained (and validated) at.
        tested: the level whose test episodes they are tested on.
        designs: each design's figure there.
        test_noise: per design, these figures less the same runs' on their own
            level's test episodes (paired by episode): what the test data's
            render noise changes.
        train_noise: per design, these figures less those of the runs trained
            at ``tested`` on the same test episodes: what the training data's
            render noise changes; None when ``tested`` is a test level (not trained).
        between: every two designs' paired difference on these test episodes
            (``"a - b"``, in the designs' order): how they rank on other renders.
    """

    trained: str
    tested: str
    designs: Mapping[str, DesignFigure]
    test_noise: Mapping[str, Paired]
    train_noise: Mapping[str, Paired] | None
    between: Mapping[str, Paired]


@dataclass(frozen=True)
class TaskFidelityResult:
    """The check's figures (:mod:`~mincam_render.studies.task_fidelity.study`)."""

    config: Mapping[str, Any]
    task: str
    error_name: str
    levels: tuple[LevelFigures, ...]
    acceptance: Mapping[str, tuple[Acceptance, ...]]
    chosen: str | None
    versions: Mapping[str, str]
    cross: tuple[CrossFigures, ...] = ()

    def accepted(self, level: str) -> bool:
        """Every design's figure at ``level`` within the share of its interval."""
        return all(a.passes for a in self.acceptance[level])

    def verdict(self, level: str) -> dict[str, bool]:
        """``accepted``, ``within_seed_noise`` (every design), ``supported`` (each either).

        Also ``criterion_resolves``: the replicate (other training seeds, same
        renders) would itself be accepted; where it is not, the quarter-interval
        criterion cannot tell a fidelity apart from training seeds at this size.
        """
        checks = self.acceptance[level]
        return {
            "accepted": self.accepted(level),
            "within_seed_noise": all(a.within_seed_noise for a in checks),
            "supported": supported(checks),
            "criterion_resolves": all(
                a.replicate_moved is not None and abs(a.replicate_moved) < a.share * a.half_width
                for a in checks
            ),
        }

    def as_json(self) -> JsonObject:
        """JSON-ready dict (every record as its fields) with every level's verdict."""
        out = json.loads(json.dumps(dataclasses.asdict(self), default=str))
        out["verdicts"] = {name: self.verdict(name) for name in self.acceptance}
        return out


def supported(checks: tuple[Acceptance, ...]) -> bool:
    """Every design accepted, or its move within what other training seeds make."""
    return all(a.passes or a.within_seed_noise for a in checks)


def level_requests(cfg: TaskFidelityConfig, level: SampleLevel) -> dict[str, RenderRequest]:
    """``{episode: RenderRequest}`` of a level: the plan's, or its samples times the factor.

    A level other than the plan renders with full fidelity and explicit
    settings (:func:`~mincam_render.data.render_job.rescale.rescaled_request`):
    the plan's (as the plan's episode was rendered, else looked up or
    measured) with frames' and backgrounds' samples scaled, the level's depth
    and seeds.
    """
    from mincam_render.data.render_job.rescale import rescaled_request
    from mincam_render.studies.comparison.study import episode_requests

    requests = episode_requests(cfg.comparison)
    if level.planned:
        return dict(requests)
    return {
        name: rescaled_request(
            request,
            cfg.plan.episodes / name,
            level.factor,
            max_depth=level.max_depth,
            difference_seeds=level.difference_seeds,
        )
        for name, request in requests.items()
    }


def render_level(
    cfg: TaskFidelityConfig,
    level: SampleLevel,
    *,
    hold: Callable[[], AbstractContextManager[Any]] = contextlib.nullcontext,
    workers: int = 2,
) -> None:
    """Render (or resume) a level's episodes, one at a time, each inside ``hold()``.

    Of a test level (``cfg.test_levels``) only the test episodes. ``hold``: e.g.
    a lock on the machine's CPUs, so other jobs interleave.
    """
    from mincam_render.data.render_job import render_dataset

    tests_only = level in cfg.test_levels
    for name, request in level_requests(cfg, level).items():
        if tests_only and not name.startswith("test-"):
            continue
        with hold():
            render_dataset(request, level.episodes / name, workers=workers, progress=False)


def level_figures(
    cfg: TaskFidelityConfig,
    level: SampleLevel,
    out: Path,
    *,
    train_workers: int = 1,
    progress: bool = False,
) -> tuple[LevelFigures, str]:
    """Train and test every design on a level's episodes; its figures and the error's name.

    Runs go to ``out/<level>/runs`` (kept: a second call reads them back).
    """
    names = episode_names(cfg)
    tested = _tested_designs(
        cfg, lambda n: level.episodes / n, out / level.name, train_workers, progress
    )
    figures = LevelFigures(
        level=level.name,
        factor=level.factor,
        difference_seeds=level.difference_seeds.value,
        render_s_per_frame=render_seconds_per_frame([level.episodes / n for n in names]),
        designs=tested.designs,
        trivial=tested.trivial,
        noise=None,
        replicate=tested.replicate,
        between=between_designs(tested.designs),
    )
    return figures, tested.error_name


def cross_figures(
    cfg: TaskFidelityConfig,
    trained: SampleLevel,
    tested: SampleLevel,
    out: Path,
    own: Mapping[str, LevelFigures],
    *,
    progress: bool = False,
) -> CrossFigures:
    """``trained``'s runs (copied to ``out/<trained>-on-<tested>``) tested on ``tested``'s tests.

    ``own``: every trained level's figures on its own episodes. The runs are
    copied afresh on every call (a copy of runs trained again since, or a copy
    a kill cut short, is replaced), read back like any kept run and evaluated
    on the other test episodes; the runs of ``out/<trained>`` are left as they
    are. The paired intervals resample training seeds on both sides
    independently, also where both sides are the same runs (``test_noise``):
    conservative there.
    """
    here = out / f"{trained.name}-on-{tested.name}"
    copy_runs_afresh(out / trained.name / "runs", here / "runs")

    def episodes(name: str) -> Path:
        return (tested if name.startswith("test-") else trained).episodes / name

    designs = _tested_designs(cfg, episodes, here, 1, progress, replicate=False).designs
    mine = own[trained.name].designs
    there = own.get(tested.name)
    return CrossFigures(
        trained=trained.name,
        tested=tested.name,
        designs=dict(designs),
        test_noise={d: _between(f, tested, mine[d], trained) for d, f in designs.items()},
        train_noise=None
        if there is None
        else {d: _between(f, trained, there.designs[d], tested) for d, f in designs.items()},
        between=between_designs(designs),
    )


def between_designs(designs: Mapping[str, DesignFigure]) -> dict[str, Paired]:
    """Every two designs' paired difference (``a - b``, in order) on their common test episodes."""
    names = list(designs)
    return {
        p.key: p
        for i, a in enumerate(names)
        for p in (Paired.of(designs[a], designs[b]) for b in names[i + 1 :])
    }


def _between(a: DesignFigure, a_is: SampleLevel, b: DesignFigure, b_is: SampleLevel) -> Paired:
    """``a - b`` of one design's runs tested two ways, each named by what it is."""
    return Paired.between(f"{a.design} ({a_is.name})", a.errors(),
                          f"{b.design} ({b_is.name})", b.errors())  # fmt: skip


@dataclass(frozen=True)
class _Tested:
    """Every design's test figure (comparison seeds), the trivial predictor's, the replicate's."""

    designs: dict[str, DesignFigure]
    trivial: float
    replicate: dict[str, DesignFigure] | None
    error_name: str


def _tested_designs(
    cfg: TaskFidelityConfig,
    episodes: Callable[[str], Path],
    out: Path,
    train_workers: int,
    progress: bool,
    *,
    replicate: bool = True,
) -> _Tested:
    """Train (or read back) every run into ``out/runs`` and test it on the test episodes.

    ``episodes``: the dataset of each episode name. ``replicate``: the
    replicate's runs too (their seeds come after the comparison's, so leaving
    them out leaves the comparison's runs as they are).
    """
    from mincam_render.analysis.mask_structure import view_and_label_map
    from mincam_render.core.labels import label_tasks
    from mincam_render.data.dataset import open_dataset
    from mincam_render.learn.train import TrainingData
    from mincam_render.studies.comparison.runs import task_splits, train_runs
    from mincam_render.studies.comparison.study import comparison_splits, task_comparison

    comparison = cfg.comparison
    data = {
        n: TrainingData.from_dataset(open_dataset(episodes(n)), n.split("-")[0])
        for n in episode_names(cfg)
    }
    splits = comparison_splits(data)
    trained = cfg.trained if replicate else comparison
    runs = train_runs(trained, splits, out, train_workers=train_workers, progress=progress)
    labels = comparison.task_labels(label_tasks(splits.train.label_specs))
    task = next(iter(labels))
    task_data = task_splits(splits, labels[task])
    view_map = view_and_label_map(task_data.train)
    n = comparison.seeds
    block = task_comparison(comparison, {d: rs[:n] for d, rs in runs[task].items()},
                            task_data, view_map)  # fmt: skip
    others = None
    if replicate and cfg.replicate_seeds:
        rep = task_comparison(comparison, {d: rs[n:] for d, rs in runs[task].items()},
                              task_data, view_map)  # fmt: skip
        others = {d.name: rep.figure(d.name) for d in comparison.designs}
    designs = {d.name: block.figure(d.name) for d in comparison.designs}
    return _Tested(designs, block.trivial_error.mean, others, block.error_name)


def episode_names(cfg: TaskFidelityConfig) -> list[str]:
    """The episodes of the check (``train-*``, ``val-*``, ``test-*``)."""
    from mincam_render.studies.comparison.study import episode_requests

    return list(episode_requests(cfg.comparison))


def render_seconds_per_frame(paths: list[Path]) -> float:
    """Render wall time per frame of episodes: backgrounds and frames, planning left out.

    From each episode's ``render_log.jsonl``: the wall time of every attempt that
    rendered shards (it holds the backgrounds too) less the planning's.
    """
    from mincam_render.data.dataset import LOG_NAME, read_manifest

    seconds, frames = 0.0, 0
    for path in paths:
        frames += int(read_manifest(path)["num_frames"])
        for line in (path / LOG_NAME).read_text().splitlines():
            event = json.loads(line)
            if event["event"] == "end" and event.get("rendered"):
                seconds += float(event["seconds"])
            elif event["event"] == "planned":
                seconds -= float(event["seconds"])
    return seconds / max(frames, 1)


def acceptance(
    level: LevelFigures, reference: Mapping[str, DesignFigure], share: float
) -> tuple[Acceptance, ...]:
    """Every design at a level against the reference (module docstring, step 2)."""
    out = []
    for name, fig in level.designs.items():
        ref = reference[name]
        half = 0.5 * (fig.ci95[1] - fig.ci95[0])
        moved = fig.error - ref.error
        rep = None if level.replicate is None else level.replicate[name].error - fig.error
        out.append(
            Acceptance(
                design=name,
                moved=moved,
                half_width=half,
                share=share,
                passes=abs(moved) < share * half,
                paired=Paired.of(fig, ref),
                replicate_moved=rep,
            )
        )
    return tuple(out)


def chosen_level(cfg: TaskFidelityConfig, accepted: Mapping[str, bool]) -> str | None:
    """The cheapest level with the plan's seeds that ``accepted`` holds (or None)."""
    plan_seeds = cfg.plan.difference_seeds
    candidates = [
        lv
        for lv in cfg.levels
        if lv.name != cfg.reference
        and lv.difference_seeds is plan_seeds
        and accepted.get(lv.name, False)
    ]
    return min(candidates, key=lambda lv: lv.factor).name if candidates else None


def run(
    cfg: TaskFidelityConfig,
    out: str | Path,
    *,
    train_workers: int = 1,
    hold: Callable[[], AbstractContextManager[Any]] = contextlib.nullcontext,
    progress: bool = False,
) -> TaskFidelityResult:
    """Train, test and measure every level (episodes rendered already); the check's figures.

    Args:
        cfg: the check.
        out: directory of every level's runs (``out/<level>/runs``).
        train_workers: local worker processes per level's training.
        hold: a context held around each level's training (a CPU lock).
        progress: progress bars.
    """
    from mincam_render.data.render_job import package_versions

    out = Path(out)
    figures: dict[str, LevelFigures] = {}
    error_name = ""
    for level in cfg.levels:
        with hold():
            fig, error_name = level_figures(
                cfg, level, out, train_workers=train_workers, progress=progress
            )
        figures[level.name] = dataclasses.replace(fig, noise=_noise(cfg, level))
    cross = []
    for trained, tested in cfg.cross:
        with hold():
            cross.append(cross_figures(cfg, cfg.level(trained), cfg.level(tested), out, figures,
                                       progress=progress))  # fmt: skip
    ref = figures[cfg.reference].designs
    checks = {
        name: acceptance(f, ref, cfg.acceptance_share)
        for name, f in figures.items()
        if name != cfg.reference
    }
    held = {name: supported(c) for name, c in checks.items()}
    return TaskFidelityResult(
        config=json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        task=next(iter(cfg.comparison.tasks), ""),
        error_name=error_name,
        levels=tuple(figures.values()),
        acceptance=checks,
        chosen=chosen_level(cfg, held),
        versions=package_versions(),
        cross=tuple(cross),
    )


def noise_reference(cfg: TaskFidelityConfig) -> SampleLevel:
    """What render noise is measured against: the check's reference, or a test level above it.

    A test level with more samples than the reference, its seeds and path depth
    otherwise the reference's, has the test episodes the noise is measured on,
    so the noise of every trained level, the reference's included, is taken
    against the one of those with the most samples.
    """
    ref = cfg.level(cfg.reference)
    above = [
        lv
        for lv in cfg.test_levels
        if lv.difference_seeds is ref.difference_seeds
        and lv.max_depth == ref.max_depth
        and lv.factor > ref.factor
    ]
    return max(above, key=lambda lv: lv.factor) if above else ref


def _noise(cfg: TaskFidelityConfig, level: SampleLevel) -> NoiseFigures | None:
    """The level's render error on the noise episodes against :func:`noise_reference`.

    That reference has none of its own (None), unless it is the plan (a reduced
    check without a level above it): then the plan is measured against the
    second reference, a cheaper level, its share of the difference's power
    taken by samples (:func:`.noise.noise_figures`). The label signal's second
    estimate is the second reference's render, or the level's own when the
    level is the second reference: the two renders' noises are independent, so
    their covariance leaves them out.
    """
    ref = noise_reference(cfg)
    if level.name == ref.name:
        if not level.planned or cfg.second_reference is None:
            return None
        ref = cfg.level(cfg.second_reference)
    second = None
    if cfg.second_reference is not None:
        other = level if cfg.second_reference == ref.name else cfg.level(cfg.second_reference)
        second = [other.episodes / n for n in cfg.noise_episodes]
    return noise_figures(
        ([level.episodes / n for n in cfg.noise_episodes], level.factor),
        ([ref.episodes / n for n in cfg.noise_episodes], ref.factor, ref.name),
        second,
        window_frames=cfg.window_frames,
    )
