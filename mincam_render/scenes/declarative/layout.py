"""What the family reads from the user's loaded Mitsuba scene, and the checks that need it.

Movers are moved through the scene's parameters (``mi.traverse``): a mesh's
``<id>.vertex_positions``, any other shape's ``<id>.to_world``; hidden, a mover is
shrunk to nothing about its reference point. Emitters are switched through their
own parameters (radiance, intensity, irradiance, scale), scaled by 0 or 1 from
the values in the file. Errors name the description's field:
``movers[0].id = 'cupp': no shape with this id in table.xml (shapes: ...)``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import mitsuba as mi
import numpy as np

from mincam_render.core.config import ConfigError
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render.capabilities import View
from mincam_render.scenes.declarative.config import Box, MitsubaConfig

#: Scale of a hidden mover about its reference point: no longer seen, bounding box unchanged.
HIDDEN_SCALE = 1e-6
#: Emitter parameters that carry its emission (``mi.traverse`` of the emitter).
_EMISSION = re.compile(r"(^|\.)(radiance|intensity|irradiance)\.(value|data)$|(^|_)scale$")
#: How far a region may reach past the scene's bounding box, as a share of its diagonal.
_REGION_TOLERANCE = 0.01


@dataclass(frozen=True)
class MoverShape:
    """A mover's shape as the file places it (numpy, float64, m).

    Attributes:
        key: its scene parameter, ``"<id>.vertex_positions"`` or ``"<id>.to_world"``.
        file_pose: vertices ``(V, 3)`` of a mesh, or the ``(4, 4)`` to_world matrix.
        reference_m: centre of its bounding box, shape (3,).
        half_extent_m: half the size of its bounding box, shape (3,).
    """

    key: str
    file_pose: np.ndarray
    reference_m: np.ndarray
    half_extent_m: np.ndarray

    def placed(self, position_m: np.ndarray, shown: bool) -> Any:
        """The parameter value with the reference point at ``position_m`` (Dr.Jit)."""
        scale = 1.0 if shown else HIDDEN_SCALE
        if self.key.endswith(".vertex_positions"):
            v = position_m + scale * (self.file_pose - self.reference_m)
            return mi.Float(v.astype(np.float32).ravel())
        move = np.eye(4)
        move[:3, :3] *= scale
        move[:3, 3] = position_m - scale * self.reference_m
        # the 3.9.1 stubs do not type AffineTransform4f as callable
        return mi.AffineTransform4f(mi.ScalarMatrix4f(move @ self.file_pose))  # type: ignore[operator]


@dataclass(frozen=True)
class Emission:
    """An emitter's emission parameters as in the file: ``{key: (Dr.Jit type, numpy value)}``."""

    parameters: dict[str, tuple[Callable[[np.ndarray], Any], np.ndarray]]

    def apply(self, emitter: mi.Emitter, on: bool) -> None:
        """Set ``emitter``'s emission to the file's (on) or to zero (off)."""
        params = mi.traverse(emitter)
        for key, (kind, value) in self.parameters.items():
            params[key] = kind(value if on else np.zeros_like(value))
        params.update()


@dataclass(frozen=True)
class SceneLayout:
    """The parts of the scene the family moves and switches, read once.

    Attributes:
        movers: ``{mover id: MoverShape}``.
        emitters: every emitter's :class:`Emission`, in ``scene.emitters()`` order.
        switched: ``{switched emitter id: its index in emitters}``.
        bbox_m: ``(min, max)`` corners of the scene's bounding box.
        sensor_view: the view of the file's first sensor, or None.
    """

    movers: dict[str, MoverShape]
    emitters: tuple[Emission, ...]
    switched: dict[str, int]
    bbox_m: tuple[np.ndarray, np.ndarray]
    sensor_view: View | None

    @property
    def static_emitters(self) -> tuple[int, ...]:
        """Indices of the emitters that are not switched."""
        return tuple(i for i in range(len(self.emitters)) if i not in self.switched.values())


def read_layout(scene: mi.Scene, config: MitsubaConfig) -> SceneLayout:
    """The layout of ``scene`` for ``config``, its ids and regions checked.

    Raises:
        ConfigError: a mover or emitter id the scene lacks, a mover that emits or
            cannot be moved, an emitter whose emission is not a known parameter,
            or a region or path outside the scene.
    """
    bbox = scene.bbox()
    lo, hi = np.array(bbox.min, dtype=np.float64), np.array(bbox.max, dtype=np.float64)
    layout = SceneLayout(
        movers=_movers(scene, config),
        emitters=tuple(_emission(e, config) for e in scene.emitters()),
        switched=_switched(scene, config),
        bbox_m=(lo, hi),
        sensor_view=_sensor_view(scene),
    )
    _check_regions(config, lo, hi)
    return layout


def _movers(scene: mi.Scene, config: MitsubaConfig) -> dict[str, MoverShape]:
    params = mi.traverse(scene)
    shapes = {sh.id(): sh for sh in scene.shapes() if sh.id()}
    out = {}
    for i, mover in enumerate(config.movers):
        where = f"movers[{i}].id = {mover.id!r}"
        shape = shapes.get(mover.id)
        if shape is None:
            raise ConfigError(
                f"{where}: no shape with this id in {config.scene.name} (shapes: "
                f"{', '.join(sorted(shapes)) or 'none with an id'})"
            )
        if shape.emitter() is not None:
            raise ConfigError(f"{where}: the shape emits light; a mover may not (switch it)")
        box = shape.bbox()
        lo, hi = np.array(box.min, dtype=np.float64), np.array(box.max, dtype=np.float64)
        if f"{mover.id}.vertex_positions" in params:
            key = f"{mover.id}.vertex_positions"
            pose = np.array(params[key], dtype=np.float64).reshape(-1, 3)
        elif f"{mover.id}.to_world" in params:
            key = f"{mover.id}.to_world"
            pose = np.array(params[key].matrix.numpy(), dtype=np.float64).reshape(4, 4)
        else:
            raise ConfigError(f"{where}: a {type(shape).__name__} cannot be moved (no to_world)")
        out[mover.id] = MoverShape(key, pose, (lo + hi) / 2, (hi - lo) / 2)
    return out


def _emission(emitter: mi.Emitter, config: MitsubaConfig) -> Emission:
    params = mi.traverse(emitter)
    found: dict[str, tuple[Callable[[np.ndarray], Any], np.ndarray]] = {
        k: (type(params[k]), np.array(params[k], dtype=np.float32))
        for k in params.keys()
        if _EMISSION.search(k)
    }
    if not found:
        raise ConfigError(
            f"scene = '{config.scene}': a {type(emitter).__name__} emitter has no radiance, "
            "intensity, irradiance or scale parameter to switch its light with"
        )
    return Emission(found)


def _switched(scene: mi.Scene, config: MitsubaConfig) -> dict[str, int]:
    """``{id: index in scene.emitters()}`` of the switched emitters (by their id or shape's)."""
    index = {e.id(): i for i, e in enumerate(scene.emitters()) if e.id()}
    for sh in scene.shapes():
        if sh.emitter() is not None and sh.id():
            for i, e in enumerate(scene.emitters()):
                if e == sh.emitter():
                    index.setdefault(sh.id(), i)
    out = {}
    for i, switch in enumerate(config.emitters):
        if switch.id not in index:
            raise ConfigError(
                f"emitters[{i}].id = {switch.id!r}: no emitter (or shape with one) with this id "
                f"in {config.scene.name} (have: {', '.join(sorted(index)) or 'none with an id'})"
            )
        out[switch.id] = index[switch.id]
    if len(set(out.values())) < len(out):
        raise ConfigError("emitters: two ids name the same emitter (its own and its shape's)")
    return out


def _sensor_view(scene: mi.Scene) -> View | None:
    """The first sensor's view (its pose and horizontal field of view), or None."""
    from mincam_render.render.user_scene import sensor_pose

    if not scene.sensors():
        return None
    pose = sensor_pose(scene)
    fov = mi.traverse(scene.sensors()[0]).get("x_fov")
    fov_deg = float(np.array(fov).ravel()[0]) if fov is not None else 60.0
    return View(pose.position, pose.look_at, pose.up, fov_deg)


def _check_regions(config: MitsubaConfig, lo: np.ndarray, hi: np.ndarray) -> None:
    """ConfigError naming the first region or path that reaches outside the scene."""
    margin = _REGION_TOLERANCE * float(np.linalg.norm(hi - lo)) + 1e-9
    places: list[tuple[str, Box | None, tuple]] = [
        (f"movers[{i}]", m.region, m.path) for i, m in enumerate(config.movers)
    ]
    places += [(f"labels[{i}]", label.region, ()) for i, label in enumerate(config.labels)]
    for where, region, path in places:
        points = [region.min_m, region.max_m] if region is not None else list(path)
        field = "region" if region is not None else "path"
        if any(np.any(np.asarray(p) < lo - margin) or np.any(np.asarray(p) > hi + margin)
               for p in points):  # fmt: skip
            shown = (
                f"{{min_m = {list(region.min_m)}, max_m = {list(region.max_m)}}}"
                if region is not None
                else str([list(p) for p in path])
            )
            raise ConfigError(
                f"{where}.{field} = {shown}: outside the scene, whose bounding box spans "
                f"{_rounded(lo)} to {_rounded(hi)} m"
            )


def check_in_view(config: MitsubaConfig, layout: SceneLayout, camera: FreeformCamera) -> None:
    """ConfigError naming a mover whose bounding box is never in the camera's field of view.

    Every place its region or path allows is tried (a grid of the region, points
    along the path); occlusion is not considered.
    """
    right, up, forward = camera.frame
    half = math.tan(math.radians(camera.fov_deg) / 2)
    corners = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)])
    for i, mover in enumerate(config.movers):
        shape = layout.movers[mover.id]
        places = _places(mover.region, mover.path)
        points = (places[:, None, :] + corners[None] * shape.half_extent_m).reshape(-1, 3)
        rel = points - np.asarray(camera.position)
        x, y, z = rel @ right, rel @ up, rel @ forward
        seen = (z > 0) & (np.abs(x) <= half * z) & (np.abs(y) <= half * z)
        if not seen.any():
            raise ConfigError(
                f"movers[{i}] ({mover.id!r}): never enters the camera's view (a "
                f"{camera.fov_deg:.0f} deg square from camera.position = "
                f"{list(camera.position)} towards {list(camera.look_at)}); move its "
                "region or path, or the camera"
            )


def _places(region: Box | None, path: tuple) -> np.ndarray:
    """Points ``(N, 3)`` a reference point may take: a 9^3 grid of the region, or the path."""
    if region is not None:
        axes = [np.linspace(a, b, 9) for a, b in zip(region.min_m, region.max_m, strict=True)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    loop = np.asarray([*path, path[0]], dtype=np.float64)
    t = np.linspace(0.0, 1.0, 64)[:, None]
    return np.concatenate([a + t * (b - a) for a, b in zip(loop[:-1], loop[1:], strict=True)])


def _rounded(v: Iterable[float]) -> list[float]:
    return [round(float(x), 3) for x in v]
