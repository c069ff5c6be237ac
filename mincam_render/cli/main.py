"""The ``mincam-render`` command line (one entry point, subcommands)."""

from __future__ import annotations

import errno
import json
import logging
import math
import time
from pathlib import Path

import click
import numpy as np

from . import __name__ as _pkg

MM = 1e-3
log = logging.getLogger(_pkg)


class FiniteFloat(click.FloatRange):
    """A float range that also refuses NaN and infinities (click's FloatRange passes NaN)."""

    name = "finite float"

    def convert(self, value, param, ctx):
        """The float, or a usage error naming the option."""
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


class InputError(click.ClickException):
    """Bad input (an option, a file, a field): exit code 2, like click's own usage errors."""

    exit_code = 2


#: OSError numbers that are the machine's failure, not the user's input.
_MACHINE_ERRNOS = {errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.ENOMEM}


def _user_error(err: Exception) -> click.ClickException:
    """One line for an error: bad input (exit 2), or a failure while working (exit 1).

    Bad input: invalid values, files and data (ValueError, KeyError, path errors).
    A failure: a worker or the machine failed (RuntimeError, a full disk), or an
    optional extra is not installed (ImportError).
    """
    failed = isinstance(err, RuntimeError | ImportError) or (
        isinstance(err, OSError) and err.errno in _MACHINE_ERRNOS
    )
    return click.ClickException(str(err)) if failed else InputError(str(err))


def _vec3(ctx, param, value):
    if value is None:
        return None
    try:
        parts = [float(p) for p in value.split(",")]
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not three comma-separated numbers, e.g. 0,0,1"
        ) from None
    if len(parts) != 3:
        raise click.BadParameter(f"{value!r} has {len(parts)} numbers; expected x,y,z (metres)")
    return tuple(parts)


def _grid(ctx, param, value):
    try:
        r, c = (int(p) for p in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not ROWSxCOLS, e.g. 4x6") from None
    if not (1 <= r <= 64 and 1 <= c <= 64):
        raise click.BadParameter(f"{value!r}: rows and columns must each be in [1, 64], e.g. 4x6")
    return (r, c)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", is_flag=True, help="Log debug messages.")
def main(verbose: bool) -> None:
    """Render, train and export minimalist cameras of freeform pixels."""
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )


@main.command("transport")
@click.argument("scene", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/transport"),
    show_default=True,
    help="Output directory (created).",
)
@click.option(
    "--spp",
    type=click.IntRange(1, 1 << 24),
    default=16,
    show_default=True,
    help="Samples per mask texel.",
)
@click.option("--seed", type=click.IntRange(0), default=0, show_default=True, help="Random seed.")
@click.option(
    "--mask-res",
    type=click.IntRange(1, 4096),
    default=32,
    show_default=True,
    help="Mask resolution (texels per side).",
)
@click.option(
    "--grid",
    "grid",
    default="4x6",
    show_default=True,
    callback=_grid,
    help="Detector grid ROWSxCOLS on the board.",
)
@click.option(
    "--pitch-mm",
    type=FiniteFloat(0.0, min_open=True),
    default=20.0,
    show_default=True,
    help="Detector pitch (mm).",
)
@click.option(
    "--position", callback=_vec3, default="0,0,0", show_default=True, help="Board centre x,y,z (m)."
)
@click.option(
    "--look-at",
    callback=_vec3,
    default="0,0,1",
    show_default=True,
    help="Point the board faces x,y,z (m).",
)
@click.option(
    "--up",
    callback=_vec3,
    default="0,1,0",
    show_default=True,
    help="Up direction x,y,z (row 0 of the masks).",
)
@click.option(
    "--pose-from-sensor",
    is_flag=True,
    help="Take position, view direction and up from the scene's sensor (see --sensor-id).",
)
@click.option(
    "--sensor-id",
    default=None,
    help="With --pose-from-sensor: the id of the sensor to use (default: the first).",
)
@click.option(
    "--scene-scale",
    type=FiniteFloat(0.0, min_open=True, max=1e6),
    default=1.0,
    show_default=True,
    help="Multiply the scene's lengths by this (0.001 for a scene modelled in millimetres).",
)
@click.option(
    "--max-depth",
    type=click.IntRange(1, 64),
    default=None,
    help="Override the scene's path depth (1 = emitters only).",
)
@click.pass_context
def transport_cmd(ctx, scene, out, spp, seed, mask_res, grid, pitch_mm, max_depth, **pose):
    """Render transport images T[detector, row, col] of a camera in a scene.

    SCENE is a Mitsuba XML file; without it the built-in demo scene is used.
    Writes transport.exr (one channel per detector, watts), transport.png and
    config.json (the resolved configuration) into --out.

    \b
    Example:
      mincam-render transport --out runs/demo --spp 16 --mask-res 32
    """
    from mincam_render.analysis.plots import plot_transport_grid
    from mincam_render.data.exr import write_transport_exr
    from mincam_render.optics.camera import DetectorLayout, FreeformCamera
    from mincam_render.render import backend, user_scene
    from mincam_render.render.mitsuba_scene import SceneError, demo_scene, load_scene
    from mincam_render.render.transport import render_transport_with_noise

    try:
        mi_scene = load_scene(str(scene) if scene is not None else demo_scene())
        user_scene.rescale_scene(mi_scene, pose.pop("scene_scale"))
        camera = FreeformCamera(
            mask_resolution=(mask_res, mask_res),
            layout=DetectorLayout.grid(rows=grid[0], cols=grid[1], pitch_m=pitch_mm * MM),
            **_transport_pose(ctx, mi_scene, **pose),
        )
        warnings = user_scene.check_scene(mi_scene, camera, require_emitter=True)
        info = backend.describe()
        log.info(
            "rendering %d detectors x %dx%d texels x %d spp (%s)",
            camera.num_detectors,
            mask_res,
            mask_res,
            spp,
            info["variant"],
        )
        t0 = time.perf_counter()
        t, noise = render_transport_with_noise(
            mi_scene, camera, spp=spp, seed=seed, max_depth=max_depth
        )
        seconds = time.perf_counter() - t0
        warnings += user_scene.check_transport(t)
    except (ValueError, SceneError, backend.BackendUnavailableError) as err:
        raise _user_error(err) from None
    spp_target = user_scene.spp_for_noise(spp, noise)
    worst = float(np.nanmax(noise))
    if worst > user_scene.TARGET_RELATIVE_NOISE:
        warnings.append(
            f"worst detector relative error {worst:.1%}: --spp {spp_target} reaches 1 %"
        )
        log.warning("%s", warnings[-1])
    out.mkdir(parents=True, exist_ok=True)
    config = {
        "scene": str(scene) if scene is not None else "builtin:demo",
        "scene_scale": ctx.params["scene_scale"],
        "pose_from_sensor": pose["pose_from_sensor"],
        "spp": spp,
        "seed": seed,
        "max_depth": max_depth,
        "camera": camera.to_dict(),
        "backend": info,
        "render_seconds": seconds,
        "relative_noise": [None if np.isnan(x) else float(x) for x in noise],
        "spp_for_1_percent": spp_target,
        "warnings": warnings,
        "units": {"transport": "W per unit transmittance", "lengths": "m"},
        "array_axes": "T[detector, row, col]; row 0 = up side, col 0 = left, seen from the camera",
    }
    write_transport_exr(out / "transport.exr", t, config)
    plot_transport_grid(
        t,
        out / "transport.png",
        title=f"transport images, {config['scene']}, {spp} spp",
        board_positions_m=np.asarray(camera.layout.positions_m),
    )
    (out / "config.json").write_text(json.dumps(config, indent=2, default=str))
    click.echo(
        f"wrote {out / 'transport.exr'} ({t.shape[0]} detectors, {t.shape[1]}x{t.shape[2]}), "
        f"transport.png, config.json; render {seconds:.2f} s; total power at M=1: "
        f"{t.sum(axis=(1, 2)).mean():.3e} W per detector; worst detector relative error "
        f"{worst:.2%} (--spp {spp_target} for 1 %)"
    )


def _transport_pose(ctx, mi_scene, *, position, look_at, up, pose_from_sensor, sensor_id) -> dict:
    """Camera pose keywords from the options, or from the scene's sensor."""
    from mincam_render.render.user_scene import sensor_pose

    given = [
        name
        for name in ("position", "look_at", "up")
        if ctx.get_parameter_source(name) is not click.core.ParameterSource.DEFAULT
    ]
    if not pose_from_sensor:
        if sensor_id is not None:
            raise click.UsageError("--sensor-id needs --pose-from-sensor")
        return {"position": position, "look_at": look_at, "up": up}
    if given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        raise click.UsageError(f"--pose-from-sensor takes the pose from the scene: drop {flags}")
    p = sensor_pose(mi_scene, sensor_id)
    return {"position": p.position, "look_at": p.look_at, "up": p.up}


@main.command("preview")
@click.argument("scene")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/preview"),
    show_default=True,
    help="Output directory (created).",
)
@click.option("--seed", type=click.IntRange(0), default=0, show_default=True, help="Random seed.")
@click.option(
    "--frames",
    "n_shown",
    type=click.IntRange(1, 12),
    default=3,
    show_default=True,
    help="How many frames to show.",
)
@click.option(
    "--duration-s",
    type=FiniteFloat(0.0, min_open=True),
    default=60.0,
    show_default=True,
    help="Length of the sequence the frames are spread over (s).",
)
@click.option(
    "--spp",
    type=click.IntRange(1, 4096),
    default=32,
    show_default=True,
    help="Samples per pixel of the views.",
)
def preview_cmd(scene, out, seed, n_shown, duration_s, spp):
    """Render a few frames of a scene family with their labels drawn on.

    SCENE is a family name (patches, workspace, lighting, traffic) or a path to
    a scene description (.toml). Writes preview_<family>.png into --out: per
    frame the training camera's view, a bird's-eye view and detector 0's
    transport image, with the frame's labels.

    \b
    Example:
      mincam-render preview workspace --out runs/preview --frames 3
    """
    from mincam_render.analysis.preview import render_preview
    from mincam_render.core.config import ConfigError
    from mincam_render.render.mitsuba_scene import SceneError
    from mincam_render.scenes import load_family

    try:
        probe = load_family(scene, seed=seed, num_frames=1)
        num_frames = max(1, int(round(duration_s * probe.fps)))
        family = load_family(scene, seed=seed, num_frames=num_frames)
        frames = sorted({int(round(x)) for x in np.linspace(0, num_frames - 1, n_shown)})
        out.mkdir(parents=True, exist_ok=True)
        path = render_preview(
            family, frames, out / f"preview_{family.name}.png", spp=spp, progress=True
        )
    except (ConfigError, SceneError, ValueError, ImportError) as err:
        raise _user_error(err) from None
    click.echo(f"wrote {path}")


# ---- training, sweeps, pruning, mask export (mincam_render.learn.train / .masks) ----------


def _int_list(ctx, param, value):
    if value is None:  # the option's default: decided by the command
        return None
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not comma-separated integers, e.g. 1,2,4,8"
        ) from None
    if not out or min(out) < 1:
        raise click.BadParameter(f"{value!r}: need integers >= 1")
    return out


def _grid_list(ctx, param, value):
    try:
        return [_grid(ctx, param, v.strip()) for v in value.split(",") if v.strip()]
    except click.BadParameter:
        raise click.BadParameter(f"{value!r} is not a list of ROWSxCOLS, e.g. 2x2,4x4") from None


def _training_options(f):
    """Options shared by train, sweep and prune (the paper's recipe as defaults)."""
    opts = [
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
        click.option(
            "--steps",
            type=click.IntRange(1),
            default=3000,
            show_default=True,
            help="Maximum training steps (early stopping may end sooner).",
        ),
        click.option("--batch-size", type=click.IntRange(2), default=64, show_default=True),
        click.option(
            "--lr",
            type=FiniteFloat(0, 1, min_open=True, max_open=True),
            default=None,
            help="Head learning rate [default: 1e-3*min(1,sqrt(16/inputs))].",
        ),
        click.option(
            "--mask-lr",
            type=FiniteFloat(0, 10),
            default=0.05,
            show_default=True,
            help="Adam learning rate of the mask logits.",
        ),
        click.option("--eval-every", type=click.IntRange(1), default=100, show_default=True),
        click.option(
            "--patience",
            type=click.IntRange(1),
            default=8,
            show_default=True,
            help="Evaluations without validation improvement before stopping.",
        ),
        click.option("--seed", type=click.IntRange(0), default=0, show_default=True),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _config(steps, batch_size, lr, mask_lr, eval_every, patience, seed):
    from mincam_render.learn.train import TrainConfig

    return TrainConfig(
        max_steps=steps,
        batch_size=batch_size,
        lr=lr,
        mask_lr=mask_lr,
        eval_every=eval_every,
        patience=patience,
        seed=seed,
    )


def _splits(dataset, family, frames, spp, seed):
    """(train, val, test) TrainingData from a dataset directory or an in-memory render."""
    from mincam_render.learn.train import TrainingData

    if dataset is not None:
        from mincam_render.data.dataset import open_dataset

        ds = open_dataset(dataset)
        sizes = {name: stop - start for name, (start, stop) in ds.splits.items()}
        empty = [name for name in ("train", "val") if sizes.get(name, 0) == 0]
        if empty:
            raise InputError(
                f"{dataset} has no {' and no '.join(empty)} frames (split sizes {sizes}): "
                "training needs both; render it with e.g. --splits 0.7,0.1,0.2"
            )
        return tuple(TrainingData.from_dataset(ds, s) for s in ("train", "val", "test"))
    if family is None:
        raise InputError("give a DATASET directory (mincam-render render) or --family")
    from mincam_render.scenes import load_family

    fam = load_family(family, seed=seed, num_frames=frames)
    log.info("rendering %d frames of %s in memory (%d spp)", frames, fam.name, spp)
    data = TrainingData.render(fam, range(frames), spp=spp, seed=seed, progress=True)
    return data.split((0.7, 0.1, 0.2))


# OSError: a full disk or an unreadable file; ImportError: a missing extra (the
# traffic family needs SUMO), whose message names the extra
_TRAIN_ERRORS = (ValueError, KeyError, RuntimeError, OSError, ImportError)


@main.command("train")
@_training_options
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/train"),
    show_default=True,
    help="Run directory (created; an existing checkpoint there is resumed).",
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
    callback=lambda c, p, v: None if v is None else _grid(c, p, v),
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
def train_cmd(
    dataset,
    family,
    frames,
    spp,
    steps,
    batch_size,
    lr,
    mask_lr,
    eval_every,
    patience,
    seed,
    out,
    pixels,
    baseline,
    no_sensor_model,
    on_the_fly,
    export_dir,
    no_resume,
):
    """Train a minimalist (or baseline) camera end to end; metrics on the test split.

    Reads a dataset written by `mincam-render render`, or renders --frames of a
    scene family in memory. Writes checkpoint.pt (resumable), TensorBoard event
    files, history.jsonl, mask_evolution.png, run.json and metrics.json
    (test RMSE/accuracy after rounding and median filtering) into --out.

    \b
    Example:
      mincam-render train --family patches --frames 300 --pixels 4 --steps 200 \\
          --out runs/patches4
    """
    from mincam_render.learn.train import RenderedBatches, run_masks, train_run

    try:
        config = _config(steps, batch_size, lr, mask_lr, eval_every, patience, seed)
        if no_resume and (out / "checkpoint.pt").exists():
            (out / "checkpoint.pt").unlink()
        train, val, test = _splits(dataset, family, frames, spp, seed)
        stream = None
        if on_the_fly:
            if family is None:
                raise InputError("--on-the-fly needs --family (frames are rendered)")
            from mincam_render.scenes import load_family

            n = steps * batch_size * train.history
            stream = RenderedBatches(
                load_family(family, seed=seed + 1, num_frames=n), batch_size, spp=spp, seed=seed + 1
            )
        metrics = train_run(
            train,
            val,
            test,
            out,
            pixels=pixels,
            baseline_grid=baseline,
            sensor_model=not no_sensor_model,
            config=config,
            on_the_fly=stream,
            resume=not no_resume,
            progress=True,
        )
        if export_dir is not None and baseline is None:
            from mincam_render.export.masks import export_masks

            m, camera, run = run_masks(out)
            export_masks(
                m,
                camera,
                export_dir,
                task=str(train.source.get("family", "")),
                provenance={"run": str(out), "data": run["data"]},
            )
    except _TRAIN_ERRORS as err:
        raise _user_error(err) from None
    t = metrics["test"]
    click.echo(
        f"{metrics['model']['kind']} {metrics['model']['pixels']} px: test "
        f"{t['error_name']} = {t['error']:.4f} after {metrics['steps']} steps "
        f"({metrics['train_wall_time_s']:.1f} s); wrote {out / 'metrics.json'}"
    )


@main.command("sweep")
@_training_options
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/sweep"),
    show_default=True,
    help="Output directory (created).",
)
@click.option(
    "--pixels",
    "pixel_counts",
    default=None,
    callback=_int_list,
    help="Minimalist-camera pixel counts (default: 1, 2, 4, ... up to the rendered detectors).",
)
@click.option(
    "--baselines",
    default="1x1,2x2,4x4,8x8,16x16",
    show_default=True,
    callback=_grid_list,
    help="Baseline resolutions ROWSxCOLS.",
)
def sweep_cmd(
    dataset,
    family,
    frames,
    spp,
    steps,
    batch_size,
    lr,
    mask_lr,
    eval_every,
    patience,
    seed,
    out,
    pixel_counts,
    baselines,
):
    """Task error against pixel count: minimalist cameras vs baselines (log axis).

    Every camera gets the same training budget. Writes sweep.png, sweep.md,
    sweep.json and one resumable run directory per camera into --out.

    \b
    Example:
      mincam-render sweep --family patches --frames 300 --steps 100 --pixels 1,4 \\
          --baselines 2x2,8x8 --out runs/sweep_patches
    """
    from mincam_render.learn.train import sweep

    try:
        config = _config(steps, batch_size, lr, mask_lr, eval_every, patience, seed)
        train, val, test = _splits(dataset, family, frames, spp, seed)
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
        raise _user_error(err) from None
    from mincam_render.learn.train import sweep_table

    click.echo(sweep_table(rows))
    click.echo(f"wrote {out / 'sweep.png'}, sweep.md, sweep.json")


@main.command("prune")
@_training_options
@click.option(
    "--run",
    "run_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="A minimalist-camera run directory from `mincam-render train`.",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/prune"),
    show_default=True,
    help="Output directory (created).",
)
def prune_cmd(
    dataset,
    family,
    frames,
    spp,
    steps,
    batch_size,
    lr,
    mask_lr,
    eval_every,
    patience,
    seed,
    run_dir,
    out,
):
    """Greedy pruning (supplement C): drop the least useful pixel, retrain the head, repeat.

    Use the same data as the run. Writes prune.json and prune.png (test error
    against pixel count) into --out.

    \b
    Example:
      mincam-render prune --family patches --frames 300 --steps 100 \\
          --run runs/patches4 --out runs/patches4_prune
    """
    from mincam_render.learn.models import CountLoss
    from mincam_render.learn.train import build_mincam, greedy_prune, load_run, plot_sweep

    try:
        config = _config(steps, batch_size, lr, mask_lr, eval_every, patience, seed)
        run, state = load_run(run_dir)
        if run["model"]["kind"] != "mincam":
            raise ValueError(f"{run_dir}: only minimalist-camera runs can be pruned")
        train, val, test = _splits(dataset, family, frames, spp, seed)
        # the run's own count loss (its description lists count_classes when classified)
        loss = CountLoss.CROSS_ENTROPY if "count_classes" in run["model"] else CountLoss.MSE
        model = build_mincam(
            train,
            detectors=run["model"]["detectors"],
            sensor_model=run["model"]["sensor_model"],
            count_loss=loss,
        )
        model.load_state_dict(state)
        records = greedy_prune(model, train, val, test, config, progress=True)
    except _TRAIN_ERRORS as err:
        raise _user_error(err) from None
    out.mkdir(parents=True, exist_ok=True)
    (out / "prune.json").write_text(json.dumps(records, indent=2, default=str))
    rows = [
        {
            "kind": "mincam",
            "pixels": r["pixels"],
            "error": r["test"]["error"],
            "error_name": r["test"]["error_name"],
        }
        for r in records
    ]
    plot_sweep(rows, out / "prune.png", title="greedy pruning")
    for r in records:
        click.echo(
            f"{r['pixels']:3d} px  removed {r['removed']}  "
            f"test {r['test']['error_name']} = {r['test']['error']:.4f}"
        )
    click.echo(f"wrote {out / 'prune.json'}, prune.png")


@main.command("export-masks")
@click.argument("run_dir", type=click.Path(file_okay=False, path_type=Path))
@click.option("--task", default=None, help="Task name [default: the run's scene family].")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("masks"),
    show_default=True,
    help="Masks go into OUT/<task>/.",
)
@click.option("--no-pdf", is_flag=True, help="Skip the PDF print sheet.")
def export_masks_cmd(run_dir, task, out, no_pdf):
    """Export a trained camera's masks for printing.

    Writes into OUT/<task>/: mask_NN.png (16-bit transmittance), masks.exr,
    print_sheet.svg/.pdf at true size with cut marks and labels, masks.json.

    \b
    Example:
      mincam-render export-masks runs/patches4 --task patches --out masks
    """
    from mincam_render.export.masks import export_masks
    from mincam_render.learn.train import run_masks

    try:
        m, camera, run = run_masks(run_dir)
        task = task or str(run["data"]["train"].get("family") or "task")
        paths = export_masks(
            m,
            camera,
            out / task,
            task=task,
            pdf=not no_pdf,
            provenance={"run": str(run_dir), "data": run["data"]},
        )
    except _TRAIN_ERRORS as err:
        raise _user_error(err) from None
    click.echo(
        f"wrote {len(paths['png'])} masks to {out / task} "
        f"(PNG, EXR, print_sheet.svg{'' if no_pdf else '/.pdf'}, masks.json)"
    )


def _render_splits(ctx, param, value):
    try:
        parts = tuple(float(p) for p in value.split(","))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not three fractions, e.g. 0.7,0.15,0.15") from None
    if len(parts) != 3:
        raise click.BadParameter(f"{value!r}: expected three fractions train,val,test")
    return parts


def _render_settings(ctx, param, values):
    import tomllib

    out: dict = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{item!r} is not KEY=VALUE, e.g. camera.detectors=8")
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw  # a bare string
        node = out
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


@main.command("render")
@click.argument("family")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Dataset directory (created; an unfinished one is resumed).",
)
@click.option("--frames", type=click.IntRange(1, 10**9), required=True, help="Frames to render.")
@click.option(
    "--seed",
    type=click.IntRange(0, 2**63 - 1),
    default=0,
    show_default=True,
    help="Dataset seed (scene trajectories and per-frame render seeds).",
)
@click.option(
    "--shard-frames",
    type=click.IntRange(1, 1 << 20),
    default=256,
    show_default=True,
    help="Frames per shard file.",
)
@click.option(
    "--splits",
    callback=_render_splits,
    default="0.7,0.15,0.15",
    show_default=True,
    help="Train,val,test fractions (contiguous in time).",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    callback=_render_settings,
    metavar="KEY=VALUE",
    help="Override a scene description value (TOML syntax), repeatable.",
)
@click.option(
    "--detectors",
    type=click.IntRange(1, 64),
    default=None,
    help="Number of freeform pixels (same as --set camera.detectors=N).",
)
@click.option(
    "--fidelity",
    type=click.Choice(["auto", "full"]),
    default="auto",
    show_default=True,
    help="auto: measure what the scene needs; full: no shortcuts.",
)
@click.option(
    "--spp",
    type=click.IntRange(1, 1 << 20),
    default=None,
    help="Samples per texel (default: from --target-error).",
)
@click.option(
    "--max-depth",
    type=click.IntRange(0, 64),
    default=None,
    help="Path depth (2 = direct light, 0 = the scene's integrator).",
)
@click.option(
    "--shared-render/--per-detector",
    default=None,
    help="One render for all detectors, or one per detector (default: by parallax).",
)
@click.option(
    "--differential/--no-differential",
    default=None,
    help="Render frames as a converged static background plus what the movers change "
    "(default: when cheaper at the target error; indoor families only).",
)
@click.option(
    "--background-interval",
    "background_interval_s",
    type=FiniteFloat(1e-3, 1e6),
    default=60.0,
    show_default=True,
    help="Scene seconds between the daylight components a background is interpolated "
    "between (--differential).",
)
@click.option(
    "--shared-difference/--per-detector-difference",
    default=None,
    help="With --differential: render the movers' change once from the board centre "
    "for all detectors (default: when its parallax error is below a share of the target).",
)
@click.option(
    "--background-spp",
    type=click.IntRange(1, 1 << 20),
    default=None,
    help="Samples per texel of the static backgrounds (default: from --target-error).",
)
@click.option(
    "--mask-res",
    type=click.IntRange(1, 4096),
    default=None,
    help="Mask texels per side (default: the family camera's).",
)
@click.option(
    "--dtype",
    type=click.Choice(["float16", "float32"]),
    default=None,
    help="Storage type (default: float16 if within --dtype-error).",
)
@click.option(
    "--target-error",
    type=FiniteFloat(1e-6, 1.0),
    default=0.01,
    show_default=True,
    help="Target relative measurement error (chooses spp).",
)
@click.option(
    "--dtype-error",
    type=FiniteFloat(1e-9, 1.0),
    default=1e-3,
    show_default=True,
    help="Largest relative measurement error float16 may add.",
)
@click.option(
    "--workers",
    type=click.IntRange(0, 256),
    default=None,
    help="Local worker processes, the cores shared among them (0 = in this process). "
    "Default: by job size; the first shard renders in this process, the rest in one "
    "worker per core only if that would take this process more than 10 s.",
)
@click.option(
    "--ray",
    "ray_address",
    default=None,
    metavar="ADDRESS",
    help="Render on a Ray cluster ('local' starts one; needs the ray extra).",
)
@click.option(
    "--replan",
    is_flag=True,
    help="Measure the fidelity plan again instead of reusing a kept plan of the same "
    "description, camera, targets and frame count.",
)
@click.option("--no-progress", is_flag=True, help="Hide the progress bar.")
def render_cmd(
    family,
    out,
    frames,
    seed,
    shard_frames,
    splits,
    overrides,
    detectors,
    fidelity,
    spp,
    max_depth,
    shared_render,
    differential,
    background_interval_s,
    background_spp,
    shared_difference,
    mask_res,
    dtype,
    target_error,
    dtype_error,
    workers,
    ray_address,
    replan,
    no_progress,
):
    """Render a dataset of transport images T[frame, detector, row, col] with labels.

    FAMILY is a scene family name (patches, workspace, lighting, traffic) or a
    scene TOML file. The same command after an interruption resumes and gives
    the same bytes as an uninterrupted run; a different configuration into a
    non-empty --out is refused. The fidelity plan is measured once per
    description, camera, targets and frame count (on the seed-0 episode, so every
    seed shares it) and kept; shipped plans (scenes/plans/) start at once.
    Format: docs/dataset_format.md.

    \b
    Example:
      mincam-render render patches --out runs/patches-ds --frames 512 --workers 2
      mincam-render render patches --out runs/tiny --frames 40 --shard-frames 8 \\
          --detectors 2 --mask-res 8 --spp 4
    """
    from mincam_render.data.dataset import DatasetError
    from mincam_render.data.render_job import RenderError, RenderRequest, render_dataset

    if detectors is not None:
        overrides = {**overrides, "camera": {**overrides.get("camera", {}), "detectors": detectors}}
    try:
        request = RenderRequest(
            family=str(family),
            num_frames=frames,
            seed=seed,
            overrides=overrides or None,
            shard_frames=shard_frames,
            splits=splits,
            fidelity=fidelity,
            spp=spp,
            max_depth=max_depth,
            shared_render=shared_render,
            differential=differential,
            background_interval_s=background_interval_s,
            background_spp=background_spp,
            shared_difference=shared_difference,
            mask_res=mask_res,
            dtype=dtype,
            target_error=target_error,
            dtype_error_bound=dtype_error,
        )
        summary = render_dataset(
            request,
            out,
            workers=workers,
            ray_address=ray_address,
            progress=not no_progress,
            use_plan_cache=not replan,
        )
    except (ValueError, DatasetError, RenderError, OSError, ImportError) as err:
        raise _user_error(err) from None
    click.echo(
        f"{out}: {summary.num_frames} frames in {summary.shards_total} shards; rendered "
        f"{len(summary.shards_rendered)}, kept {len(summary.shards_kept)}, repaired "
        f"{len(summary.shards_repaired)}; {summary.seconds:.1f} s "
        f"({summary.frames_per_s:.1f} frames/s)"
    )


@main.command("export-exr")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--frames",
    "frame_list",
    required=True,
    help="Frame indices, e.g. 0,5,10-12 (ranges inclusive).",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Directory for frame-NNNNNN.exr files (created).",
)
def export_exr_cmd(dataset, frame_list, out):
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
        raise _user_error(err) from None
    click.echo(f"wrote {len(paths)} EXR file(s) to {out}")


@main.command("repair")
@click.argument("dataset", type=click.Path(file_okay=False, path_type=Path))
def repair_cmd(dataset):
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
        raise _user_error(err) from None
    restored = ", ".join(summary.restored_fields) or "none"
    click.echo(
        f"{dataset}: manifest rebuilt; kept {len(summary.kept)} of {summary.num_shards} "
        f"shards; fields restored from the request's plan: {restored}"
    )
    for shard, reason in summary.dropped.items():
        click.echo(f"  shard {shard}: {reason}; the same `render` command renders it again")


def _episode_options(f):
    """Options of the commands that render independent episodes and compare designs.

    Defaults are :class:`ComparisonConfig`'s (one source of truth).
    """
    from mincam_render.analysis.comparison_config import ComparisonConfig as C

    options = [
        click.option("--family", default=C.family, show_default=True,
                     help="Scene family name or scene description (.toml)."),
        click.option("--train-episodes", type=click.IntRange(1, 100),
                     default=C.train_episodes, show_default=True,
                     help="Training episodes (other scene seeds; temporal tasks: 1)."),
        click.option("--train-frames", type=click.IntRange(30), default=C.train_frames,
                     show_default=True,
                     help="Frames of each training episode (at --fps)."),
        click.option("--val-frames", type=click.IntRange(30), default=C.val_frames,
                     show_default=True,
                     help="Frames of the validation episode."),
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
        click.option("--spp", type=click.IntRange(1, 1 << 20), default=None,
                     help="Render at a fixed quick fidelity (SPP samples per texel, every "
                     "detector, the scene's path depth) instead of the measured (auto) "
                     "fidelity."),
        click.option("--fps", type=FiniteFloat(0.1, 1000.0), default=C.fps,
                     show_default=True, help="Frame rate of the episodes (overrides the "
                     "family's): at 2 fps, 1,200 frames cover 10 minutes of activity."),
    ]  # fmt: skip
    for option in reversed(options):
        f = option(f)
    return f


def _family_detectors(family: str) -> int:
    """Detectors of a family's camera (its default pixel count)."""
    from mincam_render.core.config import ConfigError
    from mincam_render.scenes.registry import load_family

    try:
        return load_family(family, seed=0, num_frames=30).camera().num_detectors
    except ConfigError as err:
        raise _user_error(err) from None


def _compare(out: Path, designs: tuple, **episode) -> dict:
    """Run :func:`run_comparison` for the episode options and ``designs``; print the figures."""
    from mincam_render.analysis.comparison import ComparisonConfig, run_comparison
    from mincam_render.core.config import ConfigError
    from mincam_render.data.render_job import RenderError
    from mincam_render.learn.train import TrainConfig
    from mincam_render.render.mitsuba_scene import SceneError

    t0 = time.perf_counter()
    spp, steps, workers = episode.pop("spp"), episode.pop("steps"), episode.pop("workers")
    quick = {"spp": spp, "max_depth": 0, "shared_render": False, "differential": False}
    try:
        cfg = ComparisonConfig(
            **episode,
            designs=designs,
            train=TrainConfig(max_steps=steps),
            fidelity=quick if spp is not None else {},
        )
        click.echo(
            f"[1/2] episodes of {cfg.family}: train {cfg.train_episodes} x {cfg.train_frames}, "
            f"val {cfg.val_frames}, "
            f"test {cfg.test_episodes} x {cfg.test_frames} frames; {len(designs)} designs x "
            f"{cfg.seeds} seeds"
        )
        result = run_comparison(cfg, out, workers=workers, masks_dir=out / "masks")
    except (ConfigError, SceneError, RenderError, ValueError, OSError) as err:
        raise _user_error(err) from None
    click.echo(f"[2/2] test {result['error_name']}, mean over {cfg.seeds} seeds [95 % CI]")
    for name, d in result["designs"].items():
        e = d["error"]
        state = d["state"]
        click.echo(
            f"  {name:18s} {e['mean']:.3f} [{e['ci95'][0]:.3f}, {e['ci95'][1]:.3f}]  "
            f"({state}; {sum(d['train_wall_time_s']):.0f} s training)"
        )
    t = result["trivial"]["error"]
    click.echo(f"  {'trivial':18s} {t['mean']:.3f} [{t['ci95'][0]:.3f}, {t['ci95'][1]:.3f}]")
    if result["verdict"]:
        click.echo(f"  verdict: {result['verdict']}")
    for name, against in result["versus_trivial"].items():
        click.echo(f"  {name} against the trivial predictor: {against}")
    click.echo(
        f"  {time.perf_counter() - t0:.0f} s; figure {result['figure']}; masks in "
        f"{out / 'masks' / result['task']}/; metrics {out / 'metrics.json'}"
    )
    return result


@main.command("pipeline")
@_episode_options
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/main"),
    show_default=True,
    help="Output directory (episodes, runs, figure, metrics, masks).",
)
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
    callback=_grid,
    help="Baseline camera resolution ROWSxCOLS.",
)
def pipeline_cmd(out, pixels, baseline_grid, **episode):
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
    from mincam_render.analysis.comparison import Design

    pixels = pixels or _family_detectors(episode["family"])
    _compare(out, (Design(pixels=pixels), Design(grid=baseline_grid)), **episode)


@main.command("study")
@_episode_options
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Output directory (episodes, runs, figure, metrics, table, masks).",
)
@click.option(
    "--pixels",
    default=None,
    callback=_int_list,
    help="Minimalist-camera pixel counts (default: 1, 2, 4, ... up to the family's detectors).",
)
@click.option(
    "--baseline-grids",
    default="2x2,4x4,8x8,16x16,32x32",
    show_default=True,
    callback=_grid_list,
    help="Baseline resolutions.",
)
@click.option(
    "--ablation/--no-ablation",
    default=False,
    help="Also train every minimalist camera without the detector model (supplement A).",
)
@click.option(
    "--reference-pixels",
    type=click.IntRange(1),
    default=4,
    show_default=True,
    help="Pixel count of the design whose pixel reduction factor is reported.",
)
def study_cmd(out, pixels, baseline_grids, ablation, reference_pixels, **episode):
    """A sweep of minimalist cameras against baselines on independent episodes.

    Like `pipeline`, with every design of --pixels (and, with --ablation, the
    same cameras trained without the detector model) and --baseline-grids;
    adds OUT/study.md (the table, with convergence and the trivial predictor)
    and the pixel reduction factor of the --reference-pixels camera: the
    baseline pixels of the smallest baseline whose interval overlaps or beats
    it, over its pixels.

    \b
    Example:
      mincam-render study --family patches --out runs/study-patches --spp 16
    """
    from mincam_render.analysis.comparison import Design, study_table, summarise_study
    from mincam_render.learn.train import default_pixel_counts

    pixels = pixels or default_pixel_counts(_family_detectors(episode["family"]))
    if reference_pixels not in pixels:
        raise click.BadParameter(
            f"{reference_pixels} is not among --pixels {pixels}", param_hint="--reference-pixels"
        )
    designs = [Design(pixels=k) for k in pixels]
    if ablation:
        designs += [Design(pixels=k, sensor_model=False) for k in pixels]
    designs += [Design(grid=g) for g in baseline_grids]
    result = summarise_study(
        _compare(out, tuple(designs), **episode), f"mincam-{reference_pixels}px"
    )
    (out / "metrics.json").write_text(json.dumps(result, indent=2, default=str) + "\n")
    (out / "study.md").write_text(study_table(result) + "\n")
    click.echo(study_table(result))


@main.group("bench")
def bench_group() -> None:
    """Benchmarks: measured error against run time."""


@bench_group.command("fidelity")
@click.argument("families", nargs=-1, required=True)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/bench-fidelity"),
    show_default=True,
    help="Output directory (created): fidelity.json, pareto_<family>.png, fidelity.html.",
)
@click.option(
    "--frames",
    type=click.IntRange(1, 1000),
    default=2,
    show_default=True,
    help="Frames rendered per setting, spread over the sequence.",
)
@click.option(
    "--reference-spp",
    type=click.IntRange(2, 1 << 20),
    default=256,
    show_default=True,
    help="Samples per texel of the converged reference.",
)
@click.option(
    "--base-spp",
    type=click.IntRange(1, 1 << 20),
    default=16,
    show_default=True,
    help="Samples per texel of the base setting the knobs start from.",
)
@click.option(
    "--mask-res",
    type=click.IntRange(1, 4096),
    default=None,
    help="Mask texels per side (default: the family camera's).",
)
@click.option("--no-auto", is_flag=True, help="Skip the automatic fidelity decision.")
@click.option("--seed", type=click.IntRange(0, 2**63 - 1), default=0, show_default=True)
def bench_fidelity_cmd(families, out, frames, reference_spp, base_spp, mask_res, no_auto, seed):
    """Error of detector measurements against run time for every fidelity knob.

    \b
    Example:
      mincam-render bench fidelity workspace --out runs/bench-fidelity
    """
    from mincam_render.analysis.fidelity_bench import (
        FidelityBenchConfig,
        bench_fidelity,
        pareto_table,
        write_fidelity_report,
    )
    from mincam_render.core.config import ConfigError

    try:
        cfg = FidelityBenchConfig(
            num_frames=frames,
            reference_spp=reference_spp,
            base_spp=base_spp,
            mask_resolution=mask_res,
            include_auto=not no_auto,
            seed=seed,
        )
        results = [bench_fidelity(f, cfg) for f in families]
        paths = write_fidelity_report(results, out)
    except (ValueError, ConfigError, OSError) as err:
        raise _user_error(err) from None
    for r in results:
        click.echo(f"== {r['family']}\n{pareto_table(r)}\n" + "\n".join(r["statements"]))
    click.echo(f"wrote {paths['json']} and {paths['html']}")


@main.group("report")
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
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("runs/sim2real"),
    show_default=True,
    help="Output directory (created): sim2real.html and sim2real.json.",
)
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
def report_sim2real_cmd(measurements, surrogate_family, frames, out, spp, steps, seed):
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
        result = analyze_sim2real(measurements, spp=spp, steps=steps, seed=seed, progress=True)
        paths = write_sim2real_report(result, out)
    except (ValueError, ConfigError, Sim2RealError, OSError) as err:
        raise _user_error(err) from None
    click.echo(result["verdict"]["summary"])
    click.echo(f"wrote {paths['json']} and {paths['html']}")


if __name__ == "__main__":
    main()
