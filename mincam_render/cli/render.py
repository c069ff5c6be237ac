"""``render``, ``export-exr`` and ``repair``: datasets of transport images on disk.

The options of ``render`` that describe the dataset fill
:class:`~mincam_render.data.render_job.RenderRequest`: each option's parameter
name is the field's name and its default the field's default.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import click

from mincam_render.core.config import SceneOverrides
from mincam_render.data.render_job import RenderRequest
from mincam_render.render.differential import DifferenceSeeds
from mincam_render.render.fidelity import Fidelity
from mincam_render.render.precision import ErrorScale, StorageDtype

from .errors import user_error
from .options import (
    FiniteFloat,
    apply_options,
    field_default,
    out_option,
    scene_settings,
    with_detectors,
)

_default = functools.partial(field_default, RenderRequest)


def _render_splits(ctx: click.Context, param: click.Parameter, value: str) -> tuple[float, ...]:
    try:
        parts = tuple(float(p) for p in value.split(","))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not three fractions, e.g. 0.7,0.15,0.15") from None
    if len(parts) != 3:
        raise click.BadParameter(f"{value!r}: expected three fractions train,val,test")
    return parts


#: What to render: options named like the RenderRequest fields they fill (and
#: --detectors, a shorthand for --set camera.detectors=N).
_REQUEST_OPTIONS = [
    click.option(
        "--frames", "num_frames", type=click.IntRange(1, 10**9), required=True,
        help="Frames to render.",
    ),
    click.option(
        "--seed", type=click.IntRange(0, 2**63 - 1), default=_default("seed"), show_default=True,
        help="Dataset seed (scene trajectories and per-frame render seeds).",
    ),
    click.option(
        "--shard-frames", type=click.IntRange(1, 1 << 20), default=_default("shard_frames"),
        show_default=True, help="Frames per shard file.",
    ),
    click.option(
        "--splits", callback=_render_splits, default=",".join(map(str, _default("splits"))),
        show_default=True, help="Train,val,test fractions (contiguous in time).",
    ),
    click.option(
        "--set", "overrides", multiple=True, callback=scene_settings, metavar="KEY=VALUE",
        help="Override a scene description value (TOML syntax), repeatable.",
    ),
    click.option(
        "--detectors", type=click.IntRange(1, 64), default=None,
        help="Number of freeform pixels (same as --set camera.detectors=N).",
    ),
    click.option(
        "--fidelity", type=click.Choice([f.value for f in Fidelity]),
        default=_default("fidelity").value, show_default=True,
        help="auto: measure what the scene needs; full: no shortcuts.",
    ),
    click.option(
        "--spp", type=click.IntRange(1, 1 << 20), default=_default("spp"),
        help="Samples per texel (default: from --target-error).",
    ),
    click.option(
        "--max-depth", type=click.IntRange(0, 64), default=_default("max_depth"),
        help="Path depth (2 = direct light, 0 = the scene's integrator).",
    ),
    click.option(
        "--shared-render/--per-detector", default=_default("shared_render"),
        help="One render for all detectors, or one per detector (default: by parallax).",
    ),
    click.option(
        "--differential/--no-differential", default=_default("differential"),
        help="Render frames as a converged static background plus what the movers change "
        "(default: when cheaper at the target error; indoor families only).",
    ),
    click.option(
        "--background-interval", "background_interval_s", type=FiniteFloat(1e-3, 1e6),
        default=_default("background_interval_s"), show_default=True,
        help="Scene seconds between the daylight components a background is interpolated "
        "between (--differential).",
    ),
    click.option(
        "--shared-difference/--per-detector-difference", default=_default("shared_difference"),
        help="With --differential: render the movers' change once from the board centre "
        "for all detectors (default: when its parallax error is below a share of the target).",
    ),
    click.option(
        "--background-spp", type=click.IntRange(1, 1 << 20), default=_default("background_spp"),
        help="Samples per texel of the static backgrounds (default: from --target-error).",
    ),
    click.option(
        "--mask-res", type=click.IntRange(1, 4096), default=_default("mask_res"),
        help="Mask texels per side (default: the family camera's).",
    ),
    click.option(
        "--dtype", type=click.Choice([d.value for d in StorageDtype]), default=_default("dtype"),
        help="Storage type (default: float16 if within --dtype-error).",
    ),
    click.option(
        "--target-error", type=FiniteFloat(1e-6, 1.0), default=_default("target_error"),
        show_default=True,
        help="Target measurement error relative to the total (chooses spp when the plan is "
        "made in that scale, see --error-scale).",
    ),
    click.option(
        "--error-scale", type=click.Choice([s.value for s in ErrorScale]),
        default=_default("error_scale"),
        help="What the plan's target is relative to: the frame's total, its mean over "
        "frames, or the label signal (default: the family's).",
    ),
    click.option(
        "--signal-target-error", type=FiniteFloat(1e-6, 100.0),
        default=_default("signal_target_error"),
        help="Target measurement error relative to the label signal (default: the "
        "family's, chosen by the task-level check).",
    ),
    click.option(
        "--samples-factor", type=FiniteFloat(1e-4, 1e4), default=_default("samples_factor"),
        help="Render the plan at this many times its samples of frames and backgrounds, at "
        "full path depth (16): the task-fidelity check's level of that factor "
        "(docs/fidelity.md says which factor a family's task needs at which size).",
    ),
    click.option(
        "--difference-seeds", type=click.Choice([s.value for s in DifferenceSeeds]),
        default=_default("difference_seeds"),
        help="With --differential: the movers' change shares one seed per background "
        "window, or has its own per frame (twice its paths; default: the planner's).",
    ),
    click.option(
        "--dtype-error", "dtype_error_bound", type=FiniteFloat(1e-9, 1.0),
        default=_default("dtype_error_bound"), show_default=True,
        help="Largest relative measurement error float16 may add.",
    ),
]  # fmt: skip

#: How to render it: not part of the request (the same request gives the same bytes).
_RUN_OPTIONS = [
    click.option(
        "--workers", type=click.IntRange(0, 256), default=None,
        help="Local worker processes, the cores shared among them (0 = in this process). "
        "Default: by job size; the first shard renders in this process, the rest in one "
        "worker per core only if that would take this process more than 10 s.",
    ),
    click.option(
        "--ray", "ray_address", default=None, metavar="ADDRESS",
        help="Render on a Ray cluster ('local' starts one; needs the ray extra).",
    ),
    click.option(
        "--replan", is_flag=True,
        help="Measure the fidelity plan again instead of reusing a kept plan of the same "
        "description, camera, targets and frame count.",
    ),
    click.option("--no-progress", is_flag=True, help="Hide the progress bar."),
    click.option(
        "-y", "--yes", is_flag=True,
        help="Render a new job even when its estimate (frames x measured seconds per frame, "
        "shards x bytes per shard, shown before rendering) is above a day in one process or "
        "the free disk; without it such a job is refused before anything is written.",
    ),
]  # fmt: skip


@click.command("render")
@click.argument("family")
@out_option("Dataset directory (created; an unfinished one is resumed).")
@apply_options(_REQUEST_OPTIONS)
@apply_options(_RUN_OPTIONS)
def render_cmd(
    out: Path,
    workers: int | None,
    ray_address: str | None,
    replan: bool,
    no_progress: bool,
    yes: bool,
    **request_options: Any,
) -> None:
    """Render a dataset of transport images T[frame, detector, row, col] with labels.

    FAMILY is a scene family name (patches, workspace, lighting, traffic, or one
    an installed package registers), a family class (module:Class) or a scene
    TOML file (docs/your_own_task.md). The same command after an interruption resumes and gives
    the same bytes as an uninterrupted run; a different configuration into a
    non-empty --out is refused. The fidelity plan is measured once per
    description, camera, targets and frame count (on the seed-0 episode, so every
    seed shares it) and kept; shipped plans (scenes/plans/) start at once.
    A new job's time and disk are estimated before anything is written (its
    first frames rendered and timed); one above a day in one process or the
    free disk is refused unless --yes. Format: docs/dataset_format.md.

    \b
    Example:
      mincam-render render patches --out runs/patches-ds --frames 512 --workers 2
      mincam-render render patches --out runs/tiny --frames 40 --shard-frames 8 \\
          --detectors 2 --mask-res 8 --spp 4
    """
    from mincam_render.data.dataset import DatasetError
    from mincam_render.data.render_job import JobLimits, RenderError, render_dataset

    try:
        summary = render_dataset(
            _request(**request_options),
            out,
            workers=workers,
            ray_address=ray_address,
            progress=not no_progress,
            use_plan_cache=not replan,
            limits=JobLimits(confirmed=yes),
        )
    except (ValueError, DatasetError, RenderError, OSError, ImportError, MemoryError) as err:
        raise user_error(err) from None
    click.echo(
        f"{out}: {summary.num_frames} frames in {summary.shards_total} shards; rendered "
        f"{len(summary.shards_rendered)}, kept {len(summary.shards_kept)}, repaired "
        f"{len(summary.shards_repaired)}; {summary.seconds:.1f} s "
        f"({summary.frames_per_s:.1f} frames/s)"
    )


def _request(*, detectors: int | None, overrides: SceneOverrides, **fields: Any) -> RenderRequest:
    """The request the options describe; ``fields`` are named like RenderRequest's fields."""
    return RenderRequest(overrides=with_detectors(overrides, detectors) or None, **fields)


@click.command("export-exr")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--frames",
    "frame_list",
    required=True,
    help="Frame indices, e.g. 0,5,10-12 (ranges inclusive).",
)
@out_option("Directory for frame-NNNNNN.exr files (created).")
def export_exr_cmd(dataset: Path, frame_list: str, out: Path) -> None:
    """Write chosen frames of a rendered dataset as OpenEXR (one channel per detector, W).

    \b
    Example:
      mincam-render export-exr runs/tiny --frames 0,5,10-12 --out runs/tiny-exr
    """
    from mincam_render.data.dataset import DatasetError, open_dataset, parse_frame_list

    try:
        ds = open_dataset(dataset)
        paths = ds.export_exr(parse_frame_list(frame_list, ds.num_frames), out)
    except (ValueError, DatasetError, OSError) as err:
        raise user_error(err) from None
    click.echo(f"wrote {len(paths)} EXR file(s) to {out}")


@click.command("repair")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
def repair_cmd(dataset: Path) -> None:
    """Rebuild an edited or damaged manifest from its request and the shards' own records.

    Shards that pass their own checksum and were rendered for the request are
    kept; the rest are listed, and the same `render` command renders them again.

    \b
    Example:
      mincam-render repair runs/tiny
    """
    from mincam_render.data.dataset import DatasetError
    from mincam_render.data.repair import repair_dataset

    try:
        summary = repair_dataset(dataset)
    except (ValueError, DatasetError, OSError, RuntimeError) as err:
        raise user_error(err) from None
    restored = ", ".join(summary.restored_fields) or "none"
    click.echo(
        f"{dataset}: manifest rebuilt; kept {len(summary.kept)} of {summary.num_shards} "
        f"shards; fields restored from the request's plan: {restored}"
    )
    for shard, reason in summary.dropped.items():
        click.echo(f"  shard {shard}: {reason}; the same `render` command renders it again")
