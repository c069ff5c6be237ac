"""``mincam-render report``: reports comparing simulation with measurements, and energy."""

from __future__ import annotations

from pathlib import Path

import click

from .errors import InputError, user_error
from .options import out_option


@click.group("report")
def report_group() -> None:
    """Reports: simulation against measurements (sim2real), the self-powered budget (energy)."""


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
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=0, show_default=True)
def report_sim2real_cmd(
    measurements: Path | None,
    surrogate_family: str | None,
    frames: int,
    out: Path,
    spp: int,
    steps: int,
    seed: int,
) -> None:
    """Compare simulated with measured (or SURROGATE) freeform-pixel recordings.

    Give a recording directory (format: docs/sim2real_format.md), or --surrogate FAMILY.

    \b
    Example:
      mincam-render report sim2real --surrogate patches --frames 300 --out runs/s2r
      mincam-render report sim2real runs/s2r/surrogate_input --out runs/s2r-again
    """
    from mincam_render.analysis.sim2real import (
        Sim2RealError,
        analyze_sim2real,
        make_surrogate,
        write_sim2real_report,
    )
    from mincam_render.core.config import ConfigError

    if (measurements is None) == (surrogate_family is None):
        raise InputError("give a MEASUREMENTS directory or --surrogate FAMILY (one)")
    try:
        if surrogate_family is not None:
            measurements = make_surrogate(
                surrogate_family,
                out / "surrogate_input",
                num_frames=frames,
                spp=spp,
                seed=seed,
                progress=True,
            )
        assert measurements is not None  # for mypy: exactly one of the two was given
        result = analyze_sim2real(measurements, spp=spp, steps=steps, seed=seed, progress=True)
        paths = write_sim2real_report(result, out)
    except (ValueError, ConfigError, Sim2RealError, OSError) as err:
        raise user_error(err) from None
    click.echo(result["verdict"]["summary"])
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
    from mincam_render.analysis.energy import (
        analyze_energy,
        headline,
        load_energy_config,
        write_energy_report,
    )
    from mincam_render.core.config import ConfigError

    try:
        overrides = {"render": {"spp": spp}} if spp is not None else None
        config = load_energy_config(config_path, overrides)
        result = analyze_energy(families, config, studies_dir=studies_dir)
        paths = write_energy_report(result, out)
    except (ValueError, ConfigError, OSError) as err:
        raise user_error(err) from None
    click.echo(headline(result))
    click.echo(f"wrote {paths['json']}, {paths['html']} and {paths['png']}")
