"""Scenes users bring: their units, their own sensor's pose, checks before and after a render.

A scene modelled in millimetres, a camera placed a light-year away or a scene
without a light source all render without an error and give useless numbers.
These checks turn such mistakes into an error or a warning that names the
option to change. They run on a loaded ``mi.Scene``, so XML files and dicts
take the same path.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.delta_lights import delta_emitters
from mincam_render.render.mitsuba_scene import SceneError

log = logging.getLogger(__name__)

#: A scene whose bounding box spans more than this (m) is probably not in metres.
UNIT_WARNING_EXTENT_M = 1000.0
#: The camera must lie within this many scene extents of the scene's bounding box.
MAX_CAMERA_DISTANCE_EXTENTS = 100.0
#: Relative standard error a render should reach (the target `transport` reports against).
TARGET_RELATIVE_NOISE = 0.01


@dataclass(frozen=True)
class Pose:
    """A camera pose in world coordinates (m): where it is, what it faces, its up."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]


def rescale_scene(scene: mi.Scene, factor: float) -> mi.Scene:
    """Multiply every length of ``scene`` by ``factor`` (e.g. 0.001: millimetres to metres).

    Shapes are scaled about the world origin (their ``to_world`` or vertex
    positions); sensors and emitters that are not shapes are moved, not
    scaled (Mitsuba cameras reject scale factors). Radiance, irradiance and
    intensity values are kept as they are. The scene is changed in place.

    Raises:
        SceneError: ``factor`` is not a positive finite number, or a shape
            exposes neither a transform nor vertices (its bounding box would
            not follow).

    """
    if isinstance(factor, bool) or not isinstance(factor, int | float):
        raise SceneError(f"scene scale = {factor!r} is invalid: allowed a positive number")
    if not (math.isfinite(factor) and factor > 0):
        raise SceneError(f"scene scale = {factor!r} is invalid: allowed a positive finite number")
    if factor == 1.0:
        return scene
    before = _bbox_corners(scene)
    params = mi.traverse(scene)
    for key in list(params.keys()):
        node, name = params.properties[key][2], key.rpartition(".")[2]
        if isinstance(node, mi.Shape) and name == "to_world":
            params[key] = mi.Transform4f().scale(factor) @ params[key]
        elif isinstance(node, mi.Shape) and name == "vertex_positions":
            params[key] = params[key] * factor
        elif name == "to_world":
            params[key] = _moved(params[key], factor)
        elif name == "position":
            params[key] = params[key] * factor
    params.update()
    after = _bbox_corners(scene)
    if before is not None and (
        after is None or not np.allclose(after, before * factor, rtol=1e-4, atol=1e-6)
    ):
        raise SceneError(
            f"--scene-scale {factor:g}: some shapes of the scene cannot be rescaled (bounds "
            f"{before.tolist()} became {None if after is None else after.tolist()}): rescale "
            "the scene file itself"
        )
    return scene


def _moved(transform: mi.Transform4f, factor: float) -> mi.Transform4f:
    """``transform`` with its translation multiplied by ``factor`` (rotation kept)."""
    matrix = mi.Matrix4f(transform.matrix)
    for row in range(3):
        matrix[row, 3] *= factor
    return mi.Transform4f(matrix)


def _bbox_corners(scene: mi.Scene) -> np.ndarray | None:
    """``[[min xyz], [max xyz]]`` of the scene's shapes (m), or None without shapes."""
    box = scene.bbox()
    if not box.valid():
        return None
    return np.array([list(box.min), list(box.max)], dtype=np.float64)


def sensor_pose(scene: mi.Scene, sensor_id: str | None = None) -> Pose:
    """The pose of the scene's first sensor, or of the one with id ``sensor_id``.

    Mitsuba sensors look along their local +z with local +y up; ``look_at``
    is one metre in front of the sensor.

    Raises:
        SceneError: the scene has no sensor, or none with that id.

    """
    sensors = list(scene.sensors())
    if sensor_id is not None:
        sensors = [s for s in sensors if s.id() == sensor_id]
    if not sensors:
        ids = [s.id() for s in scene.sensors()]
        wanted = f"sensor with id {sensor_id!r}" if sensor_id is not None else "sensor"
        raise SceneError(
            f"--pose-from-sensor: the scene has no {wanted} (sensor ids: {ids}): add one "
            "to the scene, or give --position, --look-at and --up"
        )
    to_world = sensors[0].world_transform()
    position = _vector(to_world @ mi.Point3f(0.0, 0.0, 0.0))
    forward = _unit(_vector(to_world @ mi.Vector3f(0.0, 0.0, 1.0)))
    up = _unit(_vector(to_world @ mi.Vector3f(0.0, 1.0, 0.0)))
    look_at = (position[0] + forward[0], position[1] + forward[1], position[2] + forward[2])
    return Pose(position=position, look_at=look_at, up=up)


def _vector(value: mi.Point3f | mi.Vector3f) -> tuple[float, float, float]:
    x, y, z = (float(np.asarray(dr.ravel(c))[0]) for c in (value.x, value.y, value.z))
    return x, y, z


def _unit(v: tuple[float, float, float]) -> tuple[float, float, float]:
    norm = math.sqrt(sum(c * c for c in v))
    return v[0] / norm, v[1] / norm, v[2] / norm


def check_scene(scene: mi.Scene, camera: FreeformCamera, *, require_emitter: bool) -> list[str]:
    """Check ``scene`` and the camera's pose before a render; return warnings.

    Errors (raised): an emitter whose radiance, intensity or irradiance is
    negative, NaN or infinite; no emitter when ``require_emitter`` (else a warning, the
    render then gives zeros); a camera farther from the scene's bounding box
    than :data:`MAX_CAMERA_DISTANCE_EXTENTS` extents. Warnings (returned and
    logged): no emitter without ``require_emitter``; a scene spanning more
    than :data:`UNIT_WARNING_EXTENT_M`, which suggests millimetres.

    Raises:
        SceneError: with the option that fixes it.

    """
    _check_emission(scene)
    warnings = []
    if not scene.emitters():
        message = (
            "the scene has no emitter, so every measurement is zero: add a light source "
            "(e.g. an area emitter on a shape, or a constant environment)"
        )
        if require_emitter:
            raise SceneError(message)
        warnings.append(message)
    corners = _bbox_corners(scene)
    if corners is not None:
        warnings += _unit_warnings(corners, camera)
        _check_camera_distance(corners, camera)
    for message in warnings:
        log.warning("%s", message)
    return warnings


#: Traversable emitter parameters that hold emitted power densities.
_EMISSION_KEYS = ("radiance.value", "intensity.value", "irradiance.value", "radiance.data")


def _check_emission(scene: mi.Scene) -> None:
    params = mi.traverse(scene)
    for key in params.keys():
        if not key.endswith(_EMISSION_KEYS):
            continue
        values = np.asarray(params[key], dtype=np.float64).ravel()
        bad = values[~np.isfinite(values) | (values < 0)]
        if bad.size:
            raise SceneError(
                f"emitter parameter {key} = {bad[0]:g} is invalid: emitted radiance, intensity "
                "and irradiance must be finite and >= 0 (W m^-2 sr^-1, W sr^-1, W m^-2)"
            )


def _unit_warnings(corners: np.ndarray, camera: FreeformCamera) -> list[str]:
    extent = float(np.max(corners[1] - corners[0]))
    if extent <= UNIT_WARNING_EXTENT_M:
        return []
    baseline_mm = 1e3 * float(np.ptp(np.asarray(camera.layout.positions_m), axis=0).max())
    return [
        f"scene spans {extent:.4g} m against a detector baseline of {baseline_mm:.3g} mm: "
        "is it in millimetres? pass --scene-scale 0.001 (the API: rescale_scene)"
    ]


def _check_camera_distance(corners: np.ndarray, camera: FreeformCamera) -> None:
    extent = max(float(np.max(corners[1] - corners[0])), 1e-9)
    position = np.asarray(camera.position, dtype=np.float64)
    outside = np.maximum(np.maximum(corners[0] - position, position - corners[1]), 0.0)
    distance = float(np.linalg.norm(outside))
    if distance > MAX_CAMERA_DISTANCE_EXTENTS * extent:
        raise SceneError(
            f"camera position {tuple(camera.position)} is {distance:.3g} m from the scene, "
            f"which spans {extent:.3g} m: place it within {MAX_CAMERA_DISTANCE_EXTENTS:g} "
            "scene extents (--position, or --pose-from-sensor)"
        )


def check_transport(transport: np.ndarray, scene: mi.Scene) -> list[str]:
    """Check a rendered ``T[detector, row, col]`` of ``scene``: detectors that see no light.

    Raises:
        SceneError: every detector sees zero (with what to check, and the
            emitters the scene has, by Mitsuba class).

    Returns:
        warnings (also logged): the detectors that see zero, by index.

    """
    power = np.asarray(transport, dtype=np.float64).reshape(len(transport), -1).sum(axis=1)
    dark = np.flatnonzero(power <= 0.0)
    if len(dark) == len(power):
        raise SceneError(
            f"all {len(power)} detectors see no light: check the pose (--position, --look-at; "
            "the board faces look_at), the scene's units (--scene-scale) and its emitters "
            f"({_emitter_census(scene)})"
        )
    if len(dark) == 0:
        return []
    message = (
        f"{len(dark)} of {len(power)} detectors see no light (zero transport): detectors "
        f"{dark.tolist()}; they face away from the lit scene or are blocked"
    )
    log.warning("%s", message)
    return [message]


def _emitter_census(scene: mi.Scene) -> str:
    """The scene's emitters by Mitsuba class, and where its delta lights would count."""
    counts = Counter(e.class_name() for e in scene.emitters())
    if not counts:
        return "found none"
    found = ", ".join(f"{n} {name}" for name, n in sorted(counts.items()))
    if not delta_emitters(scene):
        return f"found {found}"
    return (
        f"found {found}; point, spot and directional lights reach a detector only from "
        "in front of the board, within its field of view, unblocked"
    )


def spp_for_noise(
    spp: int, relative_noise: np.ndarray, target: float = TARGET_RELATIVE_NOISE
) -> int:
    """Samples per texel that bring the worst detector's relative error to ``target``.

    Monte Carlo error falls as 1/sqrt(spp); dark detectors (NaN noise) are ignored.
    """
    worst = float(np.nanmax(relative_noise)) if np.any(np.isfinite(relative_noise)) else 0.0
    return max(1, math.ceil(spp * (worst / target) ** 2))
