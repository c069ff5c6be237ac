"""The design protocol: how to train masks that generalise, and what they must beat.

Every section is a set of comparisons
(:func:`mincam_render.studies.comparison.study.run`) on one shared set
of episodes: validation and test episodes are the same everywhere, training
sets are the first ``n`` training episodes, so every figure of a section is
measured on the same test episodes and pairs with the others.

1. **Per task against joint** (:func:`protocol_table`): each label's figure of
   a camera per task (the paper's) beside one joint camera of the same pixels
   and one of the per-task cameras' total.
2. **Recipes** (:func:`recipe_table`): variants of the recipe, each design's
   pooled validation error and test error, the paired test difference from the
   base recipe, and which variant validation would choose.
3. **Learning curves** (:func:`learning_curves`): error against training
   episodes (and render and training seconds), and where another doubling
   stops paying.
4. **References** (:func:`reference_table`): end-to-end masks against PCA, PLS
   and distilled masks of the same pixels, each also tuned end to end.
5. **Oracle** (:func:`oracle_point`): the learning curves' designs on the
   most episodes with the background known exactly: the information limit.
6. **Restarts** (:func:`restart_table`): the minimalist designs' seed spread,
   plain against the best of several restarts chosen on validation.
7. **Selection** (:func:`selection_agreement`): how well the pooled validation
   error ranks runs and designs against their test error.
8. **Floors** (:func:`floor_checks`): the configured floors (a design against a
   box camera, with a margin) on the learning curves' largest training set;
   also on its test episodes rendered with more samples (:func:`retested_point`).

Everything resumes: comparisons keep their finished runs on disk.
"""

from __future__ import annotations

import dataclasses
import enum
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any
from typing import Protocol as Interface

import numpy as np

from mincam_render.analysis.statistics import (
    EpisodeErrors,
    EpisodeErrorsJson,
    Interval,
    bootstrap_interval,
)
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.comparison import study as comparison_study
from mincam_render.studies.comparison.config import ComparisonConfig, Protocol
from mincam_render.studies.comparison.figures import DesignFigure, Paired
from mincam_render.studies.comparison.result import ComparisonResult
from mincam_render.studies.comparison.runs import copy_runs_afresh
from mincam_render.studies.comparison.study import Design
from mincam_render.studies.design_protocol.config import (
    DesignProtocolConfig,
    Floor,
    RecipeVariant,
)

if TYPE_CHECKING:
    from mincam_render.data.render_job.request import RenderRequest


class Compare(Interface):
    """A comparison run for the study: ``(config, out_dir[, test episodes]) -> its result``."""

    def __call__(
        self, comparison: ComparisonConfig, where: Path, tests: Path | None = None
    ) -> ComparisonResult:
        """The comparison's result in ``where``; tested on ``tests`` when given."""


@dataclass(frozen=True)
class ProtocolRow:
    """One label's figure under each camera of the per-task against joint table.

    Args:
        label: the label.
        metric: ``rmse`` or ``accuracy``.
        figures: ``{camera: (mean, (lo, hi))}``; cameras are ``per-task <design>``
            and ``joint <design>``.
    """

    label: str
    metric: str
    figures: Mapping[str, tuple[float, tuple[float, float]]]


@dataclass(frozen=True)
class RecipeRow:
    """One recipe variant: every design's figures and its paired differences from the base.

    ``versus_base`` on the test episodes, ``versus_base_validation`` on the
    validation episodes (what choosing a recipe may look at).
    """

    variant: str
    changes: Mapping[str, Any]
    designs: Mapping[str, DesignFigure]
    versus_base: Mapping[str, Paired]
    versus_base_validation: Mapping[str, Paired]


@dataclass(frozen=True)
class LadderPoint:
    """The designs trained on the first ``episodes`` training episodes."""

    episodes: int
    frames: int
    render_s: float
    designs: Mapping[str, DesignFigure]
    trivial: float


@dataclass(frozen=True)
class Doubling:
    """What doubling the training episodes bought a design: paired on the same test episodes."""

    design: str
    episodes: tuple[int, int]
    change: Paired
    relative: float

    @property
    def pays(self) -> bool:
        """The larger training set is lower on the same test episodes (interval below 0)."""
        return self.change.a_lower


@dataclass(frozen=True)
class ReferenceRow:
    """End-to-end masks of ``pixels`` against the reference masks of as many pixels.

    ``recipe``: the recipe every design of the row trained with.
    """

    pixels: int
    designs: Mapping[str, DesignFigure]
    versus_end_to_end: Mapping[str, Paired]
    recipe: str = "base"


@dataclass(frozen=True)
class ChosenRestarts:
    """The cameras restarts keep: each group's run of lowest validation error.

    Args:
        runs: the kept run of each group (indices among the design's runs).
        per_seed: each kept run's test error.
        error: mean over the kept runs of the test error pooled over test episodes.
        ci95: its 95 % interval (kept runs and test episodes).
        episode_errors: the kept runs' errors on each test episode.
    """

    runs: tuple[int, ...]
    per_seed: tuple[float, ...]
    error: float
    ci95: tuple[float, float]
    episode_errors: EpisodeErrorsJson


@dataclass(frozen=True)
class Restarts:
    """Restarts chosen on validation against plain seeds (the seed spread, section 6).

    Args:
        design: the minimalist design.
        restarts: runs per kept camera; the one with the lowest validation error is kept.
        plain: the first ``seeds`` runs as plain seeds (one camera each).
        chosen: each group of ``restarts`` runs reduced to its validation pick.
        spread_plain: standard deviation over cameras of the plain seeds' test error.
        spread_chosen: the same over the picked cameras.
        train_s_per_camera: training time of one kept camera (s): a run, or
            ``restarts`` runs.
    """

    design: str
    restarts: int
    plain: DesignFigure
    chosen: ChosenRestarts
    spread_plain: float
    spread_chosen: float
    train_s_per_camera: tuple[float, float]


@dataclass(frozen=True)
class Selection:
    """Spearman rank correlation of pooled validation error with test error."""

    runs: int
    runs_spearman: float
    designs: int
    designs_spearman: float


class FloorVerdict(enum.StrEnum):
    """Where a floor's paired interval lies against its margin."""

    MET = "met"  # the whole interval below the margin
    MISSED = "missed"  # the whole interval at or above it
    UNDECIDED = "undecided"  # the interval holds the margin: the test episodes cannot tell


@dataclass(frozen=True)
class FloorCheck:
    """A floor on the learning curves' largest training set (section 8).

    Args:
        floor: the design, baseline and margin.
        episodes: training episodes of the comparison it was measured on.
        paired: ``design - baseline`` on the same test episodes.
        verdict: met, missed or undecided.
        test_factor: samples of the test renders relative to the plan's (1:
            the plan's tests; see ``DesignProtocolConfig.floor_test_factors``).
    """

    floor: Floor
    episodes: int
    paired: Paired
    verdict: FloorVerdict
    test_factor: float = 1.0


@dataclass(frozen=True)
class DesignProtocolResult:
    """Every section's figures (:mod:`~mincam_render.studies.design_protocol.study`)."""

    config: Mapping[str, Any]
    task: str
    error_name: str
    protocol: Sequence[ProtocolRow] = ()
    recipes: Sequence[RecipeRow] = ()
    chosen_recipe: Mapping[str, str] = field(default_factory=dict)
    ladder: Sequence[LadderPoint] = ()
    doublings: Sequence[Doubling] = ()
    references: Sequence[ReferenceRow] = ()
    oracle: LadderPoint | None = None
    restarts: Sequence[Restarts] = ()
    selection: Selection | None = None
    floors: Sequence[FloorCheck] = ()
    #: The largest point's runs on its tests rendered again, by samples factor (``"4x"``).
    retested: Mapping[str, LadderPoint] = field(default_factory=dict)
    versions: Mapping[str, str] = field(default_factory=dict)

    def as_json(self) -> JsonObject:
        """JSON-ready dict (every record as its fields)."""
        return json.loads(json.dumps(dataclasses.asdict(self), default=str))


def protocol_table(cfg: DesignProtocolConfig, compare: Compare, out: Path) -> list[ProtocolRow]:
    """Each label under per-task cameras and joint cameras (module docstring, section 1).

    For every per-task budget ``k``: per-task cameras of ``k`` pixels (every
    task), joint cameras of ``k`` and of ``k`` times the number of tasks.
    """
    n = cfg.protocol_episodes
    per_task = compare(
        cfg.comparison(n, _minimalist(cfg.protocol_pixels), protocol=Protocol.PER_TASK),
        out / "protocol" / "per-task",
    )
    tasks = len(per_task.tasks)
    joint_px = sorted({p for k in cfg.protocol_pixels for p in (k, k * tasks)})
    joint = compare(
        cfg.comparison(n, _minimalist(joint_px), protocol=Protocol.JOINT),
        out / "protocol" / "joint",
    )
    rows = []
    for label, lab in per_task.labels.items():
        figures = {f"per-task {d}": _mean_ci(c) for d, c in lab.configs.items()}
        figures |= {f"joint {d}": _mean_ci(c) for d, c in joint.labels[label].configs.items()}
        rows.append(ProtocolRow(label=label, metric=lab.metric, figures=figures))
    return rows


def _minimalist(pixels: Sequence[int]) -> tuple[Design, ...]:
    """Minimalist designs of ``pixels``."""
    return tuple(Design(pixels=k) for k in pixels)


def _mean_ci(c: Interval) -> tuple[float, tuple[float, float]]:
    return c.mean, (c.low, c.high)


def recipe_table(
    cfg: DesignProtocolConfig, compare: Compare, out: Path
) -> tuple[list[RecipeRow], dict[str, str]]:
    """Every recipe variant on the validation and test episodes (section 2).

    Runs are kept in ``out/recipes/<variant>``, but a variant that trains what
    the learning curves' point of ``recipe_episodes`` trains (the base, when
    that count is on the ladder) is that point's comparison (:func:`ladder_dir`):
    trained once for both sections.

    Returns:
        ``(rows, chosen)``: ``chosen[design]`` is the recipe validation picks:
        among the variants lower than the base on the validation episodes (the
        paired interval below 0), the one with the lowest validation error; the
        base where no variant is. A diagnostic (``RecipeVariant.diagnostic``) is never picked.
    """
    rows: list[RecipeRow] = []
    for variant in cfg.recipes:
        designs = _recipe_designs(cfg, variant)
        where = out / "recipes" / variant.name
        if _is_ladder_point(cfg, variant):
            where = ladder_dir(out, cfg.recipe_episodes)  # trained once for both sections
        result = compare(_recipe_comparison(cfg, variant), where)
        block = result.block(cfg.task)
        figures = {d.name: block.figure(d.name) for d in designs}
        base = rows[0].designs if rows else figures
        rows.append(
            RecipeRow(
                variant=variant.name,
                changes=dict(variant.changes),
                designs=figures,
                versus_base={n: Paired.of(f, base[n]) for n, f in figures.items()},
                versus_base_validation={
                    n: _paired_validation(f, base[n]) for n, f in figures.items()
                },
            )
        )
    return rows, chosen_recipes(cfg, rows)


def chosen_recipes(cfg: DesignProtocolConfig, rows: Sequence[RecipeRow]) -> dict[str, str]:
    """``{design: variant}`` validation picks from ``rows`` (:func:`recipe_table`).

    A diagnostic (``RecipeVariant.diagnostic``) is no recipe and never picked.
    """
    diagnostics = {v.name for v in cfg.recipes if v.diagnostic}
    candidates = [r for r in rows if r.variant not in diagnostics]
    return {d.name: _chosen(candidates, d.name) for d in cfg.ladder_designs}


def _recipe_designs(cfg: DesignProtocolConfig, variant: RecipeVariant) -> tuple[Design, ...]:
    """The designs ``variant`` is tried on (a mask-only change: the minimalist ones)."""
    if variant.baselines_only:
        return tuple(d for d in cfg.ladder_designs if not d.is_mincam)
    return tuple(d for d in cfg.ladder_designs if d.is_mincam or not variant.minimalist_only)


def _recipe_comparison(cfg: DesignProtocolConfig, variant: RecipeVariant) -> ComparisonConfig:
    """What ``variant`` trains on the recipes' episodes."""
    train = variant.apply(cfg.episodes.train)
    return cfg.comparison(cfg.recipe_episodes, _recipe_designs(cfg, variant), train=train)


def _is_ladder_point(cfg: DesignProtocolConfig, variant: RecipeVariant) -> bool:
    """Whether ``variant`` trains what the learning curves' point of ``recipe_episodes`` does."""
    n = cfg.recipe_episodes
    return n in cfg.ladder and _recipe_comparison(cfg, variant) == cfg.comparison(
        n, cfg.ladder_designs
    )


def ladder_dir(out: Path, n: int) -> Path:
    """The comparison of the learning curves' point of ``n`` training episodes."""
    return out / "ladder" / f"episodes-{n}"


def _paired_validation(a: DesignFigure, b: DesignFigure) -> Paired:
    va, vb = a.val(), b.val()
    if va is None or vb is None:
        raise ValueError(f"{a.design}: the runs kept no validation-episode errors")
    return Paired.between(a.design, va, b.design, vb)


def _chosen(rows: Sequence[RecipeRow], design: str) -> str:
    """The variant validation picks for ``design`` (:func:`recipe_table`)."""
    better = [
        r for r in rows[1:] if design in r.designs and r.versus_base_validation[design].a_lower
    ]
    if not better:
        return rows[0].variant
    return min(better, key=lambda r: r.designs[design].val_error or np.inf).variant


def learning_curves(
    cfg: DesignProtocolConfig,
    compare: Compare,
    out: Path,
    render_seconds: Callable[[int], float],
) -> tuple[list[LadderPoint], list[Doubling]]:
    """Error against training episodes, and what each doubling bought (section 3).

    Args:
        cfg: the study.
        compare: runs a comparison.
        out: the study's directory.
        render_seconds: render wall time (s) of the first ``n`` training episodes.
    """
    points = []
    for n in cfg.ladder:
        result = compare(cfg.comparison(n, cfg.ladder_designs), ladder_dir(out, n))
        points.append(_ladder_point(cfg, n, result, render_seconds(n)))
    doublings = [
        Doubling(
            design=name,
            episodes=(a.episodes, b.episodes),
            change=Paired.of(b.designs[name], a.designs[name]),
            relative=b.designs[name].error / a.designs[name].error - 1.0,
        )
        for a, b in zip(points, points[1:], strict=False)
        for name in a.designs
    ]
    return points, doublings


def _ladder_point(
    cfg: DesignProtocolConfig, n: int, result: ComparisonResult, render_s: float
) -> LadderPoint:
    """The ladder's designs in ``result``, trained on ``n`` episodes."""
    block = result.block(cfg.task)
    return LadderPoint(
        episodes=n,
        frames=n * cfg.episodes.train_frames,
        render_s=render_s,
        designs={d.name: block.figure(d.name) for d in cfg.ladder_designs},
        trivial=block.trivial_error.mean,
    )


def floor_checks(
    cfg: DesignProtocolConfig, point: LadderPoint, test_factor: float = 1.0
) -> list[FloorCheck]:
    """Every configured floor on ``point`` (the learning curves' largest training set).

    ``test_factor``: the samples of ``point``'s test renders relative to the plan's.
    """
    checks = []
    for f in cfg.floors:
        paired = Paired.of(point.designs[f.design], point.designs[f.baseline])
        low, high = paired.ci95
        verdict = (
            FloorVerdict.MET
            if high < f.margin
            else FloorVerdict.MISSED
            if low >= f.margin
            else FloorVerdict.UNDECIDED
        )
        checks.append(FloorCheck(f, point.episodes, paired, verdict, test_factor))
    return checks


def _check_oracle(episodes: ComparisonConfig) -> None:
    """Refuse, before any work, an oracle of a family with no background to know exactly.

    Raises:
        ValueError: the family renders no differential background (patches, traffic).
    """
    from mincam_render.render.capabilities import DifferentialBackground
    from mincam_render.scenes.registry import load_family

    family = load_family(episodes.family, seed=0, num_frames=30, overrides=dict(episodes.overrides))
    if not isinstance(family, DifferentialBackground):
        raise ValueError(
            f"oracle: family {family.name!r} renders no background apart from its movers "
            "(no differential background); leave 'oracle' out of the sections"
        )


def oracle_point(cfg: DesignProtocolConfig, compare: Compare, out: Path) -> LadderPoint:
    """The ladder's designs on the most episodes, with the background known exactly (oracle).

    Every frame's converged background replaced by one fixed background
    (:attr:`~mincam_render.studies.comparison.config.ComparisonConfig.oracle_background`):
    what remains of the error is the people's own signal, its render noise and
    the data, not the light changing around them.
    """
    n = cfg.ladder[-1]
    result = compare(
        cfg.comparison(n, cfg.ladder_designs, oracle_background=True),
        out / "oracle" / f"episodes-{n}",
    )
    return _ladder_point(cfg, n, result, 0.0)


def retested_point(
    cfg: DesignProtocolConfig,
    compare: Compare,
    out: Path,
    episodes: Path,
    factor: float,
    *,
    progress: bool = False,
) -> LadderPoint:
    """The learning curves' largest point tested on renders with ``factor`` x the samples.

    The test episodes are rendered again (resumable) into ``out/tests-<f>x``
    (:func:`retest_requests`); the point's runs are copied afresh into
    ``out/ladder/episodes-<n>-tests-<f>x`` (nothing is trained again; the
    ladder's runs are left as they are) and tested there.
    """
    from mincam_render.data.render_job import render_dataset

    n = cfg.ladder[-1]
    comparison = cfg.comparison(n, cfg.ladder_designs)
    tests = out / f"tests-{factor:g}x"
    for name, again in retest_requests(cfg, episodes, factor).items():
        render_dataset(again, tests / name, workers=2, progress=progress)
    ladder = ladder_dir(out, n)
    here = ladder.with_name(f"{ladder.name}-tests-{factor:g}x")
    copy_runs_afresh(ladder / "runs", here / "runs")
    return _ladder_point(cfg, n, compare(comparison, here, tests), 0.0)


def retest_requests(
    cfg: DesignProtocolConfig, episodes: Path, factor: float
) -> dict[str, RenderRequest]:
    """The test episodes' requests at ``factor`` x the plan's samples, full path depth.

    Each is the episode's own request (rendered in ``episodes``, or planned
    now) rescaled by ``factor`` over the episodes' own
    :attr:`~DesignProtocolConfig.episodes_factor`
    (:func:`~mincam_render.data.render_job.rescale.rescaled_request`), so the
    factor counts from the plan also when the episodes render at a multiple of
    it: episodes at 4x retested at 16 are the task-fidelity check's ``16x``
    (the same samples whenever the episodes' samples times the ratio are whole,
    as for any whole factors; otherwise they may differ by a rounding).
    """
    from mincam_render.data.render_job.rescale import rescaled_request

    relative = factor / cfg.episodes_factor
    requests = comparison_study.episode_requests(cfg.comparison(cfg.ladder[-1], cfg.ladder_designs))
    return {
        name: rescaled_request(request, episodes / name, relative)
        for name, request in requests.items()
        if name.startswith("test-")
    }


def restart_table(cfg: DesignProtocolConfig, compare: Compare, out: Path) -> list[Restarts]:
    """Restarts chosen on validation against plain seeds, on the most episodes (section 6).

    Each minimalist design of the ladder is trained with ``seeds x restarts``
    seeds; group ``g`` (runs ``g R .. g R + R - 1``) keeps its run with the
    lowest error pooled over the validation episodes, so there are as many
    kept cameras as plain seeds, each costing ``R`` runs. The first ``seeds``
    runs are the ladder point's (copied from it where it has finished them).
    """
    from dataclasses import replace as _replace

    seeds, r = cfg.episodes.seeds, cfg.restarts
    designs = tuple(d for d in cfg.ladder_designs if d.is_mincam)
    n = cfg.ladder[-1]
    folder = out / "restarts" / f"episodes-{n}"
    _reuse_ladder_runs(ladder_dir(out, n), folder, cfg.task, designs, seeds)
    result = compare(_replace(cfg.comparison(n, designs), seeds=seeds * r), folder)
    block = result.block(cfg.task)
    rows = []
    for d in designs:
        every = block.figure(d.name)
        test, val = every.errors(), every.val()
        if val is None:
            raise ValueError(f"{d.name}: the runs kept no validation-episode errors")
        episodes = np.arange(len(val.frames))
        picks = [
            min(range(g * r, g * r + r), key=lambda i: val.pooled(np.array([i]), episodes))
            for g in range(seeds)
        ]
        chosen = EpisodeErrors(test.error[picks], test.frames, test.pooling)
        plain = EpisodeErrors(test.error[:seeds], test.frames, test.pooling)
        iv = bootstrap_interval(chosen)
        rows.append(
            Restarts(
                design=d.name,
                restarts=r,
                plain=_with_errors(every, plain, every.per_seed[:seeds]),
                chosen=ChosenRestarts(
                    runs=tuple(picks),
                    per_seed=tuple(every.per_seed[i] for i in picks),
                    error=iv.mean,
                    ci95=(iv.low, iv.high),
                    episode_errors=chosen.as_dict(),
                ),
                spread_plain=float(np.std(every.per_seed[:seeds], ddof=1)),
                spread_chosen=float(np.std([every.per_seed[i] for i in picks], ddof=1)),
                train_s_per_camera=(every.train_s_per_run, every.train_s_per_run * r),
            )
        )
    return rows


def _reuse_ladder_runs(
    ladder: Path, folder: Path, task: str, designs: Sequence[Design], seeds: int
) -> None:
    """Copy the ladder point's finished runs of the first ``seeds`` into ``folder``'s runs.

    A design's run ``i`` trains with the same seed in any comparison of the same
    episodes and recipe, so the restarts' first seeds are the ladder's runs:
    copied, they resume as finished instead of training again (a run of other
    data or recipe would be refused there, not reused). Runs already in
    ``folder`` are kept; a copy is complete or absent (copied beside, then
    renamed).
    """
    import os
    import shutil

    from mincam_render.studies.comparison.runs import design_run_finished

    for d in designs:
        for i in range(seeds):
            for name in (f"{d.name}-seed{i}", f"{task}/{d.name}-seed{i}"):  # one task or several
                src, dst = ladder / "runs" / name, folder / "runs" / name
                if dst.exists() or not design_run_finished(src, d):
                    continue
                partial = dst.with_name(dst.name + ".copying")
                shutil.rmtree(partial, ignore_errors=True)
                shutil.copytree(src, partial)
                os.replace(partial, dst)


def _with_errors(
    figure: DesignFigure, errors: EpisodeErrors, per_seed: tuple[float, ...]
) -> DesignFigure:
    """``figure`` with the test errors of only some of its runs (``errors``, ``per_seed``)."""
    iv = bootstrap_interval(errors)
    return dataclasses.replace(figure, per_seed=per_seed, error=iv.mean, ci95=(iv.low, iv.high),
                               episode_errors=errors.as_dict())  # fmt: skip


def reference_table(cfg: DesignProtocolConfig, compare: Compare, out: Path) -> list[ReferenceRow]:
    """End-to-end masks against reference masks of the same pixels (section 4)."""
    rows = []
    for k in cfg.reference_pixels:
        designs = [Design(pixels=k)]
        for ref in cfg.references:
            designs += [
                Design(pixels=k, reference=ref),
                Design(pixels=k, reference=ref, tuned=True),
            ]
        result = compare(_reference_comparison(cfg, tuple(designs)), reference_dir(cfg, out, k))
        block = result.block(cfg.task)
        figures = {d.name: block.figure(d.name) for d in designs}
        e2e = figures[designs[0].name]
        rows.append(
            ReferenceRow(
                pixels=k,
                recipe=cfg.reference_recipe.name if cfg.reference_recipe else "base",
                designs=figures,
                versus_end_to_end={
                    n: Paired.of(e2e, f) for n, f in figures.items() if f is not e2e
                },
            )
        )
    return rows


def _reference_comparison(
    cfg: DesignProtocolConfig, designs: tuple[Design, ...]
) -> ComparisonConfig:
    """What the references section trains: ``designs`` with the reference recipe."""
    recipe = cfg.reference_recipe
    train = recipe.apply(cfg.episodes.train) if recipe else cfg.episodes.train
    return cfg.comparison(cfg.reference_episodes, designs, train=train)


def reference_dir(cfg: DesignProtocolConfig, out: Path, pixels: int) -> Path:
    """The references section's comparison at ``pixels`` (``-<recipe>`` unless the base)."""
    recipe = cfg.reference_recipe
    return out / "references" / (f"{pixels}px-{recipe.name}" if recipe else f"{pixels}px")


def selection_agreement(figures: Sequence[DesignFigure]) -> Selection:
    """How the pooled validation error ranks runs, and designs, against their test error.

    Runs and designs without a recorded validation error are left out.
    """
    from scipy.stats import spearmanr

    runs_val, runs_test, means_val, means_test = [], [], [], []
    for f in figures:
        if f.val_error is None:
            continue
        runs_val += list(f.val_per_seed)
        runs_test += list(f.per_seed)
        means_val.append(f.val_error)
        means_test.append(f.error)
    return Selection(
        runs=len(runs_val),
        runs_spearman=float(spearmanr(runs_val, runs_test).statistic),
        designs=len(means_val),
        designs_spearman=float(spearmanr(means_val, means_test).statistic),
    )


def run(
    cfg: DesignProtocolConfig,
    out: str | Path,
    *,
    episodes_dir: str | Path | None = None,
    sections: Sequence[str] = ("protocol", "recipes", "ladder", "references"),
    train_workers: int = 1,
    render_seconds: Callable[[int], float] | None = None,
    progress: bool = False,
) -> DesignProtocolResult:
    """Run the study's ``sections`` into ``out`` (resumable); its figures.

    Args:
        cfg: the study.
        out: directory of every comparison (``out/<section>/<name>/``).
        episodes_dir: the shared episodes (default ``out/episodes``).
        sections: which sections to run, of ``protocol``, ``recipes``,
            ``ladder``, ``references``, ``oracle``, ``restarts``.
        train_workers: local worker processes per comparison's training.
        render_seconds: render wall time of the first ``n`` training episodes
            (default: read from their render logs).
        progress: progress bars.
    """
    from mincam_render.data.render_job import package_versions

    if cfg.floor_test_factors and "ladder" not in sections:
        raise ValueError("floor_test_factors retest the ladder's largest point: run 'ladder'")
    if "oracle" in sections:
        _check_oracle(cfg.episodes)
    out = Path(out)
    episodes = Path(episodes_dir) if episodes_dir is not None else out / "episodes"

    error_names: dict[str, str] = {}

    def compare(
        comparison: ComparisonConfig, where: Path, tests: Path | None = None
    ) -> ComparisonResult:
        result = comparison_study.run(comparison, where, episodes_dir=episodes, masks_dir=None,
                                      train_workers=train_workers, progress=progress,
                                      test_episodes_dir=tests)  # fmt: skip
        error_names.setdefault("task", result.block(cfg.task).error_name)
        return result

    seconds = render_seconds or (lambda n: training_render_seconds(episodes, n))
    replace = dataclasses.replace
    result = DesignProtocolResult(
        config=json.loads(json.dumps(dataclasses.asdict(cfg), default=str)),
        task=cfg.task,
        error_name="",
        versions=package_versions(),
    )
    if "protocol" in sections:
        result = replace(result, protocol=protocol_table(cfg, compare, out))
    if "recipes" in sections:
        recipes, chosen = recipe_table(cfg, compare, out)
        result = replace(result, recipes=recipes, chosen_recipe=chosen)
    if "ladder" in sections:
        ladder, doublings = learning_curves(cfg, compare, out, seconds)
        floors, retested = floor_checks(cfg, ladder[-1], cfg.episodes_factor), {}
        for factor in cfg.floor_test_factors:
            point = retested_point(cfg, compare, out, episodes, factor, progress=progress)
            retested[f"{factor:g}x"] = point
            floors += floor_checks(cfg, point, factor)
        result = replace(result, ladder=ladder, doublings=doublings, floors=floors,
                         retested=retested)  # fmt: skip
    if "references" in sections:
        result = replace(result, references=reference_table(cfg, compare, out))
    if "oracle" in sections:
        result = replace(result, oracle=oracle_point(cfg, compare, out))
    if "restarts" in sections:
        result = replace(result, restarts=restart_table(cfg, compare, out))
    figures = [f for p in result.ladder for f in p.designs.values()]
    ran = cfg.recipes[: len(result.recipes)]  # a recipe row that is a ladder point counts once
    for row, variant in zip(result.recipes, ran, strict=True):
        if not (result.ladder and _is_ladder_point(cfg, variant)):
            figures += row.designs.values()
    selection = selection_agreement(figures) if figures else None
    return replace(result, error_name=error_names.get("task", ""), selection=selection)


def training_render_seconds(episodes: Path, n: int) -> float:
    """Render wall time (s) of training episodes ``train-0 .. train-(n-1)`` from their logs.

    The sum of the planning, background and shard-rendering times each
    episode's ``render_log.jsonl`` records (resumed attempts included).
    """
    from mincam_render.data.dataset import LOG_NAME

    total = 0.0
    for i in range(n):
        for line in (episodes / f"train-{i}" / LOG_NAME).read_text().splitlines():
            event = json.loads(line)
            if event["event"] in ("planned", "backgrounds") or (
                event["event"] == "end" and event.get("rendered")
            ):
                total += float(event["seconds"])
    return total
