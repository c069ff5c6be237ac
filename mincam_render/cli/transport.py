"""``mincam-render transport``: transport images of one camera in a Mitsuba scene."""

from __future__ import annotations

import dataclasses
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
import numpy as np

from mincam_render.core import strict_json
from mincam_render.core.strict_json import JsonObject

from . import __name__ as _pkg
from .errors import user_error
from .options import FiniteFloat, grid, out_option, vec3

if TYPE_CHECKING:
    import mitsuba as mi

    from mincam_render.optics.camera import FreeformCamera
    from mincam_render.render.user_scene import Pose

MM = 1e-3
log = logging.getLogger(_pkg)


@dataclasses.dataclass(frozen=True, kw_only=True)
class _PoseOptions:
    """The options placing the camera in the scene (lengths in m)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    pose_from_sensor: bool
    sensor_id: str | None
    scene_scale: float


@dataclasses.dataclass(frozen=True, kw_only=True)
class _TransportRun:
    """One render: its backend, seconds, per-detector relative noise and warnings."""

    backend: dict[str, str]
    seconds: float
    noise: np.ndarray
    warnings: list[str]


@click.command("transport")
@click.argument("scene", required=False, type=click.Path(dir_okay=False, path_type=Path))
@out_option("Output directory (created).", default="runs/transport")
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
    callback=grid,
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
    "--position", callback=vec3, default="0,0,0", show_default=True, help="Board centre x,y,z (m)."
)
@click.option(
    "--look-at",
    callback=vec3,
    default="0,0,1",
    show_default=True,
    help="Point the board faces x,y,z (m).",
)
@click.option(
    "--up",
    callback=vec3,
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
def transport_cmd(
    ctx: click.Context,
    scene: Path | None,
    out: Path,
    spp: int,
    seed: int,
    mask_res: int,
    grid: tuple[int, int],
    pitch_mm: float,
    max_depth: int | None,
    **pose: Any,
) -> None:
    """Render transport images T[detector, row, col] of a camera in a scene.

    SCENE is a Mitsuba XML file; without it the built-in demo scene is used.
    Writes transport.exr (one channel per detector, watts), transport.png and
    config.json (the resolved configuration) into --out.

    \b
    Example:
      mincam-render transport --out runs/demo --spp 16 --mask-res 32
    """
    from mincam_render.render import backend, user_scene
    from mincam_render.render.mitsuba_scene import SceneError

    options = _PoseOptions(**pose)
    try:
        mi_scene, camera = _scene_and_camera(ctx, scene, mask_res, grid, pitch_mm, options)
        t, run = _render(mi_scene, camera, spp, seed, max_depth)
    except (ValueError, SceneError, backend.BackendUnavailableError) as err:
        raise user_error(err) from None
    noise = run.noise
    spp_target = user_scene.spp_for_noise(spp, noise)
    worst = float(np.nanmax(noise))
    if worst > user_scene.TARGET_RELATIVE_NOISE:
        run.warnings.append(
            f"worst detector relative error {worst:.1%}: --spp {spp_target} reaches 1 %"
        )
        log.warning("%s", run.warnings[-1])
    config = {
        "scene": str(scene) if scene is not None else "builtin:demo",
        "scene_scale": ctx.params["scene_scale"],
        "pose_from_sensor": options.pose_from_sensor,
        "spp": spp,
        "seed": seed,
        "max_depth": max_depth,
        "camera": camera.to_dict(),
        "backend": run.backend,
        "render_seconds": run.seconds,
        "relative_noise": [None if np.isnan(x) else float(x) for x in noise],
        "spp_for_1_percent": spp_target,
        "warnings": run.warnings,
        "units": {"transport": "W per unit transmittance", "lengths": "m"},
        "array_axes": "T[detector, row, col]; row 0 = up side, col 0 = left, seen from the camera",
    }
    _write(out, config, t, camera)
    click.echo(
        f"wrote {out / 'transport.exr'} ({t.shape[0]} detectors, {t.shape[1]}x{t.shape[2]}), "
        f"transport.png, config.json; render {run.seconds:.2f} s; total power at M=1: "
        f"{t.sum(axis=(1, 2)).mean():.3e} W per detector; worst detector relative error "
        f"{worst:.2%} (--spp {spp_target} for 1 %)"
    )


def _scene_and_camera(
    ctx: click.Context,
    scene: Path | None,
    mask_res: int,
    grid: tuple[int, int],
    pitch_mm: float,
    options: _PoseOptions,
) -> tuple[mi.Scene, FreeformCamera]:
    """The Mitsuba scene (rescaled) and the freeform camera the options describe."""
    from mincam_render.optics.camera import DetectorLayout, FreeformCamera
    from mincam_render.render import user_scene
    from mincam_render.render.mitsuba_scene import demo_scene, load_scene

    mi_scene = load_scene(str(scene) if scene is not None else demo_scene())
    user_scene.rescale_scene(mi_scene, options.scene_scale)
    pose = _transport_pose(ctx, mi_scene, options)
    camera = FreeformCamera(
        mask_resolution=(mask_res, mask_res),
        layout=DetectorLayout.grid(rows=grid[0], cols=grid[1], pitch_m=pitch_mm * MM),
        position=pose.position,
        look_at=pose.look_at,
        up=pose.up,
    )
    return mi_scene, camera


def _render(
    mi_scene: mi.Scene, camera: FreeformCamera, spp: int, seed: int, max_depth: int | None
) -> tuple[np.ndarray, _TransportRun]:
    """``T[detector, row, col]`` (W) and the run's backend, seconds, noise and warnings."""
    from mincam_render.render import backend, user_scene
    from mincam_render.render.transport import render_transport_with_noise

    warnings = user_scene.check_scene(mi_scene, camera, require_emitter=True)
    info = backend.describe()
    mask_res = camera.mask_resolution[0]
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
    warnings += user_scene.check_transport(t, mi_scene)
    return t, _TransportRun(backend=info, seconds=seconds, noise=noise, warnings=warnings)


def _write(out: Path, config: JsonObject, t: np.ndarray, camera: FreeformCamera) -> None:
    """transport.exr, transport.png and config.json into ``out`` (created)."""
    from mincam_render.analysis.plots import plot_transport_grid
    from mincam_render.data.exr import write_transport_exr

    out.mkdir(parents=True, exist_ok=True)
    write_transport_exr(out / "transport.exr", t, config)
    plot_transport_grid(
        t,
        out / "transport.png",
        title=f"transport images, {config['scene']}, {config['spp']} spp",
        board_positions_m=np.asarray(camera.layout.positions_m),
    )
    (out / "config.json").write_text(strict_json.dumps(config))


def _transport_pose(ctx: click.Context, mi_scene: mi.Scene, options: _PoseOptions) -> Pose:
    """The camera pose from the options, or from the scene's sensor."""
    from mincam_render.render.user_scene import Pose, sensor_pose

    given = [
        name
        for name in ("position", "look_at", "up")
        if ctx.get_parameter_source(name) is not click.core.ParameterSource.DEFAULT
    ]
    if not options.pose_from_sensor:
        if options.sensor_id is not None:
            raise click.UsageError("--sensor-id needs --pose-from-sensor")
        return Pose(position=options.position, look_at=options.look_at, up=options.up)
    if given:
        flags = ", ".join("--" + name.replace("_", "-") for name in given)
        raise click.UsageError(f"--pose-from-sensor takes the pose from the scene: drop {flags}")
    return sensor_pose(mi_scene, options.sensor_id)
