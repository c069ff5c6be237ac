"""Meshes of the room and what stands in it, and where points lie.

Numpy vertices ``(V, 3)`` in m (world frame, see :mod:`mincam_render.scenes.indoor`)
and faces ``(F, 3)``: walls with holes for the window and door, furniture built
from boxes, ceiling panels, floor lamps with a glowing drum shade; the radiance
of the emitters from their lumens; tests of points against the camera's view,
the room and floor zones.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import trimesh

from mincam_render.core.photometry import lambertian_radiance, lumens_to_watts
from mincam_render.scenes.indoor.config import (
    FloorLampConfig,
    FurnitureConfig,
    FurnitureKind,
    LightBankConfig,
    RoomConfig,
    Wall,
    ZoneConfig,
    wall_frame,
    wall_length,
)

if TYPE_CHECKING:
    from mincam_render.optics.camera import FreeformCamera


def quad(
    p0: npt.ArrayLike,
    p1: npt.ArrayLike,
    p2: npt.ArrayLike,
    p3: npt.ArrayLike,
    normal: npt.ArrayLike,
) -> tuple[np.ndarray, np.ndarray]:
    """The quad ``p0 p1 p2 p3`` (m) as two triangles facing ``normal``: ``(vertices, faces)``."""
    v = np.array([p0, p1, p2, p3], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = np.cross(v[1] - v[0], v[2] - v[0])
    if np.dot(n, normal) < 0:
        f = f[:, ::-1]
    return v, f


def merge_meshes(parts: Iterable[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate ``[(V_i, F_i)]`` into one ``(V, F)``."""
    vs, fs, off = [], [], 0
    for v, f in parts:
        vs.append(np.asarray(v, dtype=np.float64))
        fs.append(np.asarray(f) + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def wall_with_holes(
    room: RoomConfig, wall: Wall, holes: list[tuple[float, float, float, float]]
) -> tuple[np.ndarray, np.ndarray]:
    """A wall facing into the room, minus rectangular holes ``(s0, s1, z0, z1)`` (m)."""
    origin, t, n = wall_frame(room, wall)
    length, height = wall_length(room, wall), room.size_m[2]
    cuts = sorted({0.0, length, *[h[0] for h in holes], *[h[1] for h in holes]})
    quads = []
    for s0, s1 in zip(cuts[:-1], cuts[1:], strict=True):
        mid = 0.5 * (s0 + s1)
        gaps = sorted((h[2], h[3]) for h in holes if h[0] <= mid <= h[1])
        z = 0.0
        for z0, z1 in [*gaps, (height, height)]:
            if z0 > z:
                p = [
                    origin + s * t + zz * np.array([0, 0, 1.0])
                    for s, zz in ((s0, z), (s1, z), (s1, z0), (s0, z0))
                ]
                quads.append(quad(p[0], p[1], p[2], p[3], n))
            z = max(z, z1)
    return merge_meshes(quads)


def box_mesh(
    center: npt.ArrayLike, extents: npt.ArrayLike, rotation_deg: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned (then rotated about +z) box with outward faces."""
    b = trimesh.creation.box(extents=extents)
    v = np.asarray(b.vertices, dtype=np.float64)
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    return v @ rot.T + np.asarray(center), np.asarray(b.faces)


def inward_box(
    lo: np.ndarray, hi: np.ndarray, *, open_axis: int | None = None, open_at: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """A box whose faces point inward (a corridor seen from inside): ``(vertices, faces)``.

    Args:
        lo: the corner with the smallest coordinates (m, world).
        hi: the opposite corner (m, world).
        open_axis: leave out the face lying in the plane ``x[open_axis] = open_at``
            (the side open onto the room), or None for a closed box. A closed
            corridor would put a face in the doorway and coplanar with the
            room's wall, facing away from the room: rays from the room then hit
            its black back, or the wall, depending on the traversal.
        open_at: that plane's coordinate (m).
    """
    b = trimesh.creation.box(bounds=[lo, hi])
    vertices = np.asarray(b.vertices, dtype=np.float64)
    faces = np.asarray(b.faces)[:, ::-1]
    if open_axis is not None:
        on_plane = np.all(np.abs(vertices[faces][:, :, open_axis] - open_at) < 1e-9, axis=1)
        if not np.any(on_plane):
            raise ValueError(f"inward_box: no face at x[{open_axis}] = {open_at} m")
        faces = faces[~on_plane]
    return vertices, faces


def furniture_mesh(item: FurnitureConfig) -> tuple[np.ndarray, np.ndarray]:
    """Boxes making up one piece of furniture, in world coordinates."""
    d, w, h = item.size
    parts: list[
        tuple[tuple[float, float, float], tuple[float, float, float]]
    ] = []  # (centre, extents) local
    leg = 0.05
    if item.kind in (FurnitureKind.DESK, FurnitureKind.TABLE):
        parts.append(((0, 0, h - 0.015), (d, w, 0.03)))
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append(
                    ((sx * (d / 2 - leg), sy * (w / 2 - leg), (h - 0.03) / 2), (leg, leg, h - 0.03))
                )
    elif item.kind is FurnitureKind.CHAIR:
        seat = 0.46
        parts.append(((0, 0, seat - 0.03), (d, w, 0.06)))
        parts.append(((-d / 2 + 0.03, 0, (seat + h) / 2), (0.06, w, h - seat)))
        for sx in (-1, 1):
            for sy in (-1, 1):
                parts.append(
                    (
                        (sx * (d / 2 - 0.04), sy * (w / 2 - 0.04), (seat - 0.06) / 2),
                        (0.04, 0.04, seat - 0.06),
                    )
                )
    elif item.kind is FurnitureKind.SHELF:
        t = 0.02
        parts.append(((-d / 2 + t / 2, 0, h / 2), (t, w, h)))  # back panel
        for sy in (-1, 1):
            parts.append(((0, sy * (w / 2 - t / 2), h / 2), (d, t, h)))
        for k in range(5):
            parts.append(((0, 0, t / 2 + k * (h - t) / 4), (d, w, t)))
    elif item.kind is FurnitureKind.SOFA:
        parts.append(((0.05, 0, 0.21), (d - 0.1, w, 0.42)))  # seat
        parts.append(((-d / 2 + 0.1, 0, h / 2), (0.2, w, h)))  # back
        for sy in (-1, 1):
            parts.append(((0, sy * (w / 2 - 0.1), 0.3), (d, 0.2, 0.6)))  # arms
    else:  # cabinet
        parts.append(((0, 0, h / 2), (d, w, h)))
    a = math.radians(item.rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    pos = np.array([*item.position_m, 0.0])
    meshes = []
    for c, e in parts:
        v, f = box_mesh(c, e)
        meshes.append((v @ rot.T + pos, f))
    return merge_meshes(meshes)


def ceiling_panels(room: RoomConfig, bank: LightBankConfig) -> tuple[np.ndarray, np.ndarray]:
    """The bank's panels as downward-facing quads 1 cm below the ceiling."""
    z = room.size_m[2] - 0.01
    hx, hy = np.asarray(bank.panel_size_m) / 2
    quads = [
        quad(
            (x - hx, y - hy, z),
            (x + hx, y - hy, z),
            (x + hx, y + hy, z),
            (x - hx, y + hy, z),
            (0, 0, -1.0),
        )
        for x, y in bank.panels_m
    ]
    return merge_meshes(quads)


def bank_radiance_w_m2_sr(bank: LightBankConfig) -> float:
    """Lambertian radiance of one panel from its lumens (visible-band W)."""
    area = bank.panel_size_m[0] * bank.panel_size_m[1]
    return lambertian_radiance(lumens_to_watts(bank.lumens_per_panel), area)


def lamp_meshes(
    lamp: FloorLampConfig,
) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """(pole + base, glowing drum shade) of a floor lamp, world coordinates."""
    x, y = lamp.position_m
    zc = lamp.shade_center_height_m
    base = box_mesh((x, y, 0.015), (0.3, 0.3, 0.03))
    pole_len = zc - lamp.shade_height_m / 2 - 0.03
    pole = box_mesh((x, y, 0.03 + pole_len / 2), (0.025, 0.025, pole_len))
    shade = trimesh.creation.cylinder(
        radius=lamp.shade_radius_m, height=lamp.shade_height_m, sections=16
    )
    sv = np.asarray(shade.vertices, dtype=np.float64) + np.array([x, y, zc])
    return merge_meshes([base, pole]), (sv, np.asarray(shade.faces))


def lamp_radiance_w_m2_sr(lamp: FloorLampConfig) -> float:
    """Lambertian radiance of the shade surface (all of the lamp's flux leaves through it)."""
    r, h = lamp.shade_radius_m, lamp.shade_height_m
    area = 2 * math.pi * r * h + 2 * math.pi * r * r
    return lambertian_radiance(lumens_to_watts(lamp.lumens), area)


def lamp_surface_points(lamp: FloorLampConfig, n: int = 64) -> np.ndarray:
    """Points on a lamp's emitting shade (for view checks), shape (N, 3)."""
    a = np.linspace(0, 2 * math.pi, n, endpoint=False)
    x, y = lamp.position_m
    pts = []
    for dz in (-0.5, 0.0, 0.5):
        pts.append(
            np.stack(
                [
                    x + lamp.shade_radius_m * np.cos(a),
                    y + lamp.shade_radius_m * np.sin(a),
                    np.full(n, lamp.shade_center_height_m + dz * lamp.shade_height_m),
                ],
                -1,
            )
        )
    return np.concatenate(pts)


def points_in_view(camera: FreeformCamera, points: npt.ArrayLike) -> np.ndarray:
    """Which points project inside some detector's mask (ignoring occlusion), shape (N,) bool."""
    pts = np.asarray(points, dtype=np.float64)
    right, up, fwd = camera.frame
    half = 0.5 * camera.mask_size_m
    seen = np.zeros(len(pts), dtype=bool)
    for c in camera.detector_centers_m:
        # the detector's area widens its view by half its size on each side
        rel = pts - c
        depth = rel @ fwd
        ok = depth > 1e-9
        s = np.where(ok, rel @ right * camera.mask_distance_m / np.where(ok, depth, 1), np.inf)
        t = np.where(ok, rel @ up * camera.mask_distance_m / np.where(ok, depth, 1), np.inf)
        lim = half + 0.5 * camera.detector_size_m
        seen |= ok & (np.abs(s) <= lim) & (np.abs(t) <= lim)
    return seen


def inside_room(room: RoomConfig, x: float, y: float) -> bool:
    """A person is in the room when their pelvis is inside the walls."""
    return 0.0 < x < room.size_m[0] and 0.0 < y < room.size_m[1]


def zone_overlaps(zone: ZoneConfig, x: float, y: float, radius_m: float) -> bool:
    """True when the footprint circle (centre x, y, radius) overlaps the zone rectangle."""
    x0, y0, x1, y1 = zone.rect_m
    dx = max(x0 - x, 0.0, x - x1)
    dy = max(y0 - y, 0.0, y - y1)
    return dx * dx + dy * dy < radius_m * radius_m
