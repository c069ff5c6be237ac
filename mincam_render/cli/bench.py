"""``mincam-render bench``: benchmarks of measured error against run time.

The options of ``bench fidelity`` fill
:class:`~mincam_render.studies.fidelity.config.FidelityBenchConfig`: each
option's parameter name is the field's name and its default the field's default
(``--no-auto`` is ``include_auto=False``).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import click

from mincam_render.studies.fidelity.config import FidelityBenchConfig

from .errors import user_error
from .options import field_default, out_option

_default = functools.partial(field_default, FidelityBenchConfig)


@click.group("bench")
def bench_group() -> None:
    """Benchmarks: measured error against run time."""


@bench_group.command("fidelity")
@click.argument("families", nargs=-1, required=True)
@out_option(
    "Output directory (created): fidelity.json, pareto_<family>.png, fidelity.html.",
    default="runs/bench-fidelity",
)
@click.option(
    "--frames",
    "num_frames",
    type=click.IntRange(1, 1000),
    default=_default("num_frames"),
    show_default=True,
    help="Frames rendered per setting, spread over the sequence.",
)
@click.option(
    "--reference-spp",
    type=click.IntRange(2, 1 << 20),
    default=_default("reference_spp"),
    show_default=True,
    help="Samples per texel of the converged reference.",
)
@click.option(
    "--base-spp",
    type=click.IntRange(1, 1 << 20),
    default=_default("base_spp"),
    show_default=True,
    help="Samples per texel of the base setting the knobs start from.",
)
@click.option(
    "--mask-res",
    "mask_resolution",
    type=click.IntRange(1, 4096),
    default=_default("mask_resolution"),
    help="Mask texels per side (default: the family camera's).",
)
@click.option("--no-auto", is_flag=True, help="Skip the automatic fidelity decision.")
@click.option(
    "--seed", type=click.IntRange(0, 2**63 - 1), default=_default("seed"), show_default=True
)
def bench_fidelity_cmd(families: tuple[str, ...], out: Path, no_auto: bool, **fields: Any) -> None:
    """Error of detector measurements against run time for every fidelity knob.

    \b
    Example:
      mincam-render bench fidelity workspace --out runs/bench-fidelity
    """
    from mincam_render.core.config import ConfigError
    from mincam_render.studies.fidelity import pareto_table, run, write_report

    try:
        cfg = FidelityBenchConfig(families=families, include_auto=not no_auto, **fields)
        result = run(cfg, out)
        paths = write_report(result, out)
    except (ValueError, ConfigError, OSError) as err:
        raise user_error(err) from None
    for r in result.families:
        click.echo(f"== {r.family}\n{pareto_table(r)}\n" + "\n".join(r.statements))
    click.echo(f"wrote {paths['json']} and {paths['html']}")
