"""Previews of scene families: what the camera sees, a bird's-eye view, and labels."""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.capabilities import Preview
from mincam_render.scenes.base import SceneFamily

if TYPE_CHECKING:
    import mitsuba as mi

log = logging.getLogger(__name__)


def _tonemap(img: np.ndarray, scale: float) -> np.ndarray:
    """Display values in [0, 1]: ``img / scale`` clipped, sRGB-like gamma."""
    x = np.clip(img / scale, 0.0, 1.0) if scale > 0 else np.zeros_like(img)
    return x ** (1 / 2.2)


def _format_labels(family: SceneFamily, labels: dict[str, np.ndarray]) -> str:
    parts = []
    for spec_ in family.labels:
        v = labels[spec_.name]
        if spec_.element_names:
            on = [n for n, x in zip(spec_.element_names, v, strict=False) if x > 0.5]
            parts.append(f"{spec_.name}: {', '.join(on) if on else 'none'}")
        else:
            unit = f" {spec_.unit}" if spec_.unit else ""
            parts.append(f"{spec_.name} = {float(v[0]):.3g}{unit}")
    return "\n".join(parts)


def _view_sensors(family: SceneFamily, width: int) -> dict[str, mi.Sensor]:
    """The perspective sensors of a preview, ``{title: Mitsuba sensor}``.

    The camera's view, and a bird's-eye view when the family has one
    (:class:`~mincam_render.render.capabilities.Preview`).
    """
    camera = family.camera()
    poses = {"camera view": (camera.position, camera.look_at, camera.up, camera.fov_deg)}
    if isinstance(family, Preview):
        bird = family.birdseye_view()
        poses["bird's-eye view"] = (bird.position, bird.look_at, bird.up, bird.fov_deg)
    return {title: ms.perspective_sensor(*pose, width, width) for title, pose in poses.items()}


def render_preview(
    family: SceneFamily,
    frames: list[int],
    path: str | os.PathLike,
    *,
    spp: int = 32,
    width: int = 320,
    transport_spp: int = 16,
    progress: bool = False,
) -> Path:
    """Save a PNG with, per frame: camera view, bird's-eye view (if any), detector 0's T, labels.

    Args:
        family: the scene family (its default camera is used).
        frames: frame indices to show.
        path: output PNG path.
        spp: samples per pixel of the perspective renders.
        width: pixel width of each perspective render.
        transport_spp: samples per texel of the transport image.
        progress: show a progress bar over the frames (stderr).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mitsuba as mi

    camera = family.camera()
    scene = family.build_scene()
    sensors = _view_sensors(family, width)
    from tqdm import tqdm

    rendered = []
    bar = tqdm(frames, desc=f"preview {family.name}", unit="frame", disable=not progress)
    for index in bar:
        bar.set_postfix_str(", ".join(sensors) + ", transport")
        labels = family.set_frame(scene, index)
        views = [
            np.asarray(mi.render(scene, sensor=sensor, spp=spp, seed=index))[..., 0]
            for sensor in sensors.values()
        ]
        views.append(family.render_transport(scene, camera, spp=transport_spp, seed=index)[0])
        rendered.append((index, labels, views))
    # one exposure per column for all frames, so brightness changes stay visible
    columns = len(sensors) + 1
    scales = [max(float(np.percentile(r[2][c], 99.0)) for r in rendered) for c in range(columns)]
    fig, axes = plt.subplots(
        len(frames), columns, figsize=(3.5 * columns, 3.6 * len(frames)), squeeze=False
    )
    for row, (index, labels, views) in enumerate(rendered):
        titles = [*sensors, "detector 0 transport T (mask open)"]
        titles[0] = f"frame {index} (t = {family.time_s(index):.2f} s): {titles[0]}"
        for ax, img, title, scale in zip(axes[row], views, titles, scales, strict=True):
            ax.imshow(_tonemap(img, scale), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            ax.set_title(title, fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
        axes[row][0].text(
            0.02,
            0.98,
            _format_labels(family, labels),
            transform=axes[row][0].transAxes,
            va="top",
            ha="left",
            fontsize=7,
            color="yellow",
            bbox={"facecolor": "black", "alpha": 0.6, "pad": 2},
        )
    fig.suptitle(f"{family.name}: seed {family.seed}, {family.fps:g} fps", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
