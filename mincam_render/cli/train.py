"""``train``, ``sweep``, ``prune`` and ``export-masks``: learning cameras and printing masks.

The training options fill :class:`~mincam_render.learn.train_config.TrainConfig`:
each option's parameter name is the field's name and its default the field's
default, so the recipe has one source of truth.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from mincam_render.core import strict_json
from mincam_render.core.checks import check_name
from mincam_render.core.seeds import stream_seed
from mincam_render.learn.train_config import HeadKind, TrainConfig
from mincam_render.optics.perturbation import PerturbationModel

from . import __name__ as _pkg
from .errors import InputError, user_error
from .options import (
    FiniteFloat,
    apply_options,
    field_default,
    grid_list,
    int_list,
    optional_grid,
    out_option,
)

if TYPE_CHECKING:
    from mincam_render.export.masks import MaskFiles
    from mincam_render.learn.batches import RenderedBatches
    from mincam_render.learn.restore import TrainedRun
    from mincam_render.learn.training_data import TrainingData

log = logging.getLogger(_pkg)

# OSError: a full disk or an unreadable file; ImportError: a missing extra (the
# traffic family needs SUMO), whose message names the extra
_TRAIN_ERRORS = (ValueError, KeyError, RuntimeError, OSError, ImportError)

#: Where the training data come from: a dataset directory or an in-memory render.
_DATA_OPTIONS = [
    click.argument("dataset", required=False, type=click.Path(file_okay=False, path_type=Path)),
    click.option(
        "--family",
        default=None,
        help="Without DATASET: render this scene family in memory (name or .toml).",
    ),
    click.option(
        "--frames",
        type=click.IntRange(10),
        default=2000,
        show_default=True,
        help="With --family: frames rendered (split 70/10/20 in time).",
    ),
    click.option(
        "--spp",
        type=click.IntRange(1, 1 << 20),
        default=4,
        show_default=True,
        help="With --family: samples per texel.",
    ),
]

#: TrainConfig field -> (flag, type, help) of the option filling it (default: the field's).
_RECIPE_OPTIONS = {
    "max_steps": (
        "--steps",
        click.IntRange(1),
        "Maximum training steps (early stopping may end sooner).",
    ),
    "batch_size": ("--batch-size", click.IntRange(2), None),
    "lr": (
        "--lr",
        FiniteFloat(0, 1, min_open=True, max_open=True),
        "Head learning rate [default: 1e-3*min(1,sqrt(16/inputs))].",
    ),
    "mask_lr": ("--mask-lr", FiniteFloat(0, 10), "Adam learning rate of the mask logits."),
    "eval_every": ("--eval-every", click.IntRange(1), None),
    "patience": (
        "--patience",
        click.IntRange(1),
        "Evaluations without validation improvement before the learning rates decay "
        "(after --lr-decays decays: before stopping).",
    ),
    "lr_decays": (
        "--lr-decays",
        click.IntRange(0),
        "Plateaus answered by a learning-rate decay before one stops the run.",
    ),
    "lr_decay": (
        "--lr-decay",
        FiniteFloat(0, 1, min_open=True, max_open=True),
        "Factor applied to every learning rate at each decay.",
    ),
    "head": (
        "--head",
        click.Choice(HeadKind, case_sensitive=False),
        "Inference network: mlp (the paper's stacked history) or tcn (causal temporal "
        "convolutions over the history); prune keeps the run's.",
    ),
    "head_hidden": (
        "--head-hidden",
        click.IntRange(1, 4096),
        "Units of each of the head's two hidden layers; prune keeps the run's.",
    ),
    "seed": ("--seed", click.IntRange(0), None),
    "privacy_weight": (
        "--privacy-weight",
        FiniteFloat(0, 1000),
        "Adversarial privacy term: the masks minimise the task loss minus this times the "
        "loss of a decoder reconstructing the scene from the pixels (docs/privacy.md); "
        "0: the task alone. Minimalist cameras of static tasks only.",
    ),
    "signed_pixels": (
        "--signed-pixels",
        None,
        "Signed freeform pixels: each a pair of photodiodes behind two masks, read as "
        "the first minus the second (twice the photodiodes; the exported masks say "
        "which pairs). Minimalist cameras of train and sweep; prune refuses signed runs.",
    ),
}


def _recipe_option(name: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """The option filling ``TrainConfig.<name>``, with the field's default (no type: a flag)."""
    flag, type_, help_text = _RECIPE_OPTIONS[name]
    default = field_default(TrainConfig, name)
    if type_ is None:
        return click.option(flag, name, is_flag=True, default=default, help=help_text)
    return click.option(
        flag, name, type=type_, default=default, show_default=default is not None, help=help_text
    )


#: PerturbationModel record field -> help of the ``train`` option filling it (with --robust):
#: the options take the record's units (mm, deg, %, cm), converted by ``from_record``.
_PERTURBATION_HELP = {
    "mask_shift_mm": "mask position error per axis per detector (mm)",
    "mask_rotation_deg": "mask rotation error per detector (deg)",
    "gamma_deviation": "printed tone-curve exponent: gamma = 1 +- this",
    "dot_gain_deviation": "dot gain at 50 % ink coverage, +- this (<= 0.25)",
    "min_transmittance_error": "error of the printable minimum transmittance",
    "max_transmittance_error": "error of the printable maximum transmittance",
    "mask_blur_mm": "Gaussian blur sigma of the print, drawn in [0, this] (mm)",
    "gain_mismatch_percent": "per-detector gain error (%)",
    "dark_offset_v": "per-detector output offset (V)",
    "pose_orientation_deg": "camera orientation error per axis: pan, tilt, roll (deg)",
    "pose_position_cm": "camera position error per axis: right, up, forward (cm)",
    "pose_depth_m": "scene depth at which the position error is modelled exactly (m)",
}
#: PerturbationModel record fields whose options take other values than [0, 100].
_PERTURBATION_TYPES = {"pose_depth_m": FiniteFloat(0, 1e4, min_open=True)}

#: --robust and the perturbation model's half-ranges (defaults: the dataclass's).
robust_options = apply_options(
    [
        click.option(
            "--robust",
            is_flag=True,
            help="Robust training: every batch through a new built camera drawn from the "
            "perturbation model below (docs/robustness.md).",
        ),
        click.option(
            "--robust-validation-draws",
            "robust_validation_draws",
            type=click.IntRange(0, 1000),
            default=field_default(TrainConfig, "robust_validation_draws"),
            show_default=True,
            help="With --robust: validate (decay the learning rate, stop early) on the mean "
            "loss over this many built cameras, drawn once from --seed; 0: on the camera "
            "as designed.",
        ),
    ]
    + [
        click.option(
            "--" + name.replace("_", "-"),
            name,
            type=_PERTURBATION_TYPES.get(name, FiniteFloat(0, 100)),
            default=default,
            show_default=True,
            help=f"With --robust: {_PERTURBATION_HELP[name]}.",
        )
        for name, default in PerturbationModel().to_record().items()
    ]
)


def _recipe_with_perturbation(robust: bool, **recipe: Any) -> TrainConfig:
    """The TrainConfig of the options (``recipe``: the command's); with ``robust``, its model's."""
    halves = {name: recipe.pop(name) for name in PerturbationModel().to_record()}
    return TrainConfig(
        **recipe, perturbation=PerturbationModel.from_record(halves) if robust else None
    )


#: Options shared by train, sweep and prune (the paper's recipe as defaults), the
#: recipe's in the order of TrainConfig's fields.
training_options = apply_options(
    _DATA_OPTIONS
    + [_recipe_option(f.name) for f in dataclasses.fields(TrainConfig) if f.name in _RECIPE_OPTIONS]
)


@click.command("train")
@training_options
@out_option(
    "Run directory (created; an existing checkpoint there is resumed).", default="runs/train"
)
@click.option(
    "--pixels",
    type=click.IntRange(1, 4096),
    default=None,
    help="Freeform pixels of the minimalist camera (default: one per rendered detector; "
    "at most that many).",
)
@click.option(
    "--baseline",
    "baseline",
    default=None,
    callback=optional_grid,
    help="Train a ROWSxCOLS baseline camera instead.",
)
@click.option(
    "--no-sensor-model",
    is_flag=True,
    help="Train without noise/saturation (supplement A's ablation).",
)
@click.option(
    "--on-the-fly", is_flag=True, help="With --family: render fresh training frames every batch."
)
@click.option(
    "--export-masks",
    "export_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="After training, export printable masks into this directory.",
)
@click.option("--no-resume", is_flag=True, help="Start afresh even if a checkpoint exists.")
@robust_options
def train_cmd(
    dataset: Path | None,
    family: str | None,
    frames: int,
    spp: int,
    out: Path,
    pixels: int | None,
    baseline: tuple[int, int] | None,
    no_sensor_model: bool,
    on_the_fly: bool,
    export_dir: Path | None,
    no_resume: bool,
    robust: bool,
    **recipe: Any,
) -> None:
    """Train a minimalist (or baseline) camera end to end; metrics on the test split.

    Reads a dataset written by `mincam-render render`, or renders --frames of a
    scene family in memory. Writes checkpoint.pt (resumable), TensorBoard event
    files, history.jsonl, mask_evolution.png, run.json and metrics.json
    (test RMSE/accuracy after rounding and median filtering) into --out.

    With --robust, every batch is measured through a new built camera (mask
    shift and rotation, print tone, printable range, blur, detector gain and
    offset, camera orientation and position, drawn within the ranges of the
    options below), and validation uses --robust-validation-draws of them.

    \b
    Example:
      mincam-render train --family patches --frames 300 --pixels 4 --steps 200 \\
          --out runs/patches4
      mincam-render train --family patches --frames 300 --pixels 4 --steps 200 \\
          --robust --mask-shift-mm 0.5 --out runs/patches4-robust
    """
    from mincam_render.learn.train import train_run
    from mincam_render.learn.training_data import training_splits

    try:
        if robust and baseline is not None:
            raise InputError("--robust perturbs masks and diodes: not with --baseline")
        config = _recipe_with_perturbation(robust, **recipe)
        train, val, test = training_splits(dataset, family, frames, spp, config.seed)
        metrics = train_run(
            train,
            val,
            test,
            out,
            pixels=pixels,
            baseline_grid=baseline,
            sensor_model=not no_sensor_model,
            config=config,
            on_the_fly=_fresh_batches(family, spp, config, train) if on_the_fly else None,
            resume=not no_resume,
            progress=True,
        )
        if export_dir is not None and baseline is None:
            _export_run_masks(out, export_dir, train)
    except _TRAIN_ERRORS as err:
        raise user_error(err) from None
    t = metrics.test
    assert t is not None  # the command always has a test split
    click.echo(
        f"{metrics.model['kind']} {metrics.model['pixels']} px: test "
        f"{t.error_name} = {t.error:.4f} after {metrics.steps} steps "
        f"({metrics.train_wall_time_s:.1f} s); wrote {out / 'metrics.json'}"
    )


def _fresh_batches(
    family: str | None, spp: int, config: TrainConfig, train: TrainingData
) -> RenderedBatches:
    """--on-the-fly: training batches of frames rendered afresh (from the next seed)."""
    from mincam_render.learn.train import RenderedBatches
    from mincam_render.scenes import load_family

    if family is None:
        raise InputError("--on-the-fly needs --family (frames are rendered)")
    seed = stream_seed(config.seed, "train/on-the-fly")
    n = config.max_steps * config.batch_size * train.history
    return RenderedBatches(
        load_family(family, seed=seed, num_frames=n), config.batch_size, spp=spp, seed=seed
    )


def _export_run_masks(run_dir: Path, export_dir: Path, train: TrainingData) -> None:
    """--export-masks: the printable masks of a finished run."""
    from mincam_render.learn.train import open_run

    write_masks(open_run(run_dir), export_dir, str(train.source.get("family", "")))


def write_masks(run: TrainedRun, folder: Path, task: str, *, pdf: bool = True) -> MaskFiles:
    """Export ``run``'s masks into ``folder``; an unfinished run's export is marked so.

    The sidecar's provenance holds the run, its data and how far its training got
    (``training``); an unfinished run's print sheet says so in its title line.
    """
    from mincam_render.export.masks import export_masks
    from mincam_render.learn.train import masks_of

    m, camera = masks_of(run)
    return export_masks(
        m,
        camera,
        folder,
        task=task,
        pdf=pdf,
        provenance={"run": str(run.path), "data": run.record["data"], "training": run.training},
        sheet_note="" if run.finished else f"UNFINISHED RUN ({run.training})",
        signed=bool(run.record["model"].get("signed", False)),
    )


@click.command("sweep")
@training_options
@out_option("Output directory (created).", default="runs/sweep")
@click.option(
    "--pixels",
    "pixel_counts",
    default=None,
    callback=int_list,
    help="Minimalist-camera pixel counts (default: 1, 2, 4, ... up to the rendered detectors).",
)
@click.option(
    "--baselines",
    default="1x1,2x2,4x4,8x8,16x16",
    show_default=True,
    callback=grid_list,
    help="Baseline resolutions ROWSxCOLS.",
)
def sweep_cmd(
    dataset: Path | None,
    family: str | None,
    frames: int,
    spp: int,
    out: Path,
    pixel_counts: list[int] | None,
    baselines: list[tuple[int, int]],
    **recipe: Any,
) -> None:
    """Task error against pixel count: minimalist cameras vs baselines (log axis).

    Every camera gets the same training budget. Writes sweep.png, sweep.md,
    sweep.json and one resumable run directory per camera into --out.

    \b
    Example:
      mincam-render sweep --family patches --frames 300 --steps 100 --pixels 1,4 \\
          --baselines 2x2,8x8 --out runs/sweep_patches
    """
    from mincam_render.learn.train import sweep, sweep_table
    from mincam_render.learn.training_data import training_splits

    try:
        config = TrainConfig(**recipe)
        train, val, test = training_splits(dataset, family, frames, spp, config.seed)
        rows = sweep(
            train,
            val,
            test,
            pixel_counts=pixel_counts,
            baseline_grids=baselines,
            config=config,
            out_dir=out,
            progress=True,
        )
    except _TRAIN_ERRORS as err:
        raise user_error(err) from None
    click.echo(sweep_table(rows))
    click.echo(f"wrote {out / 'sweep.png'}, sweep.md, sweep.json")


@click.command("prune")
@training_options
@click.option(
    "--run",
    "run_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="A minimalist-camera run directory from `mincam-render train`.",
)
@out_option("Output directory (created).", default="runs/prune")
@click.option(
    "--allow-unfinished",
    is_flag=True,
    help="Prune a run whose training did not finish (its best state so far); prune.json "
    "marks every record unfinished.",
)
def prune_cmd(
    dataset: Path | None,
    family: str | None,
    frames: int,
    spp: int,
    run_dir: Path,
    out: Path,
    allow_unfinished: bool,
    **recipe: Any,
) -> None:
    """Greedy pruning (supplement C): drop the least useful pixel, retrain the head, repeat.

    Use the same data as the run. Writes prune.json and prune.png (test error
    against pixel count) into --out.

    \b
    Example:
      mincam-render prune --family patches --frames 300 --steps 100 \\
          --run runs/patches4 --out runs/patches4_prune
    """
    from mincam_render.learn.train import (
        ModelKind,
        SweepPoint,
        greedy_prune,
        open_run,
        plot_sweep,
        restore_mincam,
    )
    from mincam_render.learn.training_data import training_splits

    try:
        config = TrainConfig(**recipe)
        if config.signed_pixels:
            raise InputError(
                "--signed-pixels: prune keeps the run's pixels (and drops single ones)"
            )
        run = open_run(run_dir, allow_unfinished=allow_unfinished)
        run.require(ModelKind.MINCAM, "prune")  # before the data are read
        train, val, test = training_splits(dataset, family, frames, spp, config.seed)
        model = restore_mincam(run, train, "prune")
        records = greedy_prune(model, train, val, test, config, progress=True)
    except _TRAIN_ERRORS as err:
        raise user_error(err) from None
    out.mkdir(parents=True, exist_ok=True)
    source = {"run": str(run_dir), "run_training": run.training}
    (out / "prune.json").write_text(strict_json.dumps([source | r.as_json() for r in records]))
    tests = [(r, r.test) for r in records if r.test is not None]
    points = [
        SweepPoint(kind=ModelKind.MINCAM, pixels=r.pixels, error=t.error, error_name=t.error_name)
        for r, t in tests
    ]
    plot_sweep(points, out / "prune.png", title="greedy pruning")
    for r, t in tests:
        click.echo(
            f"{r.pixels:3d} px  removed {list(r.removed)}  test {t.error_name} = {t.error:.4f}"
        )
    click.echo(f"wrote {out / 'prune.json'}, prune.png")


@click.command("export-masks")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--task", default=None, help="Task name [default: the run's scene family].")
@out_option("Masks go into OUT/<task>/.", default="masks")
@click.option("--no-pdf", is_flag=True, help="Skip the PDF print sheet.")
@click.option(
    "--allow-unfinished",
    is_flag=True,
    help="Export the best masks so far of a run whose training did not finish; masks.json "
    "and the print sheet mark the export unfinished.",
)
def export_masks_cmd(
    run_dir: Path, task: str | None, out: Path, no_pdf: bool, allow_unfinished: bool
) -> None:
    """Export a trained camera's masks for printing.

    Writes into OUT/<task>/: mask_NN.png (16-bit transmittance), masks.exr,
    print_sheet.svg/.pdf at true size with cut marks and labels, masks.json.
    The folder is written whole and replaces an earlier export there; a folder
    holding anything else is refused.

    \b
    Example:
      mincam-render export-masks runs/patches4 --task patches --out masks
    """
    from mincam_render.learn.train import open_run

    try:
        task = None if task is None else check_name("--task", task)  # before the run is read
        run = open_run(run_dir, allow_unfinished=allow_unfinished)
        family = str(run.record["data"]["train"].get("family") or "task")
        task = task or check_name("--task (the run's family)", family)
        paths = write_masks(run, out / task, task, pdf=not no_pdf)
    except _TRAIN_ERRORS as err:
        raise user_error(err) from None
    click.echo(
        f"wrote {len(paths.png)} masks to {out / task} "
        f"(PNG, EXR, print_sheet.svg{'' if no_pdf else '/.pdf'}, masks.json)"
    )
    if not run.finished:
        click.echo(f"the export is marked unfinished: {run_dir} is {run.training}")
