"""``mincam-render report``: reports comparing simulation with measurements."""

from __future__ import annotations

from pathlib import Path

import click

from .errors import InputError, user_error
from .options import out_option


@click.group("report")
def report_group() -> None:
    """Reports comparing simulation with measurements."""


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
