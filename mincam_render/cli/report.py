"""``mincam-render report``: reports comparing simulation with measurements, energy, robustness."""

from __future__ import annotations

from pathlib import Path

import click

from mincam_render.studies.privacy.config import AUDIT_DETECTORS, AUDIT_TEXELS, AttackConfig
from mincam_render.studies.robustness.config import RobustnessConfig

from .errors import InputError, user_error
from .options import (
    FiniteFloat,
    apply_options,
    executor_options,
    field_default,
    float_list,
    out_option,
)


@click.group("report")
def report_group() -> None:
    """Reports: sim2real, energy budget, robustness to tolerances, privacy audit."""


@report_group.command("sim2real")
@click.argument(
    "measurements", required=False, type=click.Path(file_okay=False, exists=True, path_type=Path)
)
@click.option(
    "--surrogate",
    "surrogate_family",
    default=None,
    help="Generate a SURROGATE-real recording of this family into OUT/surrogate_input "
    "and report on it (a demo without a prototype).",
)
@click.option(
    "--frames",
    "surrogate_frames",
    type=click.IntRange(20, 100000),
    default=300,
    show_default=True,
    help="Frames of the surrogate recording.",
)
@out_option("Output directory (created): sim2real.html and sim2real.json.", default="runs/sim2real")
@click.option(
    "--spp",
    type=click.IntRange(1, 1 << 20),
    default=4,
    show_default=True,
    help="Samples per texel of the simulation renders.",
)
@click.option(
    "--steps",
    type=click.IntRange(10, 10**6),
    default=1500,
    show_default=True,
    help="Training steps of each inference head.",
)
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=0,
    show_default=True,
)
def report_sim2real_cmd(measurements: Path | None, out: Path, **config: object) -> None:
    """Compare simulated with measured (or SURROGATE) freeform-pixel recordings.

    Give a recording directory (format: docs/sim2real_format.md), or --surrogate FAMILY.

    \b
    Example:
      mincam-render report sim2real --surrogate patches --frames 300 --out runs/s2r
      mincam-render report sim2real runs/s2r/surrogate_input --out runs/s2r-again
    """
    from mincam_render.core.config import ConfigError

    # the defaults above are Sim2RealConfig's (tests/cli/test_cli_io.py): importing it here,
    # not at the top, keeps scipy out of the command line's start-up
    from mincam_render.studies.sim2real import Sim2RealConfig, Sim2RealError, run, write_report

    if (measurements is None) == (config["surrogate_family"] is None):
        raise InputError("give a MEASUREMENTS directory or --surrogate FAMILY (one)")
    try:
        cfg = Sim2RealConfig(recording=measurements, **config)  # type: ignore[arg-type]
        result = run(cfg, out, progress=True)
        paths = write_report(result, out)
    except (ValueError, ConfigError, Sim2RealError, OSError) as err:
        raise user_error(err) from None
    click.echo(result.verdict.summary)
    click.echo(f"wrote {paths['json']} and {paths['html']}")


@report_group.command("energy")
@click.option(
    "--family",
    "families",
    multiple=True,
    default=("workspace", "lighting"),
    show_default=True,
    help="Indoor scene family (name or TOML path) to render the day in; repeat for several.",
)
@click.option(
    "--config",
    "config_path",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="Energy description (TOML); default: the shipped scenes/energy.toml.",
)
@click.option(
    "--spp",
    type=click.IntRange(1, 1 << 24),
    default=None,
    help="Samples per batch of the panel's irradiance meter (default: the description's).",
)
@click.option(
    "--studies",
    "studies_dir",
    type=click.Path(file_okay=False, exists=True, path_type=Path),
    default=None,
    help="Directory of study_<family>.json tables for the module at equal task error "
    "(default: the paper's matches).",
)
@out_option("Output directory (created): energy.json, energy.html, energy.png.", "runs/energy")
def report_energy_cmd(
    families: tuple[str, ...],
    config_path: Path | None,
    spp: int | None,
    studies_dir: Path | None,
    out: Path,
) -> None:
    """Can the camera run from the light its panel sees? Lux, frame rates, hours, margins.

    Renders the panel's light over a day in each scene, then reports the
    sustainable frame rate for 1..24 pixels, the hours at 30 fps, and the
    illuminance 24 pixels need at 30 fps beside the paper's ~600 lux.

    \b
    Example:
      mincam-render report energy --family workspace --spp 1024 --out runs/energy
      mincam-render report energy --studies benchmarks/results --out runs/energy
    """
    from mincam_render.core.config import ConfigError
    from mincam_render.studies.energy import headline, load_energy_config, run, write_report

    try:
        overrides = {"render": {"spp": spp}} if spp is not None else None
        config = load_energy_config(config_path, overrides)
        result = run(config, out, families=families, studies_dir=studies_dir)
        paths = write_report(result, out)
    except (ValueError, ConfigError, OSError) as err:
        raise user_error(err) from None
    click.echo(headline(result))
    click.echo(f"wrote {paths['json']}, {paths['html']} and {paths['png']}")


@report_group.command("robustness")
@click.argument("runs", nargs=-1, required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--data",
    "data_dirs",
    multiple=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Test dataset (its test split; repeat for several episodes) [default: each run's "
    "own test split].",
)
@click.option(
    "--levels",
    default=",".join(f"{v:g}" for v in field_default(RobustnessConfig, "levels")),
    show_default=True,
    callback=float_list,
    help="Magnitudes as multiples of the default ranges, increasing from 0.",
)
@click.option(
    "--draws",
    type=click.IntRange(2, 100000),
    default=field_default(RobustnessConfig, "draws"),
    show_default=True,
    help="Built cameras drawn per level (Monte Carlo).",
)
@click.option(
    "--allowed-increase",
    type=FiniteFloat(0, 10, min_open=True, max_open=True),
    default=field_default(RobustnessConfig, "allowed_increase"),
    show_default=True,
    help="Relative error increase a tolerance allows.",
)
@click.option(
    "--seed",
    type=click.IntRange(0),
    default=field_default(RobustnessConfig, "seed"),
    show_default=True,
    help="Seed of the draws (the same draws for every run).",
)
@out_option(
    "Output directory (created): robustness.html, .png and .json.", default="runs/robustness"
)
@click.option(
    "--allow-unfinished",
    is_flag=True,
    help="Report on runs whose training did not finish (their best state so far), named "
    "'(unfinished)' in the report.",
)
def report_robustness_cmd(
    runs: tuple[Path, ...],
    data_dirs: tuple[Path, ...],
    out: Path,
    allow_unfinished: bool,
    **config: object,
) -> None:
    """Trained designs under fabrication and detector perturbations: error, tolerance, spec.

    For each minimalist-camera RUN (from `mincam-render train`, nominal or
    --robust), the task error when each perturbation alone, and all at once,
    is LEVELS x its default range, over DRAWS built cameras per level; the
    tolerance of each design for an error increase within ALLOWED_INCREASE,
    written as a fabrication spec (docs/robustness.md).

    \b
    Example:
      mincam-render report robustness runs/ws8 runs/ws8-robust --data runs/ws/test \\
          --draws 20 --out runs/robustness
    """
    from mincam_render.studies.robustness import run, write_report

    try:
        cfg = RobustnessConfig(**config)  # type: ignore[arg-type]
        designs = run(runs, data_dirs, cfg, allow_unfinished=allow_unfinished)
        paths = write_report(designs, out)
    except (ValueError, KeyError, OSError) as err:
        raise user_error(err) from None
    for d in designs:
        mix = d.curves["mix"].tolerance
        click.echo(
            f"{d.name} ({'robust' if d.robust else 'nominal'}): nominal error "
            f"{d.nominal_error:.4g}; all perturbations at once within the limit up to "
            f"{'>= ' if not mix.bounded else ''}{mix.factor:.2g}x the default ranges"
        )
    click.echo(f"wrote {paths['html']}, {paths['png'].name}, {paths['json'].name}")


@report_group.command("privacy")
@click.option(
    "--train-frames",
    type=click.IntRange(30, 100000),
    default=300,
    show_default=True,
    help="Frames of each of the 3 training episodes (validation and test episodes: 2/3 of it).",
)
@click.option(
    "--task-seeds",
    type=click.IntRange(1, 100),
    default=2,
    show_default=True,
    help="Training seeds of every design (the task).",
)
@click.option(
    "--attack-seeds",
    "seeds",
    type=click.IntRange(1, 100),
    default=field_default(AttackConfig, "seeds"),
    show_default=True,
    help="Attacker seeds per design.",
)
@click.option(
    "--attack-steps",
    "max_steps",
    type=click.IntRange(1, 10**6),
    default=field_default(AttackConfig, "max_steps"),
    show_default=True,
    help="Adam steps of each attacker at most (the best validation state is kept).",
)
@click.option(
    "--detectors",
    type=click.Choice(AUDIT_DETECTORS),
    default=AUDIT_DETECTORS[0],
    show_default=True,
    help="Detectors rendered: mincam designs of 1, 2, 4, ... up to this many pixels.",
)
@click.option(
    "--mask-res",
    type=click.Choice(AUDIT_TEXELS),
    default=AUDIT_TEXELS[0],
    show_default=True,
    help="Mask texels per side rendered: baselines up to this fine (64: adds 64x64). "
    "16 detectors at 64 texels cost about 8 times the default render.",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 256),
    default=2,
    show_default=True,
    help="Render worker processes.",
)
@apply_options(executor_options)
@out_option(
    "Working and output directory (created; resumes): episodes, views, runs, privacy.html, "
    ".json, .png.",
    default="runs/privacy",
)
def report_privacy_cmd(
    train_frames: int,
    task_seeds: int,
    seeds: int,
    max_steps: int,
    detectors: int,
    mask_res: int,
    workers: int,
    train_workers: int,
    ray_address: str | None,
    out: Path,
) -> None:
    """What can an attacker recover from K measurements? Task error against attack success.

    Renders workspace episodes with a roster of 6 people, the full 64 x 64
    view of every frame and its background (the frame without its people),
    trains mincam 1-8 px (and 8 px with the privacy term) and baselines
    2x2..32x32 (with --detectors 16 --mask-res 64, also 16 px and 64x64) for
    the people count, then attacks each trained design:
    decoders of what the people add to the view (PSNR, SSIM on the people's
    pixels and on the whole view) and a re-identifier of who is in the room
    (top-1 accuracy against chance), trained on other episodes than those it
    is scored on (docs/privacy.md).

    \b
    Example:
      mincam-render report privacy --out runs/privacy
      mincam-render report privacy --train-frames 60 --attack-steps 200 --out runs/privacy-tiny
    """
    from mincam_render.data.ray_cluster import RayError
    from mincam_render.data.render_job import RenderError
    from mincam_render.data.run_dispatch import TrainingError
    from mincam_render.studies.privacy import PrivacyConfig, headline, run, write_report

    try:
        attack = AttackConfig(seeds=seeds, max_steps=max_steps)
        cfg = PrivacyConfig.sized(train_frames=train_frames, task_seeds=task_seeds,
                                  detectors=detectors, texels=mask_res, attack=attack)  # fmt: skip
        privacy = run(
            cfg,
            out,
            workers=workers,
            train_workers=train_workers,
            ray_address=ray_address,
            progress=True,
        )
        paths = write_report(privacy, out)
    except (ValueError, KeyError, OSError, RenderError, TrainingError, RayError) as err:
        raise user_error(err) from None
    click.echo(headline(privacy))
    click.echo(f"wrote {paths['json']}, {paths['html']} and {paths['png']}")
