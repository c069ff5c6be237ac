"""``mincam-render preview``: a few frames of a scene family with their labels drawn on."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from .errors import user_error
from .options import FiniteFloat, out_option


@click.command("preview")
@click.argument("scene")
@out_option("Output directory (created).", default="runs/preview")
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
def preview_cmd(
    scene: str, out: Path, seed: int, n_shown: int, duration_s: float, spp: int
) -> None:
    """Render a few frames of a scene family with their labels drawn on.

    SCENE is a family name (patches, workspace, lighting, traffic, or one an
    installed package registers), a family class (module:Class) or a path to a
    scene description (.toml; docs/your_own_task.md). Writes
    preview_<family>.png into --out: per frame the training camera's view, a
    bird's-eye view (when the family has one) and detector 0's transport image,
    with the frame's labels.

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
        raise user_error(err) from None
    click.echo(f"wrote {path}")
