"""``pipeline`` and ``study``: camera designs compared on independent episodes.

The episode options fill
:class:`~mincam_render.studies.comparison.config.ComparisonConfig`, whose
defaults they show.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from mincam_render.core.strict_json import JsonObject
from mincam_render.learn.train_config import HeadKind
from mincam_render.studies.comparison.config import ComparisonConfig as C
from mincam_render.studies.comparison.config import Protocol

from .errors import user_error
from .options import (
    FiniteFloat,
    apply_options,
    executor_options,
    grid,
    grid_list,
    int_list,
    out_option,
    scene_settings,
    with_detectors,
)

if TYPE_CHECKING:
    from mincam_render.studies.comparison.config import Design
    from mincam_render.studies.comparison.result import ComparisonResult, TaskComparison

#: Options of the commands that render independent episodes and compare designs;
#: named like the ComparisonConfig fields they fill, except --steps (the training
#: recipe's max_steps), --workers and --spp (how episodes are rendered),
#: --train-workers and --ray (where runs train) and --detectors (a shorthand for
#: --set camera.detectors=N).
episode_options = apply_options([
    click.option("--family", default=C.family, show_default=True,
                 help="Scene family name, family class (module:Class) or scene description "
                 "(.toml)."),
    click.option("--set", "overrides", multiple=True, callback=scene_settings,
                 metavar="KEY=VALUE",
                 help="Override a scene description value in every episode (TOML syntax), "
                 "repeatable."),
    click.option("--detectors", type=click.IntRange(1, 64), default=None,
                 help="Detectors rendered per episode (same as --set camera.detectors=N; "
                 "default: the description's)."),
    click.option("--mask-res", type=click.IntRange(1, 4096), default=None,
                 help="Mask texels per side rendered (default: the family camera's); a "
                 "baseline grid can be at most this fine (64x64 needs 64)."),
    click.option("--light-scale", type=FiniteFloat(1e-9, 1e9), default=C.light_scale,
                 show_default=True,
                 help="Every emitter's radiance times this factor, applied to the rendered "
                 "episodes (transport is linear in it: no new render)."),
    click.option("--train-episodes", type=click.IntRange(1, 100),
                 default=C.train_episodes, show_default=True,
                 help="Training episodes (other scene seeds; a temporal task's windows "
                 "stay within one)."),
    click.option("--train-frames", type=click.IntRange(30), default=C.train_frames,
                 show_default=True,
                 help="Frames of each training episode (at --fps)."),
    click.option("--val-episodes", type=click.IntRange(1, 100), default=C.val_episodes,
                 show_default=True,
                 help="Validation episodes (other scene seeds), pooled for early stopping "
                 "and for choosing the kept masks."),
    click.option("--val-frames", type=click.IntRange(30), default=C.val_frames,
                 show_default=True,
                 help="Frames of each validation episode."),
    click.option("--protocol", type=click.Choice([p.value for p in Protocol]),
                 default=C.protocol.value, show_default=True,
                 callback=lambda ctx, param, value: Protocol(value),
                 help="per-task: a camera per task of the family, each with the design's "
                 "pixels (the paper's; workspace: people count, zones, door); joint: one "
                 "camera for every label."),
    click.option("--tasks", default="", callback=lambda ctx, param, value: _task_list(value),
                 metavar="TASK,...",
                 help="With --protocol per-task, train only these tasks (e.g. people_count); "
                 "default: every task of the family."),
    click.option("--test-frames", type=click.IntRange(30), default=C.test_frames,
                 show_default=True,
                 help="Frames of each test episode."),
    click.option("--test-episodes", type=click.IntRange(1, 100), default=C.test_episodes,
                 show_default=True, help="Independent test episodes (other scene seeds)."),
    click.option("--seeds", type=click.IntRange(1, 100), default=C.seeds, show_default=True,
                 help="Training seeds per camera design."),
    click.option("--seed", type=click.IntRange(0), default=C.seed, show_default=True,
                 help="Root random seed."),
    click.option("--steps", type=click.IntRange(1), default=C().train.max_steps,
                 show_default=True,
                 help="Training steps at most per run (early stopping on validation may "
                 "end sooner)."),
    click.option("--workers", type=click.IntRange(0), default=2, show_default=True,
                 help="Render worker processes (0 = in this process)."),
    click.option("--episodes-dir", type=click.Path(file_okay=False, path_type=Path),
                 default=None,
                 help="Where the episodes are rendered and read (default: OUT/episodes). "
                 "Studies sharing one directory render each episode once: an episode "
                 "there is reused when its render request is the same, and refused "
                 "otherwise."),
    *executor_options,
    click.option("--spp", type=click.IntRange(1, 1 << 20), default=None,
                 help="Render at a fixed quick fidelity (SPP samples per texel, every "
                 "detector, the scene's path depth) instead of the measured (auto) "
                 "fidelity."),
    click.option("--fps", type=FiniteFloat(0.1, 1000.0), default=C.fps,
                 show_default=True, help="Frame rate of the episodes (overrides the "
                 "family's): at 2 fps, 1,200 frames cover 10 minutes of activity."),
])  # fmt: skip


def _task_list(value: str) -> tuple[str, ...]:
    """``"people_count,zones"`` -> ``("people_count", "zones")`` (each once, in order)."""
    tasks = tuple(v.strip() for v in value.split(",") if v.strip())
    if len(set(tasks)) != len(tasks):
        raise click.BadParameter(f"{value!r}: give each task once")
    return tasks


def _head_list(value: str) -> list[HeadKind]:
    """``"mlp,tcn"`` -> ``[HeadKind.MLP, HeadKind.TCN]`` (each once, in order)."""
    try:
        heads = [HeadKind(v.strip().lower()) for v in value.split(",") if v.strip()]
    except ValueError:
        allowed = ",".join(h.value for h in HeadKind)
        raise click.BadParameter(f"{value!r}: allowed a list of {allowed}") from None
    if not heads or len(set(heads)) != len(heads):
        raise click.BadParameter(f"{value!r}: give each head once, e.g. mlp,tcn")
    return heads


def _family_detectors(family: str, overrides: JsonObject, detectors: int | None) -> int:
    """Detectors of the episodes' camera (the default pixel count), overrides applied.

    Args:
        family: the ``--family`` option.
        overrides: the ``--set`` scene overrides (a TOML table).
        detectors: the ``--detectors`` shorthand, or None.
    """
    from mincam_render.core.config import ConfigError
    from mincam_render.scenes.registry import load_family

    overrides = with_detectors(overrides, detectors)
    try:
        return (
            load_family(family, seed=0, num_frames=30, overrides=overrides).camera().num_detectors
        )
    except ConfigError as err:
        raise user_error(err) from None


def _compare(
    out: Path,
    designs: tuple[Design, ...],
    *,
    spp: int | None,
    steps: int,
    workers: int,
    train_workers: int,
    ray_address: str | None,
    overrides: JsonObject,
    detectors: int | None,
    episodes_dir: Path | None,
    **episode: Any,
) -> ComparisonResult:
    """Run the comparison (:func:`~mincam_render.studies.comparison.study.run`) of ``designs``.

    The episode options fill its config; prints its figures.
    """
    from mincam_render.core.config import ConfigError
    from mincam_render.data.ray_cluster import RayError
    from mincam_render.data.render_job import RenderError
    from mincam_render.data.run_dispatch import TrainingError
    from mincam_render.learn.train_config import TrainConfig
    from mincam_render.render.mitsuba_scene import SceneError
    from mincam_render.studies.comparison import study

    t0 = time.perf_counter()
    # a bad description fails here, on one line, before anything is printed or written
    _family_detectors(episode["family"], overrides, detectors)
    quick = {"spp": spp, "max_depth": 0, "shared_render": False, "differential": False}
    try:
        cfg = C(
            **episode,
            overrides=with_detectors(overrides, detectors),
            designs=designs,
            train=TrainConfig(max_steps=steps),
            fidelity=quick if spp is not None else {},
        )
        click.echo(
            f"[1/2] episodes of {cfg.family}: train {cfg.train_episodes} x {cfg.train_frames}, "
            f"val {cfg.val_episodes} x {cfg.val_frames}, "
            f"test {cfg.test_episodes} x {cfg.test_frames} frames; {len(designs)} designs x "
            f"{cfg.seeds} seeds"
        )
        result = study.run(
            cfg,
            out,
            workers=workers,
            train_workers=train_workers,
            ray_address=ray_address,
            masks_dir=out / "masks",
            episodes_dir=episodes_dir,
        )
    except (
        ConfigError, SceneError, RenderError, TrainingError, RayError, ValueError, OSError
    ) as err:  # fmt: skip
        raise user_error(err) from None
    _echo_comparison(result, cfg.seeds)
    click.echo(
        f"  {time.perf_counter() - t0:.0f} s; figure {result.figure}; masks in "
        f"{out / 'masks' / result.family}/; metrics {out / 'metrics.json'}"
    )
    return result


def _echo_comparison(result: ComparisonResult, seeds: int) -> None:
    """Per task: each design's test error [95 % CI], the trivial predictor's, verdicts."""
    tasks = result.tasks
    click.echo(f"[2/2] test error, mean over {seeds} seeds [95 % CI] ({result.protocol.value})")
    for task, block in tasks.items():
        if len(tasks) > 1:
            click.echo(f"  task {task}:")
        _echo_task(block)
    if len(tasks) > 1:
        for name, c in result.combined.items():
            click.echo(f"  {name} for every task: {c.pixels} pixels")
    if n := len(result.coverage.warnings):
        # each was logged before training; the summary only points at them
        click.echo(f"  label coverage: {n} warning(s), logged above and in metrics.json")


def _echo_task(block: TaskComparison) -> None:
    """One task's designs, trivial predictor, verdict and paired differences."""
    click.echo(f"  {block.error_name}:")
    for name in block.designs:
        f = block.figure(name)
        click.echo(
            f"  {name:18s} {f.error:.3f} [{f.ci95[0]:.3f}, {f.ci95[1]:.3f}]  "
            f"({f.state}; {block.train_seconds(name):.0f} s training)"
        )
    t = block.trivial_error
    click.echo(f"  {'trivial':18s} {t.mean:.3f} [{t.low:.3f}, {t.high:.3f}]")
    if block.verdict:
        click.echo(f"  verdict: {block.verdict}")
    for name, against in block.versus_trivial.items():
        click.echo(f"  {name} against the trivial predictor: {against}")
    for statement in block.paired_statements:
        click.echo(f"  {statement}")


@click.command("pipeline")
@episode_options
@out_option("Output directory (episodes, runs, figure, metrics, masks).", default="runs/main")
@click.option(
    "--pixels",
    type=click.IntRange(1, 64),
    default=None,
    help="Freeform pixels of the minimalist camera (default: the family's detectors).",
)
@click.option(
    "--baseline-grid",
    default="8x8",
    show_default=True,
    callback=grid,
    help="Baseline camera resolution ROWSxCOLS.",
)
def pipeline_cmd(
    out: Path, pixels: int | None, baseline_grid: tuple[int, int], **episode: Any
) -> None:
    """The main job: a minimalist camera against a conventional one, with a verdict that holds.

    Renders independent episodes of the family (other scene seeds) into
    OUT/episodes: TRAIN_EPISODES to train on, one to stop early on, TEST_EPISODES to test
    on, at the measured (auto) fidelity unless --spp is given. Trains a
    PIXELS-pixel minimalist camera and a baseline camera with SEEDS training
    seeds each (same recipe and budget), tests every run on every test
    episode with the paper's post-processing, and prints each design's error
    as mean over seeds with a 95 % bootstrap interval (over seeds and test
    episodes), the trivial predictor's, whether every run converged, and a
    verdict only where intervals separate. Keeps the best minimalist run's
    printable masks in OUT/masks/<family>/<design>/, writes OUT/comparison.png
    and OUT/metrics.json. Killed runs resume where they stopped.

    \b
    Example:
      mincam-render pipeline --out runs/main
      mincam-render pipeline --family patches --pixels 4 --baseline-grid 2x2
    """
    from mincam_render.studies.comparison.study import Design

    pixels = pixels or _family_detectors(
        episode["family"], episode["overrides"], episode["detectors"]
    )
    _compare(out, (Design(pixels=pixels), Design(grid=baseline_grid)), **episode)


@click.command("study")
@episode_options
@out_option("Output directory (episodes, runs, figure, metrics, table, masks).")
@click.option(
    "--pixels",
    default=None,
    callback=int_list,
    help="Minimalist-camera pixel counts (default: 1, 2, 4, ... up to the family's detectors).",
)
@click.option(
    "--baseline-grids",
    default="2x2,4x4,8x8,16x16,32x32",
    show_default=True,
    callback=grid_list,
    help="Baseline resolutions.",
)
@click.option(
    "--ablation/--no-ablation",
    default=False,
    help="Also train every minimalist camera's masks without the detector model, then a "
    "fresh head with it, tested with it (supplement A).",
)
@click.option(
    "--heads",
    default=HeadKind.MLP.value,
    show_default=True,
    callback=lambda ctx, param, value: _head_list(value),
    help="Inference networks, each trained for every design: mlp (the paper's stacked "
    "history), tcn (temporal convolutions), or mlp,tcn for both side by side.",
)
@click.option(
    "--reference-pixels",
    type=click.IntRange(1),
    default=4,
    show_default=True,
    help="Pixel count of the design whose pixel reduction factor is reported.",
)
def study_cmd(
    out: Path,
    pixels: list[int] | None,
    baseline_grids: list[tuple[int, int]],
    ablation: bool,
    heads: list[HeadKind],
    reference_pixels: int,
    **episode: Any,
) -> None:
    """A sweep of minimalist cameras against baselines on independent episodes.

    Like `pipeline`, with every design of --pixels (and, with --ablation, the
    same cameras trained without the detector model) and --baseline-grids;
    adds OUT/study.md (the table, with convergence and the trivial predictor)
    and the pixel reduction factor of the --reference-pixels camera: the
    baseline pixels of the smallest baseline whose interval overlaps or beats
    it, over its pixels.

    \b
    Example:
      mincam-render study --family patches --out runs/study-patches --spp 16 --train-workers 2
      mincam-render study --family traffic --fps 30 --train-episodes 1 --pixels 1,2,4,8 \\
          --baseline-grids 2x4,4x7,8x14 --heads mlp,tcn --out runs/study-traffic
    """
    from mincam_render.learn.train import default_pixel_counts
    from mincam_render.studies.comparison.report import study_table, write_report
    from mincam_render.studies.comparison.study import Design, summarise_study

    detectors = _family_detectors(episode["family"], episode["overrides"], episode["detectors"])
    pixels = pixels or default_pixel_counts(detectors)
    if reference_pixels not in pixels:
        raise click.BadParameter(
            f"{reference_pixels} is not among --pixels {pixels}", param_hint="--reference-pixels"
        )
    designs = []
    for head in heads:
        designs += [Design(pixels=k, head=head) for k in pixels]
        if ablation:
            designs += [Design(pixels=k, sensor_model=False, head=head) for k in pixels]
        designs += [Design(grid=g, head=head) for g in baseline_grids]
    reference = Design(pixels=reference_pixels, head=heads[0]).name
    result = summarise_study(_compare(out, tuple(designs), **episode), reference)
    write_report(result, out)
    click.echo(study_table(result))
