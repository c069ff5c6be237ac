"""Shared pieces of the indoor families: room, furniture, door, lights and people.

World frame (indoor scenes): metres, +z up, +x east, +y north. A room spans
``[0, W] x [0, D] x [0, H]`` (``RoomConfig.size_m``); its walls are named by
compass side (:class:`Wall`): south is ``y = 0``, north ``y = D``, west
``x = 0``, east ``x = W``. A position *along* a wall (``center_m`` of a door or
window) is measured from its west end (south/north walls) or south end
(west/east walls).

What is here (numpy + trimesh, no Mitsuba except in :func:`static_shapes` and
the mesh builders, which go through :mod:`mincam_render.render.mitsuba_scene`):

- descriptions (frozen dataclasses read from TOML) of the room, window, door,
  furniture, floor zones, ceiling light banks, floor lamps and people;
- geometry: walls with holes for the window and door (and a dim corridor
  behind the door), furniture built from boxes, a hinged door, ceiling panels,
  floor lamps with a glowing drum shade, articulated people;
- motion: a navigation grid with A* paths around furniture, a people simulator
  (enter through the door, walk, stand or sit, leave; or wander a room), door
  dynamics, and an on/off switching process for lights.

Everything is simulated once from a seeded ``np.random.Generator``, so a frame's
state is a pure function of its index.
"""

from __future__ import annotations

import enum
import heapq
import math
from dataclasses import dataclass, field, replace

import numpy as np
import trimesh

from mincam_render.core.config import spec
from mincam_render.core.photometry import lambertian_radiance, lumens_to_watts
from mincam_render.render import mitsuba_scene as ms
from mincam_render.scenes.base import SceneFamily

#: Floor area one person needs (m^2): a room "holds" floor_area / this many people.
AREA_PER_PERSON_M2 = 2.0
#: Where people who are not in the scene are parked (m): far below the floor, unseen.
PARK_POSITION_M = (0.0, 0.0, -50.0)
#: Navigation grid cell (m) and the clearance kept from walls and furniture (m).
NAV_CELL_M = 0.1
NAV_CLEARANCE_M = 0.3
#: Rates of the people's motion: turning (rad/s), sitting down/standing up (1/s),
#: starting/stopping the gait (1/s); stride of a full gait cycle per metre of height.
TURN_RATE_RAD_S = 5.0
SIT_RATE_PER_S = 1.0
GAIT_RATE_PER_S = 3.0
CYCLE_LENGTH_PER_HEIGHT = 0.8


class Wall(enum.Enum):
    """A wall of the room by compass side (+y north)."""

    SOUTH = "south"
    NORTH = "north"
    WEST = "west"
    EAST = "east"


class HingeSide(enum.Enum):
    """Which end of the doorway (along the wall, see module docstring) holds the hinge."""

    START = "start"
    END = "end"


class FurnitureKind(enum.Enum):
    """Furniture built from boxes; a chair is a seat people can sit on."""

    DESK = "desk"
    CHAIR = "chair"
    SHELF = "shelf"
    TABLE = "table"
    SOFA = "sofa"
    CABINET = "cabinet"


#: Default (depth along local x, width along local y, height) in m, and albedo
#: (laminate desk ~0.45, dark fabric chair ~0.12, light wood shelf ~0.5...).
FURNITURE_SIZE_M = {
    FurnitureKind.DESK: (0.7, 1.4, 0.74),
    FurnitureKind.CHAIR: (0.5, 0.5, 0.9),
    FurnitureKind.SHELF: (0.4, 1.2, 1.8),
    FurnitureKind.TABLE: (1.0, 1.6, 0.74),
    FurnitureKind.SOFA: (0.9, 2.0, 0.85),
    FurnitureKind.CABINET: (0.5, 0.8, 1.0),
}
FURNITURE_ALBEDO = {
    FurnitureKind.DESK: 0.45,
    FurnitureKind.CHAIR: 0.12,
    FurnitureKind.SHELF: 0.5,
    FurnitureKind.TABLE: 0.4,
    FurnitureKind.SOFA: 0.25,
    FurnitureKind.CABINET: 0.6,
}

# --------------------------------------------------------------------------------------
# descriptions


@dataclass(frozen=True, kw_only=True)
class RoomConfig:
    """A box room: size and the albedo of its surfaces."""

    size_m: tuple[float, float, float] = spec(
        (6.0, 5.0, 2.8), unit="m", range=(1.5, 50.0), doc="width (x), depth (y), height (z)"
    )
    wall_albedo: float = spec(0.7, range=(0.0, 1.0), doc="painted walls")
    floor_albedo: float = spec(0.25, range=(0.0, 1.0), doc="carpet or wood floor")
    ceiling_albedo: float = spec(0.8, range=(0.0, 1.0), doc="ceiling tiles")

    @property
    def floor_area_m2(self) -> float:
        return self.size_m[0] * self.size_m[1]

    def contains(self, point, margin: float = 0.0) -> bool:
        """True when a 2-D or 3-D point is inside the room by at least ``margin`` (m)."""
        p = np.asarray(point, dtype=np.float64)
        return bool(np.all(p >= margin) and np.all(p <= np.asarray(self.size_m[: len(p)]) - margin))


@dataclass(frozen=True, kw_only=True)
class WindowConfig:
    """An open window (a hole in a wall; the sun and sky come in through it)."""

    wall: Wall = spec(Wall.SOUTH, doc="wall holding the window")
    center_m: float = spec(2.0, unit="m", range=(0.0, 50.0), doc="centre along the wall")
    width_m: float = spec(2.0, unit="m", range=(0.2, 20.0), doc="opening width")
    sill_height_m: float = spec(0.9, unit="m", range=(0.0, 10.0), doc="bottom of the opening")
    height_m: float = spec(1.4, unit="m", range=(0.2, 10.0), doc="opening height")


@dataclass(frozen=True, kw_only=True)
class DoorConfig:
    """A hinged door that swings into the room, with a corridor behind it."""

    wall: Wall = spec(Wall.NORTH, doc="wall holding the door")
    center_m: float = spec(1.0, unit="m", range=(0.0, 50.0), doc="centre along the wall")
    width_m: float = spec(0.9, unit="m", range=(0.6, 3.0), doc="leaf width")
    height_m: float = spec(2.05, unit="m", range=(1.6, 5.0), doc="leaf height")
    hinge: HingeSide = spec(HingeSide.START, doc="hinge end of the doorway")
    albedo: float = spec(0.55, range=(0.0, 1.0), doc="door leaf")
    max_angle_deg: float = spec(90.0, unit="deg", range=(10.0, 170.0), doc="fully open")
    speed_deg_s: float = spec(90.0, unit="deg/s", range=(1.0, 1000.0), doc="swing speed")
    open_threshold_deg: float = spec(
        10.0, unit="deg", range=(0.0, 170.0), doc="door_open label is 1 above this angle"
    )
    trigger_distance_m: float = spec(
        1.6, unit="m", range=(0.1, 10.0), doc="opens when a person is this close to the doorway"
    )
    hold_open_s: float = spec(2.0, unit="s", range=(0.0, 600.0), doc="closes this long after")
    mean_propped_s: float = spec(
        30.0, unit="s", range=(0.0, 1e6), doc="mean time someone props it open (0 = never)"
    )
    mean_unpropped_s: float = spec(
        180.0, unit="s", range=(1.0, 1e6), doc="mean time between proppings"
    )
    corridor_depth_m: float = spec(1.5, unit="m", range=(0.5, 10.0), doc="corridor behind")
    corridor_albedo: float = spec(0.5, range=(0.0, 1.0), doc="corridor surfaces")


@dataclass(frozen=True, kw_only=True)
class FurnitureConfig:
    """One piece of furniture standing on the floor.

    Local axes: x is its depth (a chair's sitter faces +x; a desk's user sits on
    its -x side), y its width; ``rotation_deg`` turns local x from world +x
    toward +y.
    """

    kind: FurnitureKind = spec(doc="desk, chair, shelf, table, sofa or cabinet")
    position_m: tuple[float, float] = spec(unit="m", range=(0.0, 50.0), doc="footprint centre x, y")
    rotation_deg: float = spec(0.0, unit="deg", range=(-360.0, 360.0), doc="about +z")
    size_m: tuple[float, float, float] | None = spec(
        None, unit="m", range=(0.05, 10.0), doc="depth, width, height; default per kind"
    )
    albedo: float | None = spec(None, range=(0.0, 1.0), doc="default per kind")

    @property
    def size(self) -> tuple[float, float, float]:
        return self.size_m if self.size_m is not None else FURNITURE_SIZE_M[self.kind]

    @property
    def reflectance(self) -> float:
        return self.albedo if self.albedo is not None else FURNITURE_ALBEDO[self.kind]

    def footprint_corners(self) -> np.ndarray:
        """World (x, y) of the 4 footprint corners, shape (4, 2)."""
        d, w, _ = self.size
        a = math.radians(self.rotation_deg)
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        local = np.array([[-d, -w], [d, -w], [d, w], [-d, w]]) / 2
        return local @ rot.T + np.asarray(self.position_m)


@dataclass(frozen=True, kw_only=True)
class ZoneConfig:
    """A named rectangle of floor; occupied when a person's footprint overlaps it."""

    name: str = spec(doc="label element name")
    rect_m: tuple[float, float, float, float] = spec(
        unit="m", range=(0.0, 50.0), doc="x_min, y_min, x_max, y_max"
    )

    def __post_init__(self) -> None:
        x0, y0, x1, y1 = self.rect_m
        if not (x0 < x1 and y0 < y1):
            raise ValueError(f"rect_m = {list(self.rect_m)}: need x_min < x_max and y_min < y_max")


@dataclass(frozen=True, kw_only=True)
class LightBankConfig:
    """Ceiling panels switched together (LED troffers: 600 x 600 mm, ~3600 lm)."""

    name: str = spec(doc="label element name")
    panels_m: tuple[tuple[float, float], ...] = spec(
        unit="m", range=(0.0, 50.0), doc="panel centres x, y on the ceiling"
    )
    panel_size_m: tuple[float, float] = spec((0.6, 0.6), unit="m", range=(0.05, 5.0), doc="x, y")
    lumens_per_panel: float = spec(3600.0, unit="lm", range=(0.0, 1e6), doc="luminous flux")
    mean_on_s: float = spec(60.0, unit="s", range=(0.1, 1e7), doc="mean on duration")
    mean_off_s: float = spec(40.0, unit="s", range=(0.1, 1e7), doc="mean off duration")

    def __post_init__(self) -> None:
        if not self.panels_m:
            raise ValueError("panels_m = []: need at least one panel")


@dataclass(frozen=True, kw_only=True)
class FloorLampConfig:
    """A floor lamp: a pole with a glowing drum shade (a 100 W-equivalent bulb ~1600 lm)."""

    name: str = spec(doc="label element name")
    position_m: tuple[float, float] = spec(unit="m", range=(0.0, 50.0), doc="base x, y")
    lumens: float = spec(1600.0, unit="lm", range=(0.0, 1e6), doc="luminous flux")
    shade_center_height_m: float = spec(1.5, unit="m", range=(0.3, 5.0), doc="shade centre")
    shade_radius_m: float = spec(0.2, unit="m", range=(0.03, 1.0), doc="drum radius")
    shade_height_m: float = spec(0.3, unit="m", range=(0.03, 1.0), doc="drum height")
    mean_on_s: float = spec(45.0, unit="s", range=(0.1, 1e7), doc="mean on duration")
    mean_off_s: float = spec(45.0, unit="s", range=(0.1, 1e7), doc="mean off duration")


@dataclass(frozen=True, kw_only=True)
class PeopleConfig:
    """How people look and behave; each visit draws uniformly within these ranges."""

    height_m: tuple[float, float] = spec((1.55, 1.95), unit="m", range=(0.5, 2.5), doc="stature")
    build: tuple[float, float] = spec(
        (0.85, 1.25), range=(0.5, 2.0), doc="width scale (1 = average); footprint 0.22 m x build"
    )
    walk_speed_m_s: tuple[float, float] = spec(
        (0.9, 1.4), unit="m/s", range=(0.1, 3.0), doc="walking speed"
    )
    clothing_albedo: tuple[float, float] = spec(
        (0.04, 0.7), range=(0.0, 1.0), doc="shirt, trousers"
    )
    skin_albedo: tuple[float, float] = spec((0.1, 0.55), range=(0.0, 1.0), doc="head, neck")
    dwell_s: tuple[float, float] = spec(
        (10.0, 90.0), unit="s", range=(0.0, 1e6), doc="time spent at each stop"
    )
    sit_probability: float = spec(0.6, range=(0.0, 1.0), doc="a stop is on a free chair")
    stops: tuple[int, int] = spec((1, 4), range=(1, 100), doc="stops per visit")

    def __post_init__(self) -> None:
        for name in (
            "height_m",
            "build",
            "walk_speed_m_s",
            "clothing_albedo",
            "skin_albedo",
            "dwell_s",
            "stops",
        ):
            lo, hi = getattr(self, name)
            if lo > hi:
                raise ValueError(f"{name} = {[lo, hi]}: min must not exceed max")


# --------------------------------------------------------------------------------------
# validation helpers (raise ValueError naming the field)


def check_wall_opening(
    name: str,
    room: RoomConfig,
    wall: Wall,
    center: float,
    width: float,
    bottom: float,
    height: float,
) -> None:
    """Raise ``ValueError`` unless an opening fits in its wall, below the ceiling."""
    length = wall_length(room, wall)
    if center - width / 2 < 0.05 or center + width / 2 > length - 0.05:
        raise ValueError(
            f"{name}.center_m = {center} with width_m = {width}: the opening must lie within the "
            f"{wall.value} wall, [0, {length}] m"
        )
    if bottom + height > room.size_m[2] - 0.05:
        raise ValueError(
            f"{name}: top of the opening at {bottom + height:.3g} m is above the ceiling "
            f"({room.size_m[2]} m)"
        )


def check_inside(name: str, room: RoomConfig, point, margin: float = 0.0) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``point`` is ``margin`` (m) inside the room."""
    if not room.contains(point, margin):
        box = " x ".join(f"[{margin:g}, {s - margin:g}]" for s in room.size_m[: len(point)])
        raise ValueError(f"{name} = {list(point)}: outside the room, allowed {box} m")


def check_furniture(room: RoomConfig, furniture: tuple[FurnitureConfig, ...]) -> None:
    """Raise ``ValueError`` when a footprint leaves the room or an item is taller than it."""
    for i, f in enumerate(furniture):
        for c in f.footprint_corners():
            if not room.contains(c, -1e-6):
                raise ValueError(
                    f"furniture[{i}] ({f.kind.value} at {list(f.position_m)}): footprint outside "
                    f"the room [0, {room.size_m[0]}] x [0, {room.size_m[1]}] m"
                )
        if f.size[2] > room.size_m[2]:
            raise ValueError(f"furniture[{i}]: taller than the room")


def check_zones(room: RoomConfig, zones: tuple[ZoneConfig, ...]) -> None:
    """Raise ``ValueError`` for duplicate zone names or a zone reaching outside the room."""
    names = [z.name for z in zones]
    if len(set(names)) != len(names):
        raise ValueError(f"zones: names must be unique, got {names}")
    for i, z in enumerate(zones):
        x0, y0, x1, y1 = z.rect_m
        if x1 > room.size_m[0] + 1e-9 or y1 > room.size_m[1] + 1e-9:
            raise ValueError(
                f"zones[{i}].rect_m = {list(z.rect_m)} ({z.name!r}): outside the room "
                f"[0, {room.size_m[0]}] x [0, {room.size_m[1]}] m"
            )


def check_capacity(room: RoomConfig, max_people: int, field_name: str = "max_people") -> None:
    """Raise ``ValueError`` when the room's floor cannot hold ``max_people``."""
    cap = int(room.floor_area_m2 // AREA_PER_PERSON_M2)
    if max_people > cap:
        raise ValueError(
            f"{field_name} = {max_people}: the room ({room.size_m[0]} x {room.size_m[1]} m) holds "
            f"at most {cap} people ({AREA_PER_PERSON_M2} m^2 each)"
        )


def check_light_banks(room: RoomConfig, banks: tuple[LightBankConfig, ...]) -> None:
    """Raise ``ValueError`` when a ceiling panel reaches outside the ceiling."""
    for i, b in enumerate(banks):
        for j, p in enumerate(b.panels_m):
            half = np.asarray(b.panel_size_m) / 2
            if not (
                room.contains(np.asarray(p) - half, -1e-9)
                and room.contains(np.asarray(p) + half, -1e-9)
            ):
                raise ValueError(
                    f"ceiling_lights[{i}].panels_m[{j}] = {list(p)}: panel outside the ceiling"
                )


def check_camera(room: RoomConfig, camera) -> None:
    """Raise ``ValueError`` unless the camera and the point it faces are in the room."""
    check_inside("camera.position", room, camera.position, 0.01)
    check_inside("camera.look_at", room, camera.look_at, 0.0)


# --------------------------------------------------------------------------------------
# wall frames


def wall_length(room: RoomConfig, wall: Wall) -> float:
    """Length of ``wall`` (m)."""
    w, d, _ = room.size_m
    return w if wall in (Wall.SOUTH, Wall.NORTH) else d


def wall_frame(room: RoomConfig, wall: Wall) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origin at floor level, unit tangent along the wall, unit inward normal), world."""
    w, d, _ = room.size_m
    if wall is Wall.SOUTH:
        return np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0])
    if wall is Wall.NORTH:
        return np.array([0.0, d, 0]), np.array([1.0, 0, 0]), np.array([0.0, -1, 0])
    if wall is Wall.WEST:
        return np.array([0.0, 0, 0]), np.array([0.0, 1, 0]), np.array([1.0, 0, 0])
    return np.array([w, 0.0, 0]), np.array([0.0, 1, 0]), np.array([-1.0, 0, 0])


# --------------------------------------------------------------------------------------
# geometry (numpy vertices (V, 3) m, faces (F, 3))


def _quad(p0, p1, p2, p3, normal) -> tuple[np.ndarray, np.ndarray]:
    v = np.array([p0, p1, p2, p3], dtype=np.float64)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    n = np.cross(v[1] - v[0], v[2] - v[0])
    if np.dot(n, normal) < 0:
        f = f[:, ::-1]
    return v, f


def merge_meshes(parts) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate ``[(V_i, F_i)]`` into one ``(V, F)``."""
    vs, fs, off = [], [], 0
    for v, f in parts:
        vs.append(np.asarray(v, dtype=np.float64))
        fs.append(np.asarray(f) + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def wall_with_holes(room: RoomConfig, wall: Wall, holes) -> tuple[np.ndarray, np.ndarray]:
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
                quads.append(_quad(*p, n))
            z = max(z, z1)
    return merge_meshes(quads)


def box_mesh(center, extents, rotation_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned (then rotated about +z) box with outward faces."""
    b = trimesh.creation.box(extents=extents)
    v = np.asarray(b.vertices, dtype=np.float64)
    a = math.radians(rotation_deg)
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    return v @ rot.T + np.asarray(center), np.asarray(b.faces)


def inward_box(lo, hi, *, open_axis: int | None = None, open_at: float = 0.0):
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
        _quad(
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


def points_in_view(camera, points) -> np.ndarray:
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


# --------------------------------------------------------------------------------------
# the hinged door


class Door:
    """Geometry of a hinged door leaf; angle 0 = closed (in the wall), > 0 swings into the room."""

    THICKNESS_M = 0.04

    def __init__(self, room: RoomConfig, config: DoorConfig) -> None:
        self.config = config
        origin, t, n = wall_frame(room, config.wall)
        self.tangent, self.normal = t, n
        c = config.center_m
        self.center = origin + c * t  # doorway centre on the floor
        s_hinge = (
            c - config.width_m / 2 if config.hinge is HingeSide.START else c + config.width_m / 2
        )
        self.hinge = origin + s_hinge * t
        # leaf (closed): from the hinge toward the other jamb, just inside the wall plane
        self._leaf_dir = t if config.hinge is HingeSide.START else -t
        v, f = box_mesh(
            (0, 0, 0), (config.width_m - 0.01, self.THICKNESS_M, config.height_m - 0.01)
        )
        # local: x along the leaf from the hinge, y along the inward normal, z up
        self._local = v + np.array([config.width_m / 2, self.THICKNESS_M / 2, config.height_m / 2])
        # a left-handed (leaf, normal, up) basis mirrors the box: flip faces to keep them outward
        mirrored = np.linalg.det(np.stack([self._leaf_dir, n, [0.0, 0.0, 1.0]])) < 0
        self.faces = f[:, ::-1] if mirrored else f

    def vertices(self, angle_rad: float) -> np.ndarray:
        """World vertices of the leaf opened by ``angle_rad`` (turning toward the room)."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        d = c * self._leaf_dir + s * self.normal
        side = c * self.normal - s * self._leaf_dir
        v = self._local
        return self.hinge + v[:, :1] * d + v[:, 1:2] * side + v[:, 2:3] * np.array([0, 0, 1.0])

    def corridor(self, room: RoomConfig) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        w = c.width_m + 1.2
        a = self.center - self.tangent * w / 2
        b = self.center + self.tangent * w / 2 - self.normal * c.corridor_depth_m
        lo = np.minimum(a, b)
        hi = np.maximum(a, b)
        hi[2] = c.height_m + 0.3
        axis = int(np.argmax(np.abs(self.normal)))
        return inward_box(lo, hi, open_axis=axis, open_at=float(self.center[axis]))

    def waypoints(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(corridor start, doorway, inside the room) (x, y) points of the way in."""
        corridor = self.center - 0.7 * self.config.corridor_depth_m * self.normal
        inside = self.center + 0.9 * self.normal
        return corridor[:2], self.center[:2], inside[:2]


# --------------------------------------------------------------------------------------
# people


@dataclass(frozen=True)
class Appearance:
    """One visitor's body: stature (m), build (width scale), albedos, walking speed (m/s)."""

    height_m: float
    build: float
    upper_albedo: float
    lower_albedo: float
    skin_albedo: float
    speed_m_s: float

    @property
    def radius_m(self) -> float:
        """Footprint radius (m): half the shoulder width."""
        return 0.22 * self.build * self.height_m / 1.75

    @staticmethod
    def draw(rng: np.random.Generator, people: PeopleConfig) -> Appearance:
        return Appearance(
            height_m=float(rng.uniform(*people.height_m)),
            build=float(rng.uniform(*people.build)),
            upper_albedo=float(rng.uniform(*people.clothing_albedo)),
            lower_albedo=float(rng.uniform(*people.clothing_albedo)),
            skin_albedo=float(rng.uniform(*people.skin_albedo)),
            speed_m_s=float(rng.uniform(*people.walk_speed_m_s)),
        )


#: A person standing still, used for slots nobody occupies.
DEFAULT_APPEARANCE = Appearance(1.75, 1.0, 0.3, 0.2, 0.35, 1.2)


@dataclass(frozen=True)
class Pose:
    """Where a person is and how their limbs are posed.

    Args:
        x, y: pelvis position on the floor (m).
        heading_rad: facing direction, from +x toward +y.
        gait_phase_rad: walking cycle phase.
        gait: walking amplitude, 0 (still) to 1 (walking).
        sit: 0 standing to 1 seated.
    """

    x: float
    y: float
    heading_rad: float = 0.0
    gait_phase_rad: float = 0.0
    gait: float = 0.0
    sit: float = 0.0


def _rot_fwd(theta):
    """Rotation about local y that swings a limb hanging along -z forward (+x) by theta."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


class BodyModel:
    """Articulated low-poly person: three meshes (clothes upper, clothes lower, skin).

    Proportions are fractions of stature (thigh and shin 0.245, pelvis at 0.53
    standing); widths scale with build. Face counts do not depend on the person.
    """

    PARTS = ("upper", "lower", "skin")

    def __init__(self) -> None:
        cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=8)
        self._limb = (np.asarray(cyl.vertices) - [0, 0, 0.5], np.asarray(cyl.faces))  # z in [-1, 0]
        torso = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=12)
        self._torso = (
            np.asarray(torso.vertices) + [0, 0, 0.5],
            np.asarray(torso.faces),
        )  # z in [0, 1]
        head = trimesh.creation.icosphere(subdivisions=1)
        self._head = (np.asarray(head.vertices), np.asarray(head.faces))
        box = trimesh.creation.box(extents=(1, 1, 1))
        self._foot = (np.asarray(box.vertices), np.asarray(box.faces))
        # fixed layout of the parts in each mesh (for faces)
        self.faces = {
            "upper": merge_meshes([self._torso] + [self._limb] * 4)[1],
            "lower": merge_meshes([self._limb] * 4 + [self._foot] * 2)[1],
            "skin": merge_meshes([self._head, self._limb])[1],
        }

    def vertices(self, a: Appearance, p: Pose) -> dict[str, np.ndarray]:
        """World vertices of each mesh for appearance ``a`` in pose ``p``."""
        h, b = a.height_m, a.build
        s = h / 1.75
        leg = 0.245 * h
        ankle = 0.04 * h
        sit_thigh = p.sit * math.pi / 2
        hz = leg * (math.cos(sit_thigh) + 1.0) + ankle
        amp = 0.45 * p.gait
        limbs_lo = []
        feet = []
        for side, ph in ((1.0, p.gait_phase_rad), (-1.0, p.gait_phase_rad + math.pi)):
            walk_thigh = amp * math.sin(ph)
            walk_shin = walk_thigh - amp * 0.9 * (0.5 - 0.5 * math.cos(ph + 0.6))
            thigh = (1 - p.sit) * walk_thigh + sit_thigh
            shin = (1 - p.sit) * walk_shin
            hip = np.array([0.0, side * 0.09 * b * s, hz])
            r_t, r_s = _rot_fwd(thigh), _rot_fwd(shin)
            knee = hip + r_t @ np.array([0, 0, -leg])
            limbs_lo.append(self._place(self._limb, hip, r_t, (0.065 * b * s, 0.065 * b * s, leg)))
            limbs_lo.append(self._place(self._limb, knee, r_s, (0.05 * b * s, 0.05 * b * s, leg)))
            ank = knee + r_s @ np.array([0, 0, -leg])
            feet.append(
                self._place(
                    self._foot,
                    ank + r_s @ np.array([0.05 * s, 0, -ankle / 2]),
                    r_s,
                    (0.24 * s, 0.09 * s, ankle),
                )
            )
        torso_h = 0.31 * h
        upper = [
            self._place(
                self._torso,
                np.array([0, 0, hz - 0.02 * h]),
                np.eye(3),
                (0.11 * b * s, 0.18 * b * s, torso_h),
            )
        ]
        for side, ph in ((1.0, p.gait_phase_rad), (-1.0, p.gait_phase_rad + math.pi)):
            walk_arm = -0.7 * amp * math.sin(ph)
            arm = (1 - p.sit) * walk_arm + p.sit * 0.35
            fore = (1 - p.sit) * (walk_arm + 0.2 * p.gait) + p.sit * 1.4
            sh = np.array([0.0, side * (0.18 * b + 0.04) * s, hz + 0.28 * h])
            r_a, r_f = _rot_fwd(arm), _rot_fwd(fore)
            elbow = sh + r_a @ np.array([0, 0, -0.17 * h])
            upper.append(self._place(self._limb, sh, r_a, (0.04 * b * s, 0.04 * b * s, 0.17 * h)))
            upper.append(
                self._place(self._limb, elbow, r_f, (0.035 * b * s, 0.035 * b * s, 0.17 * h))
            )
        skin = [
            self._place(
                self._head,
                np.array([0, 0, hz + 0.405 * h]),
                np.eye(3),
                (0.055 * h, 0.05 * h, 0.065 * h),
            ),
            self._place(
                self._limb,
                np.array([0, 0, hz + 0.36 * h]),
                np.eye(3),
                (0.03 * s, 0.03 * s, 0.08 * h),
            ),
        ]
        c, sn = math.cos(p.heading_rad), math.sin(p.heading_rad)
        world = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
        pos = np.array([p.x, p.y, 0.0])
        out = {}
        for name, parts in (("upper", upper), ("lower", limbs_lo + feet), ("skin", skin)):
            out[name] = np.concatenate(parts) @ world.T + pos
        return out

    def parked(self) -> dict[str, np.ndarray]:
        """Vertices of an unused slot: a standing person far below the floor."""
        x, y, z = PARK_POSITION_M
        v = self.vertices(DEFAULT_APPEARANCE, Pose(x, y))
        return {k: vv + np.array([0, 0, z]) for k, vv in v.items()}

    @staticmethod
    def _place(mesh, origin, rot, scale) -> np.ndarray:
        return (mesh[0] * np.asarray(scale)) @ rot.T + origin


# --------------------------------------------------------------------------------------
# navigation


class NavGrid:
    """Free floor cells (``NAV_CELL_M``) at ``NAV_CLEARANCE_M`` from walls and obstacles."""

    def __init__(self, room: RoomConfig, obstacles: list[FurnitureConfig]) -> None:
        w, d, _ = room.size_m
        self.nx, self.ny = int(math.ceil(w / NAV_CELL_M)), int(math.ceil(d / NAV_CELL_M))
        xs = (np.arange(self.nx) + 0.5) * NAV_CELL_M
        ys = (np.arange(self.ny) + 0.5) * NAV_CELL_M
        gx, gy = np.meshgrid(xs, ys)  # [iy, ix]
        c = NAV_CLEARANCE_M
        free = (gx > c) & (gx < w - c) & (gy > c) & (gy < d - c)
        for f in obstacles:
            dd, ww, _ = f.size
            a = math.radians(f.rotation_deg)
            rx = (gx - f.position_m[0]) * math.cos(a) + (gy - f.position_m[1]) * math.sin(a)
            ry = -(gx - f.position_m[0]) * math.sin(a) + (gy - f.position_m[1]) * math.cos(a)
            free &= ~((np.abs(rx) < dd / 2 + c) & (np.abs(ry) < ww / 2 + c))
        self.free = free
        self.free_cells = np.argwhere(free)  # (iy, ix)
        if len(self.free_cells) == 0:
            raise ValueError("furniture: no free floor left to walk on")

    def cell(self, p) -> tuple[int, int]:
        ix = min(max(int(p[0] / NAV_CELL_M), 0), self.nx - 1)
        iy = min(max(int(p[1] / NAV_CELL_M), 0), self.ny - 1)
        return iy, ix

    def point(self, c) -> np.ndarray:
        return (np.array([c[1], c[0]], dtype=np.float64) + 0.5) * NAV_CELL_M

    def nearest_free(self, p) -> tuple[int, int]:
        iy, ix = self.cell(p)
        if self.free[iy, ix]:
            return iy, ix
        d = np.abs(self.free_cells - [iy, ix]).sum(axis=1)
        return tuple(self.free_cells[int(np.argmin(d))])

    def random_point(self, rng: np.random.Generator) -> np.ndarray:
        c = self.free_cells[rng.integers(len(self.free_cells))]
        return self.point(c) + rng.uniform(-0.3, 0.3, 2) * NAV_CELL_M

    def _clear(self, a, b) -> bool:
        n = int(np.linalg.norm(b - a) / (0.5 * NAV_CELL_M)) + 2
        for t in np.linspace(0, 1, n):
            iy, ix = self.cell(a + t * (b - a))
            if not self.free[iy, ix]:
                return False
        return True

    def plan(self, a, b) -> list[np.ndarray]:
        """Waypoints from ``a`` to ``b`` (x, y), around obstacles (A*, 8-connected, smoothed)."""
        a, b = np.asarray(a, float), np.asarray(b, float)
        s, g = self.nearest_free(a), self.nearest_free(b)
        came = {s: None}
        cost = {s: 0.0}
        heap = [(0.0, s)]
        while heap:
            _, cur = heapq.heappop(heap)
            if cur == g:
                break
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dx == 0 and dy == 0:
                        continue
                    nb = (cur[0] + dy, cur[1] + dx)
                    if not (0 <= nb[0] < self.ny and 0 <= nb[1] < self.nx) or not self.free[nb]:
                        continue
                    nc = cost[cur] + (1.4142 if dx and dy else 1.0)
                    if nc < cost.get(nb, math.inf):
                        cost[nb] = nc
                        came[nb] = cur
                        heapq.heappush(heap, (nc + math.hypot(nb[0] - g[0], nb[1] - g[1]), nb))
        cells = []
        cur = g if g in came else s
        while cur is not None:
            cells.append(cur)
            cur = came[cur]
        pts = [self.point(c) for c in reversed(cells)]
        # string-pulling: keep a point only when the straight line would cross an obstacle
        smooth = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self._clear(pts[i], pts[j]):
                j -= 1
            smooth.append(pts[j])
            i = j
        return [a, *smooth, b]


# --------------------------------------------------------------------------------------
# simulation


def switching_process(
    rng: np.random.Generator, num_frames: int, fps: float, mean_on_s: float, mean_off_s: float
) -> np.ndarray:
    """On/off state per frame of a two-state Markov process (exponential durations).

    The initial state is drawn from the stationary distribution, so the sequence
    has no start-up transient. Returns a bool array of shape (num_frames,).
    """
    out = np.zeros(num_frames, dtype=bool)
    on = bool(rng.random() < mean_on_s / (mean_on_s + mean_off_s))
    t, end = 0.0, num_frames / fps
    while t < end:
        dur = rng.exponential(mean_on_s if on else mean_off_s)
        i0, i1 = int(math.ceil(t * fps - 1e-9)), int(math.ceil(min(t + dur, end) * fps - 1e-9))
        out[i0:i1] = on
        t += dur
        on = not on
    return out


@dataclass
class PeopleTrack:
    """Simulated people (numpy), per frame ``f`` and slot ``k``.

    ``active[f, k]`` (in the scene: inside the room or in the corridor),
    ``pose[f, k] = (x, y, heading, gait phase, gait, sit)``, ``visit[f, k]``
    (index into ``appearances``, -1 when inactive), ``door_angle_rad[f]``.
    """

    active: np.ndarray
    pose: np.ndarray
    visit: np.ndarray
    appearances: list[Appearance]
    door_angle_rad: np.ndarray


@dataclass
class _Agent:
    appearance: int
    pos: np.ndarray  # (x, y) on the floor (m)
    heading_rad: float
    tasks: list = field(default_factory=list)
    stops_left: int = 0
    phase_rad: float = 0.0
    gait: float = 0.0
    sit: float = 0.0
    seat: int | None = None
    passing: bool = False  # on the way through the doorway (opens the door)


def _turn(h, target, max_step):
    d = (target - h + math.pi) % (2 * math.pi) - math.pi
    return h + max(-max_step, min(max_step, d))


def simulate_people(
    *,
    rng: np.random.Generator,
    num_frames: int,
    fps: float,
    slots: int,
    people: PeopleConfig,
    nav: NavGrid,
    seats: list[tuple[float, float, float]],
    door: Door | None,
    arrivals_per_s: float = 0.0,
    population: int = 0,
    burn_in_s: float = 0.0,
) -> PeopleTrack:
    """Simulate people frame by frame.

    With a ``door``, people arrive (Poisson, ``arrivals_per_s``) while fewer than
    ``slots`` are present, enter from the corridor through the doorway, make
    ``people.stops`` stops (sitting on a free chair with ``sit_probability``, else
    standing at a random free spot) of ``people.dwell_s`` each, and leave the way
    they came; the door opens when someone is near it or someone props it open.
    Without a door, ``population`` people wander the room for the whole sequence.
    People avoid furniture but not each other (they may overlap briefly).
    """
    dt = 1.0 / fps
    burn = int(round(burn_in_s * fps))
    total = burn + num_frames
    appearances: list[Appearance] = []
    agents: list[_Agent | None] = [None] * slots
    seat_owner: list[int | None] = [None] * len(seats)
    active = np.zeros((num_frames, slots), dtype=bool)
    pose = np.zeros((num_frames, slots, 6))
    visit = np.full((num_frames, slots), -1, dtype=np.int32)
    door_angle = np.zeros(num_frames)
    entrance = door.waypoints() if door is not None else None

    def new_agent(pos, stops):
        appearances.append(Appearance.draw(rng, people))
        return _Agent(
            appearance=len(appearances) - 1,
            pos=np.asarray(pos, float),
            heading_rad=float(rng.uniform(-math.pi, math.pi)),
            stops_left=stops,
        )

    def plan_next(k, ag):
        if ag.stops_left > 0 or entrance is None:
            ag.stops_left -= 1
            ag.passing = False
            free = [i for i, o in enumerate(seat_owner) if o is None]
            if free and rng.random() < people.sit_probability:
                si = int(free[rng.integers(len(free))])
                seat_owner[si] = k
                ag.seat = si
                goal = np.array(seats[si][:2])
                ag.tasks = [
                    ("walk", nav.plan(ag.pos, goal)[1:]),
                    ("sit", si),
                    ("dwell", float(rng.uniform(*people.dwell_s))),
                    ("stand", si),
                ]
            else:
                goal = nav.random_point(rng)
                ag.tasks = [
                    ("walk", nav.plan(ag.pos, goal)[1:]),
                    ("dwell", float(rng.uniform(*people.dwell_s))),
                ]
        else:
            corridor, doorway, inside = entrance
            ag.tasks = [
                ("walk", [*nav.plan(ag.pos, inside)[1:], doorway, corridor]),
                ("exit", None),
            ]
            ag.passing = True

    if entrance is None:
        for k in range(min(population, slots)):
            agents[k] = new_agent(nav.random_point(rng), 0)
    door_cfg = door.config if door is not None else None
    propped = False
    propped_until = 0.0
    if door_cfg is not None and door_cfg.mean_propped_s > 0:
        propped_until = rng.exponential(door_cfg.mean_unpropped_s)
    last_near = -math.inf
    angle = 0.0
    for step in range(total):
        t = step * dt
        # arrivals
        if entrance is not None and rng.random() < arrivals_per_s * dt:
            free_slots = [k for k in range(slots) if agents[k] is None]
            if free_slots:
                k = free_slots[0]
                corridor, doorway, inside = entrance
                ag = new_agent(corridor, int(rng.integers(people.stops[0], people.stops[1] + 1)))
                ag.heading_rad = math.atan2(*(doorway - corridor)[::-1])
                ag.tasks = [("walk", [doorway, inside])]
                ag.passing = True
                agents[k] = ag
        for k in range(slots):
            ag = agents[k]
            if ag is None:
                continue
            if not ag.tasks:
                plan_next(k, ag)
            kind, arg = ag.tasks[0]
            speed = appearances[ag.appearance].speed_m_s
            moving = False
            if kind == "walk":
                step_len = speed * dt
                while arg and step_len > 0:
                    d = arg[0] - ag.pos
                    dist = float(np.linalg.norm(d))
                    if dist > 1e-9:
                        ag.heading_rad = _turn(
                            ag.heading_rad, math.atan2(d[1], d[0]), TURN_RATE_RAD_S * dt
                        )
                    if dist <= step_len:
                        ag.pos = np.array(arg.pop(0), float)
                        step_len -= dist
                        ag.phase_rad += (
                            2
                            * math.pi
                            * dist
                            / (CYCLE_LENGTH_PER_HEIGHT * appearances[ag.appearance].height_m)
                        )
                    else:
                        ag.pos = ag.pos + d / dist * step_len
                        ag.phase_rad += (
                            2
                            * math.pi
                            * step_len
                            / (CYCLE_LENGTH_PER_HEIGHT * appearances[ag.appearance].height_m)
                        )
                        step_len = 0.0
                moving = True
                if not arg:
                    ag.tasks.pop(0)
            elif kind == "sit":
                target = seats[arg][2]
                ag.heading_rad = _turn(ag.heading_rad, target, TURN_RATE_RAD_S * dt)
                if abs((target - ag.heading_rad + math.pi) % (2 * math.pi) - math.pi) < 1e-6:
                    ag.sit = min(1.0, ag.sit + SIT_RATE_PER_S * dt)
                    if ag.sit >= 1.0:
                        ag.tasks.pop(0)
            elif kind == "dwell":
                ag.tasks[0] = ("dwell", arg - dt)
                if arg - dt <= 0:
                    ag.tasks.pop(0)
            elif kind == "stand":
                ag.sit = max(0.0, ag.sit - SIT_RATE_PER_S * dt)
                if ag.sit <= 0.0:
                    seat_owner[arg] = None
                    ag.seat = None
                    ag.tasks.pop(0)
            elif kind == "exit":
                agents[k] = None
                continue
            ag.gait = (
                min(1.0, ag.gait + GAIT_RATE_PER_S * dt)
                if moving
                else max(0.0, ag.gait - GAIT_RATE_PER_S * dt)
            )
        # door
        if door is not None:
            for ag in agents:
                if (
                    ag is not None
                    and ag.passing
                    and np.linalg.norm(ag.pos - door.center[:2]) < door_cfg.trigger_distance_m
                ):
                    last_near = t
            if door_cfg.mean_propped_s > 0 and t >= propped_until:
                propped = not propped
                propped_until = t + rng.exponential(
                    door_cfg.mean_propped_s if propped else door_cfg.mean_unpropped_s
                )
            target = (
                math.radians(door_cfg.max_angle_deg)
                if (propped or t - last_near <= door_cfg.hold_open_s)
                else 0.0
            )
            step_a = math.radians(door_cfg.speed_deg_s) * dt
            angle += max(-step_a, min(step_a, target - angle))
        f = step - burn
        if f < 0:
            continue
        door_angle[f] = angle
        for k, ag in enumerate(agents):
            if ag is None:
                continue
            active[f, k] = True
            visit[f, k] = ag.appearance
            pose[f, k] = (ag.pos[0], ag.pos[1], ag.heading_rad, ag.phase_rad, ag.gait, ag.sit)
    return PeopleTrack(active, pose, visit, appearances, door_angle)


# --------------------------------------------------------------------------------------
# labels from state


def inside_room(room: RoomConfig, x: float, y: float) -> bool:
    """A person is in the room when their pelvis is inside the walls."""
    return 0.0 < x < room.size_m[0] and 0.0 < y < room.size_m[1]


def zone_overlaps(zone: ZoneConfig, x: float, y: float, radius_m: float) -> bool:
    """True when the footprint circle (centre x, y, radius) overlaps the zone rectangle."""
    x0, y0, x1, y1 = zone.rect_m
    dx = max(x0 - x, 0.0, x - x1)
    dy = max(y0 - y, 0.0, y - y1)
    return dx * dx + dy * dy < radius_m * radius_m


# --------------------------------------------------------------------------------------
# Mitsuba shapes


def static_shapes(
    room: RoomConfig,
    window: WindowConfig | None,
    door: Door | None,
    furniture: tuple[FurnitureConfig, ...],
) -> dict:
    """The room shell, corridor and furniture as one Mitsuba mesh with a per-vertex albedo.

    One shape rather than one per albedo: every shape adds to the per-frame cost
    of tracing the render kernel (Dr.Jit records each shape's and BSDF's calls).
    """
    holes: dict[Wall, list] = {w: [] for w in Wall}
    if window is not None:
        holes[window.wall].append(
            (
                window.center_m - window.width_m / 2,
                window.center_m + window.width_m / 2,
                window.sill_height_m,
                window.sill_height_m + window.height_m,
            )
        )
    if door is not None:
        c = door.config
        holes[c.wall].append(
            (c.center_m - c.width_m / 2, c.center_m + c.width_m / 2, 0.0, c.height_m)
        )
    w, d, h = room.size_m
    parts = [(wall_with_holes(room, wall, holes[wall]), room.wall_albedo) for wall in Wall]
    floor = _quad((0, 0, 0), (w, 0, 0), (w, d, 0), (0, d, 0), (0, 0, 1.0))
    ceiling = _quad((0, 0, h), (w, 0, h), (w, d, h), (0, d, h), (0, 0, -1.0))
    parts += [(floor, room.floor_albedo), (ceiling, room.ceiling_albedo)]
    if door is not None:
        parts.append((door.corridor(room), door.config.corridor_albedo))
    parts += [(furniture_mesh(item), item.reflectance) for item in furniture]
    vertices, faces = merge_meshes([mesh for mesh, _ in parts])
    albedo = np.concatenate([np.full(len(mesh[0]), a) for mesh, a in parts])
    return {ROOM_KEY: ms.mesh(ROOM_KEY, vertices, faces, reflectance=albedo)}


class PeopleLayout:
    """Where each person slot's vertices lie in the one mesh holding every person.

    All people are one mesh (key ``"people"``) with a per-vertex albedo
    (``vertex_albedo``), not three meshes per slot: Dr.Jit records the calls of
    every shape and BSDF when it traces a frame's render, and the 24 person
    meshes of the workspace's 8 slots cost about 4 ms of tracing per frame
    (render at 1 spp: 13.8 ms with them, 9-10 ms with one mesh).
    Slot ``s`` owns vertices ``[s V, (s + 1) V)``,
    its parts (upper clothes, lower clothes, skin) in :attr:`BodyModel.PARTS` order.
    """

    def __init__(self, body: BodyModel, slots: int) -> None:
        self.body, self.slots = body, slots
        parked = body.parked()
        self.part_sizes = [len(parked[p]) for p in BodyModel.PARTS]
        self.slot_size = sum(self.part_sizes)
        self.parked_vertices = np.concatenate([parked[p] for p in BodyModel.PARTS])
        offsets = np.cumsum([0, *self.part_sizes[:-1]])
        parts = zip(BodyModel.PARTS, offsets, strict=True)
        one = np.concatenate([body.faces[p] + o for p, o in parts])
        self.faces = np.concatenate([one + k * self.slot_size for k in range(slots)])

    def person(self, a: Appearance, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices (V, 3) m, albedo (V,))`` of one slot holding person ``a`` in ``pose``."""
        v = self.body.vertices(a, pose)
        albedo = np.repeat([a.upper_albedo, a.lower_albedo, a.skin_albedo], self.part_sizes)
        return np.concatenate([v[p] for p in BodyModel.PARTS]), albedo

    def empty(self) -> tuple[np.ndarray, np.ndarray]:
        """``(vertices, albedo)`` of an unused slot: parked out of sight."""
        return self.parked_vertices, np.full(self.slot_size, PARKED_ALBEDO)

    def slot(self, s: int) -> slice:
        """Vertex range of slot ``s``."""
        return slice(s * self.slot_size, (s + 1) * self.slot_size)

    def shape(self):
        """The people mesh with every slot parked, for a scene dict."""
        v, albedo = self.empty()
        return ms.mesh(
            PEOPLE_KEY,
            np.tile(v, (self.slots, 1)),
            self.faces,
            reflectance=np.tile(albedo, self.slots),
        )


# --------------------------------------------------------------------------------------
# the scene of an indoor family and its per-frame parameters


@dataclass(frozen=True)
class Light:
    """A switchable emitter of the scene: its dict key and its radiance when on (W m^-2 sr^-1)."""

    name: str
    key: str
    radiance_w_m2_sr: float

    @property
    def radiance_param(self) -> str:
        return f"{self.key}.emitter.radiance.value"

    @property
    def weight_param(self) -> str:
        return f"{self.key}.emitter.sampling_weight"


class SkySampling(enum.Enum):
    """How light samples find the sky seen through the window."""

    PORTAL = "portal"  # through the window opening (mincam_render.render.portal_sky)
    ENVMAP = "envmap"  # Mitsuba's envmap: over the whole sphere (for validation)


@dataclass(frozen=True)
class IndoorState:
    """Everything that changes between frames of an indoor scene.

    Args:
        people: the people in the scene (inside the room or in the corridor) as
            ``(appearance, pose)``; at most the family's number of slots. The
            rest of the slots are parked out of sight.
        door_angle_rad: opening of the door (0 = closed); ignored without a door.
        lights_on: on/off per switchable light, in the family's order.
        daylight_time_s: time (s) whose sun and sky light the window.
        daylight: False turns the sun and sky off (one light's background
            component); the sky keeps a 1e-6 W m^-2 sr^-1 floor so its sampling
            stays defined (about 1e-7 of the daylit sky).
    """

    people: tuple[tuple[Appearance, Pose], ...] = ()
    door_angle_rad: float = 0.0
    lights_on: tuple[bool, ...] = ()
    daylight_time_s: float = 0.0
    daylight: bool = True


#: Parameter keys of the sun and sky (checked against mi.traverse at build time).
SUN_KEY, SKY_KEY = "sun", "sky"
SUN_IRRADIANCE_PARAM = f"{SUN_KEY}.irradiance.value"
SUN_TO_WORLD_PARAM = f"{SUN_KEY}.to_world"
SKY_DATA_PARAM = f"{SKY_KEY}.data"
ROOM_KEY = "room"
PEOPLE_KEY = "people"
PEOPLE_VERTICES_PARAM = f"{PEOPLE_KEY}.vertex_positions"
PEOPLE_ALBEDO_PARAM = f"{PEOPLE_KEY}.{ms.VERTEX_ALBEDO}"
#: Albedo of an unused (parked) person slot.
PARKED_ALBEDO = 0.3
DOOR_KEY = "door"
DOOR_VERTICES_PARAM = f"{DOOR_KEY}.vertex_positions"
#: Lat-long size of the sky map seen through windows (a smooth CIE sky needs little).
SKY_MAP_SIZE = (32, 64)
#: Scenes whose parameters an :class:`IndoorRig` keeps between frames (the render
#: scene plus one more, e.g. a preview's).
_SCENES_KEPT = 2
#: Sampling weight of a switched-off emitter: tiny, never zero (an all-dark scene
#: must still have a valid emitter distribution).
OFF_SAMPLING_WEIGHT = 1e-6


@dataclass
class _SceneCache:
    """An indoor scene's parameters and the state last applied to it.

    Holds the scene itself, so its identity cannot be reused while cached.
    """

    scene: object
    params: object  # mi.SceneParameters
    applied: dict[str, object]
    people_vertices: np.ndarray  # (slots V, 3) float32, m
    people_albedo: np.ndarray  # (slots V,) float32


class IndoorRig:
    """Builds an indoor scene once and applies an :class:`IndoorState` to it in place."""

    def __init__(
        self,
        *,
        room: RoomConfig,
        window: WindowConfig | None,
        door: DoorConfig | None,
        furniture: tuple[FurnitureConfig, ...],
        banks: tuple[LightBankConfig, ...],
        lamps: tuple[FloorLampConfig, ...],
        daylight,
        daylight_update_s: float,
        slots: int,
        max_depth: int,
        sky_sampling: SkySampling = SkySampling.PORTAL,
    ) -> None:
        self.room, self.window, self.furniture = room, window, furniture
        self.door = Door(room, door) if door is not None else None
        self.banks, self.lamps = banks, lamps
        self.daylight_config, self.daylight_update_s = daylight, daylight_update_s
        self.slots, self.max_depth = slots, max_depth
        self.sky_sampling = sky_sampling
        self.body = BodyModel()
        self.people = PeopleLayout(self.body, slots)
        self.lights = tuple(
            [Light(b.name, f"bank_{i}", bank_radiance_w_m2_sr(b)) for i, b in enumerate(banks)]
            + [Light(lp.name, f"lamp_{i}", lamp_radiance_w_m2_sr(lp)) for i, lp in enumerate(lamps)]
        )
        self._sky_cache: dict[float, object] = {}
        self._scenes: list[_SceneCache] = []  # newest first

    # -- building
    def param_keys(self) -> list[str]:
        keys = [PEOPLE_VERTICES_PARAM, PEOPLE_ALBEDO_PARAM] if self.slots else []
        keys += [li.radiance_param for li in self.lights] + [li.weight_param for li in self.lights]
        if self.door is not None:
            keys.append(DOOR_VERTICES_PARAM)
        if self.window is not None:
            keys += [SUN_IRRADIANCE_PARAM, SUN_TO_WORLD_PARAM, SKY_DATA_PARAM]
        return keys

    def build_scene(self):
        import mitsuba as mi

        from mincam_render.scenes.sky import envmap_to_world

        shapes = static_shapes(self.room, self.window, self.door, self.furniture)
        if self.door is not None:
            shapes[DOOR_KEY] = ms.mesh(
                DOOR_KEY,
                self.door.vertices(0.0),
                self.door.faces,
                reflectance=self.door.config.albedo,
            )
        for li, b in zip(self.lights, self.banks, strict=False):
            shapes[li.key] = ms.mesh(
                li.key,
                *ceiling_panels(self.room, b),
                reflectance=0.8,
                radiance_w_m2_sr=li.radiance_w_m2_sr,
            )
        poles = []
        for li, lamp in zip(self.lights[len(self.banks) :], self.lamps, strict=True):
            pole, shade = lamp_meshes(lamp)
            poles.append(pole)
            shapes[li.key] = ms.mesh(
                li.key, *shade, reflectance=0.8, radiance_w_m2_sr=li.radiance_w_m2_sr
            )
        if poles:
            shapes["lamp_poles"] = ms.mesh("lamp_poles", *merge_meshes(poles), reflectance=0.08)
        if self.slots:
            shapes[PEOPLE_KEY] = self.people.shape()
        if self.window is not None:
            day = self.sky(0.0)
            shapes[SUN_KEY] = ms.directional_light(-day.sun_direction, day.sun_irradiance_w_m2)
            if self.sky_sampling is SkySampling.PORTAL:
                shapes[SKY_KEY] = ms.portal_sky(day.sky_radiance_w_m2_sr, *self.window_rectangle())
            else:
                shapes[SKY_KEY] = ms.environment_map(day.sky_radiance_w_m2_sr, envmap_to_world())
        scene = ms.load_scene(ms.scene_dict(shapes, max_depth=self.max_depth))
        params = mi.traverse(scene)
        missing = [k for k in self.param_keys() if k not in params]
        if missing:
            raise RuntimeError(f"scene has no parameter(s) {missing[:4]}")
        return scene

    def window_rectangle(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The window opening ``(corner, edge_u, edge_v)`` (m, world), edge_u x edge_v outward."""
        w = self.window
        origin, t, inward = wall_frame(self.room, w.wall)
        corner = origin + (w.center_m - w.width_m / 2) * t + w.sill_height_m * np.array([0, 0, 1.0])
        edge_u, edge_v = w.width_m * t, w.height_m * np.array([0, 0, 1.0])
        if np.cross(edge_u, edge_v) @ inward > 0:
            corner, edge_u = corner + edge_u, -edge_u
        return corner, edge_u, edge_v

    def sky(self, time_s: float):
        """Daylight at ``time_s`` rounded down to the update interval (cached)."""
        from mincam_render.scenes.sky import daylight

        tq = self.daylight_time_s(time_s)
        if tq not in self._sky_cache:
            if len(self._sky_cache) > 64:
                self._sky_cache.clear()
            self._sky_cache[tq] = daylight(
                self.daylight_config, tq, height=SKY_MAP_SIZE[0], width=SKY_MAP_SIZE[1]
            )
        return self._sky_cache[tq]

    def daylight_time_s(self, time_s: float) -> float:
        """The time (s) whose daylight is shown at ``time_s``: rounded down to the update period."""
        return math.floor(time_s / self.daylight_update_s + 1e-9) * self.daylight_update_s

    # -- per frame
    def apply(self, scene, state: IndoorState) -> None:
        """Set ``scene``'s parameters to ``state`` in place (no rebuild)."""
        import drjit as dr
        import mitsuba as mi

        # scalars go in as opaque variables, not literals: a literal's value is
        # baked into the kernel, so each new value would compile a new kernel

        if len(state.people) > self.slots:
            raise ValueError(
                f"state has {len(state.people)} people; the scene has {self.slots} slots"
            )
        if len(state.lights_on) != len(self.lights):
            raise ValueError(
                f"state has {len(state.lights_on)} light states; the scene has "
                f"{len(self.lights)} lights"
            )
        cache = self._parameters(scene)
        params, applied = cache.params, cache.applied
        # only what differs from the state last applied to this scene is set:
        # parked slots, unchanged lights and a window's fixed daylight cost nothing
        wanted: dict[str, object] = {}
        for s in range(self.slots):
            wanted[f"slot{s}"] = state.people[s] if s < len(state.people) else None
        wanted["lights"] = tuple(state.lights_on)
        wanted["door"] = state.door_angle_rad if self.door is not None else None
        wanted["daylight"] = (
            (self.daylight_time_s(state.daylight_time_s), state.daylight)
            if self.window is not None
            else None
        )
        todo = {k: v for k, v in wanted.items() if k not in applied or applied[k] != v}
        slots = [s for s in range(self.slots) if f"slot{s}" in todo]
        for s in slots:
            person = state.people[s] if s < len(state.people) else None
            v, albedo = self.people.empty() if person is None else self.people.person(*person)
            cache.people_vertices[self.people.slot(s)] = v
            cache.people_albedo[self.people.slot(s)] = albedo
        if slots:
            params[PEOPLE_VERTICES_PARAM] = mi.Float(cache.people_vertices.ravel())
            params[PEOPLE_ALBEDO_PARAM] = mi.Float(cache.people_albedo)
        if "lights" in todo:
            for li, on in zip(self.lights, state.lights_on, strict=True):
                params[li.radiance_param] = dr.opaque(mi.Float, li.radiance_w_m2_sr if on else 0.0)
                params[li.weight_param] = 1.0 if on else OFF_SAMPLING_WEIGHT
        if self.door is not None and "door" in todo:
            params[DOOR_VERTICES_PARAM] = mi.Float(
                self.door.vertices(state.door_angle_rad).astype(np.float32).ravel()
            )
        if self.window is not None and "daylight" in todo:
            day = self.sky(state.daylight_time_s)
            on = 1.0 if state.daylight else 0.0
            params[SUN_IRRADIANCE_PARAM] = dr.opaque(mi.Float, on * day.sun_irradiance_w_m2)
            params[SUN_TO_WORLD_PARAM] = ms.directional_light_to_world(-day.sun_direction)
            sky = np.maximum(on * day.sky_radiance_w_m2_sr, 1e-6)
            params[SKY_DATA_PARAM] = (
                ms.portal_sky_data(sky)
                if self.sky_sampling is SkySampling.PORTAL
                else ms.environment_map_data(sky)
            )
        params.update()
        applied.update(todo)

    def _parameters(self, scene) -> _SceneCache:
        """What this rig keeps of ``scene`` between frames (for the scenes last used)."""
        import mitsuba as mi

        for cache in self._scenes:
            if cache.scene is scene:
                return cache
        n = self.slots * self.people.slot_size
        cache = _SceneCache(
            scene=scene,
            params=mi.traverse(scene),
            applied={},  # nothing known: the first apply sets everything
            people_vertices=np.zeros((n, 3), dtype=np.float32),
            people_albedo=np.zeros(n, dtype=np.float32),
        )
        self._scenes = [cache, *self._scenes[: _SCENES_KEPT - 1]]
        return cache

    def birdseye_view(self):
        from mincam_render.scenes.base import View

        w, d, h = self.room.size_m
        half = 0.5 * max(w, d) + 0.2
        fov = 2 * math.degrees(math.atan(half / (h - 0.1)))
        return View((w / 2, d / 2, h - 0.1), (w / 2, d / 2, 0.0), (0.0, 1.0, 0.0), min(fov, 150.0))


def track_state(track: PeopleTrack, index: int) -> tuple[tuple[Appearance, Pose], ...]:
    """The people of frame ``index`` of a simulation, in slot order."""
    out = []
    for k in np.flatnonzero(track.active[index]):
        x, y, hd, ph, g, s = track.pose[index, k]
        out.append(
            (
                track.appearances[track.visit[index, k]],
                Pose(float(x), float(y), float(hd), float(ph), float(g), float(s)),
            )
        )
    return tuple(out)


def check_room_layout(config) -> None:
    """Checks shared by the indoor descriptions: openings, furniture, lights, capacity, camera.

    Raises:
        ValueError: naming the offending field.
    """
    r = config.room
    if config.window is not None:
        w = config.window
        check_wall_opening("window", r, w.wall, w.center_m, w.width_m, w.sill_height_m, w.height_m)
    d = config.door
    check_wall_opening("door", r, d.wall, d.center_m, d.width_m, 0.0, d.height_m)
    check_furniture(r, config.furniture)
    check_light_banks(r, config.ceiling_lights)
    check_capacity(r, config.max_people)
    check_camera(r, config.camera)


class IndoorFamily(SceneFamily):
    """What the indoor families share: one :class:`IndoorRig`, people and switched lights.

    Subclasses set ``name``, ``config_type`` and :attr:`floor_lamps`, and define
    ``labels``, ``labels_for(state)`` and ``frame_state``.
    """

    def __init__(self, config, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        c = config
        lamps = self.floor_lamps
        self.rig = IndoorRig(
            room=c.room,
            window=c.window,
            door=c.door,
            furniture=c.furniture,
            banks=c.ceiling_lights,
            lamps=lamps,
            daylight=c.daylight,
            daylight_update_s=c.daylight_update_s,
            slots=c.max_people,
            max_depth=c.max_depth,
        )
        rng = np.random.default_rng(seed)
        nav = NavGrid(c.room, [f for f in c.furniture if f.kind is not FurnitureKind.CHAIR])
        seats = [
            (*f.position_m, math.radians(f.rotation_deg))
            for f in c.furniture
            if f.kind is FurnitureKind.CHAIR
        ]
        self.track = simulate_people(
            rng=rng,
            num_frames=num_frames,
            fps=c.fps,
            slots=c.max_people,
            people=c.people,
            nav=nav,
            seats=seats,
            door=self.rig.door,
            arrivals_per_s=c.arrivals_per_min / 60.0,
            burn_in_s=c.burn_in_s,
        )
        # in the rig's light order: ceiling banks, then floor lamps
        switched = [*c.ceiling_lights, *lamps]
        self.lights_on = (
            np.stack(
                [
                    switching_process(rng, num_frames, c.fps, li.mean_on_s, li.mean_off_s)
                    for li in switched
                ],
                axis=1,
            )
            if switched
            else np.zeros((num_frames, 0), dtype=bool)
        )

    @property
    def floor_lamps(self) -> tuple:
        """The description's floor lamps (none unless the family has them)."""
        return ()

    @property
    def fps(self) -> float:
        return self.config.fps

    def camera(self):
        return self.config.camera.camera()

    def build_scene(self):
        return self.rig.build_scene()

    def state(self, index: int) -> IndoorState:
        """The scene state of frame ``index`` (people, door, lights, daylight time)."""
        self.check_index(index)
        return IndoorState(
            people=track_state(self.track, index),
            door_angle_rad=float(self.track.door_angle_rad[index]),
            lights_on=tuple(bool(v) for v in self.lights_on[index]),
            daylight_time_s=self.time_s(index),
        )

    def labels_for(self, state: IndoorState) -> dict[str, np.ndarray]:
        """Labels of any state (e.g. one placed by hand in a test)."""
        raise NotImplementedError

    def apply_state(self, scene, state: IndoorState) -> dict[str, np.ndarray]:
        """Set ``scene`` to ``state`` in place and return its labels."""
        self.rig.apply(scene, state)
        return self.labels_for(state)

    def set_frame(self, scene, index: int) -> dict[str, np.ndarray]:
        return self.apply_state(scene, self.state(index))

    has_background = True

    def _window_start_s(self, index: int, interval_s: float) -> float:
        if not interval_s > 0:
            raise ValueError(f"interval_s = {interval_s!r}: allowed a number > 0 (s)")
        return math.floor(self.time_s(index) / interval_s + 1e-9) * interval_s

    def background_key(self, index: int, interval_s: float) -> str:
        lights = "".join("1" if on else "0" for on in self.state(index).lights_on)
        if self.rig.window is None:  # no daylight: the lights alone make the background
            return f"lights={lights}"
        return f"lights={lights};daylight_s={self._window_start_s(index, interval_s):.10g}"

    def set_background(self, scene, index: int, interval_s: float, *, at: float = 0.0) -> None:
        # nobody in the room, the door closed, the frame's lights, and the daylight
        # at position ``at`` of the frame's interval (0 its start, 1 its end)
        if not 0.0 <= at <= 1.0:
            raise ValueError(f"at = {at!r}: allowed a number in [0, 1]")
        start = self._window_start_s(index, interval_s)
        state = IndoorState(
            lights_on=self.state(index).lights_on, daylight_time_s=start + at * interval_s
        )
        self.rig.apply(scene, state)

    def background_components(self, index: int, interval_s: float) -> dict[str, float]:
        # each light alone (weight 1 when on), and the daylight with every light
        # off at the ends of the frame's window (linear in time between them)
        parts = {
            f"light={li.key}": 1.0
            for li, on in zip(self.rig.lights, self.state(index).lights_on, strict=True)
            if on
        }
        if self.rig.window is not None:
            start = self._window_start_s(index, interval_s)
            a = self.window_fraction(index, interval_s)
            for t, w in ((start, 1.0 - a), (start + interval_s, a)):
                key = f"daylight_s={t:.10g}"
                parts[key] = parts.get(key, 0.0) + w
        return parts

    def set_background_component(self, scene, key: str) -> None:
        off = (False,) * len(self.rig.lights)
        name, _, value = key.partition("=")
        if name == "daylight_s" and self.rig.window is not None:
            state = IndoorState(lights_on=off, daylight_time_s=float(value))
        elif name == "light" and value in (keys := [li.key for li in self.rig.lights]):
            on = tuple(k == value for k in keys)
            state = IndoorState(lights_on=on, daylight=False)
        else:
            raise ValueError(f"{key!r} is not a background component of family {self.name!r}")
        self.rig.apply(scene, state)

    def set_frame_in_window(self, scene, index: int, interval_s: float) -> dict[str, np.ndarray]:
        state = replace(self.state(index), daylight_time_s=self._window_start_s(index, interval_s))
        return self.apply_state(scene, state)

    def sun_window(self):
        """The window opening (see the base class), or None without a window."""
        return None if self.rig.window is None else self.rig.window_rectangle()

    def window_fraction(self, index: int, interval_s: float) -> float:
        """Where frame ``index``'s daylight lies in its window, in [0, 1) (0: its start).

        On the daylight's update grid: the frame's background is interpolated
        linearly between the window's ends with this weight.
        """
        if self.rig.window is None:
            return 0.0
        start = self._window_start_s(index, interval_s)
        shown = self.rig.daylight_time_s
        t0, t1 = shown(start), shown(start + interval_s)
        if t1 <= t0:  # the daylight does not change within the window
            return 0.0
        return min(max((shown(self.time_s(index)) - t0) / (t1 - t0), 0.0), 1.0)

    def birdseye_view(self):
        return self.rig.birdseye_view()
