"""The ``mincam-render`` command line (one entry point, subcommands)."""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

import click
import numpy as np

from . import __name__ as _pkg

MM = 1e-3
log = logging.getLogger(_pkg)


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
    "--pitch-mm", type=float, default=20.0, show_default=True, help="Detector pitch (mm)."
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
    "--max-depth",
    type=click.IntRange(1, 64),
    default=None,
    help="Override the scene's path depth (1 = emitters only).",
)
def transport_cmd(
    scene, out, spp, seed, mask_res, grid, pitch_mm, position, look_at, up, max_depth
):
    """Render transport images T[detector, row, col] of a camera in a scene.

    SCENE is a Mitsuba XML file; without it the built-in demo scene is used.
    Writes transport.exr (one channel per detector, watts), transport.png and
    config.json (the resolved configuration) into --out.

    \b
    Example:
      mincam-render transport --out runs/demo --spp 16 --mask-res 32
    """
    from . import backend
    from .camera import DetectorLayout, FreeformCamera
    from .exr import write_transport_exr
    from .mitsuba_scene import SceneError, demo_scene
    from .plots import plot_transport_grid
    from .transport import render_transport

    try:
        camera = FreeformCamera(
            mask_resolution=(mask_res, mask_res),
            layout=DetectorLayout.grid(rows=grid[0], cols=grid[1], pitch_m=pitch_mm * MM),
            position=position,
            look_at=look_at,
            up=up,
        )
        scene_input = str(scene) if scene is not None else demo_scene()
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
        t = render_transport(scene_input, camera, spp=spp, seed=seed, max_depth=max_depth)
        seconds = time.perf_counter() - t0
    except (ValueError, SceneError, backend.BackendUnavailableError) as err:
        raise click.ClickException(str(err)) from None
    out.mkdir(parents=True, exist_ok=True)
    config = {
        "scene": str(scene) if scene is not None else "builtin:demo",
        "spp": spp,
        "seed": seed,
        "max_depth": max_depth,
        "camera": camera.to_dict(),
        "backend": info,
        "render_seconds": seconds,
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
        f"{t.sum(axis=(1, 2)).mean():.3e} W per detector"
    )


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
    type=click.FloatRange(0.0, min_open=True),
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
    from .config import ConfigError
    from .generators import load_family
    from .mitsuba_scene import SceneError
    from .preview import render_preview

    try:
        probe = load_family(scene, seed=seed, num_frames=1)
        num_frames = max(1, int(round(duration_s * probe.fps)))
        family = load_family(scene, seed=seed, num_frames=num_frames)
        frames = sorted({int(round(x)) for x in np.linspace(0, num_frames - 1, n_shown)})
        out.mkdir(parents=True, exist_ok=True)
        path = render_preview(family, frames, out / f"preview_{family.name}.png", spp=spp)
    except (ConfigError, SceneError, ValueError, ImportError) as err:
        raise click.ClickException(str(err)) from None
    click.echo(f"wrote {path}")


if __name__ == "__main__":
    main()
