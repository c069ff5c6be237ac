"""Descriptions of an indoor scene and their checks.

Frozen dataclasses read from TOML: the room, its window and door, furniture,
floor zones, ceiling light banks, floor lamps and people; the walls' frames
(which way a position along a wall runs); and the checks that raise
``ValueError`` naming the field that does not fit the room.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mincam_render.core.config import Described, check_min_max, spec

if TYPE_CHECKING:
    from mincam_render.scenes.base import CameraMount

#: Floor area one person needs (m^2): a room "holds" floor_area / this many people.
AREA_PER_PERSON_M2 = 2.0


class Wall(enum.Enum):
    """A wall of the room by compass side (+y north)."""

    SOUTH = "south"
    NORTH = "north"
    WEST = "west"
    EAST = "east"


class HingeSide(enum.Enum):
    """Which end of the doorway (along the wall, see the package docstring) holds the hinge."""

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


@dataclass(frozen=True, kw_only=True)
class RoomConfig(Described):
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

    def contains(self, point: Sequence[float] | np.ndarray, margin: float = 0.0) -> bool:
        """True when a 2-D or 3-D point is inside the room by at least ``margin`` (m)."""
        p = np.asarray(point, dtype=np.float64)
        return bool(np.all(p >= margin) and np.all(p <= np.asarray(self.size_m[: len(p)]) - margin))


@dataclass(frozen=True, kw_only=True)
class WindowConfig(Described):
    """An open window (a hole in a wall; the sun and sky come in through it)."""

    wall: Wall = spec(Wall.SOUTH, doc="wall holding the window")
    center_m: float = spec(2.0, unit="m", range=(0.0, 50.0), doc="centre along the wall")
    width_m: float = spec(2.0, unit="m", range=(0.2, 20.0), doc="opening width")
    sill_height_m: float = spec(0.9, unit="m", range=(0.0, 10.0), doc="bottom of the opening")
    height_m: float = spec(1.4, unit="m", range=(0.2, 10.0), doc="opening height")


@dataclass(frozen=True, kw_only=True)
class DoorConfig(Described):
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
class FurnitureConfig(Described):
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
class ZoneConfig(Described):
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
class LightBankConfig(Described):
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
class FloorLampConfig(Described):
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
class PeopleConfig(Described):
    """How people look and behave; each visit draws uniformly within these ranges.

    With ``roster = N > 0`` the looks are drawn once, from ``roster_seed``, for
    N fixed people (identity 0 .. N-1), and every visit is one of them not
    already present, so episodes of any seed show the same people.
    """

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
    roster: int = spec(
        0,
        range=(0, 1000),
        doc="0: every visit is a new person; N: every visit is one of N fixed people "
        "(same looks and gait in every episode; privacy studies)",
    )
    roster_seed: int = spec(
        0, range=(0, 2**31 - 1), doc="seed of the roster's looks (not the episode's seed)"
    )

    def description_omits(self) -> tuple[str, ...]:
        """Without a roster its fields are left out of resolved descriptions (format 4 as is)."""
        return ("roster", "roster_seed") if self.roster == 0 else ()

    def __post_init__(self) -> None:
        check_min_max(
            self,
            "height_m",
            "build",
            "walk_speed_m_s",
            "clothing_albedo",
            "skin_albedo",
            "dwell_s",
            "stops",
        )


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


def check_inside(
    name: str, room: RoomConfig, point: Sequence[float] | np.ndarray, margin: float = 0.0
) -> None:
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


def check_camera(room: RoomConfig, camera: CameraMount) -> None:
    """Raise ``ValueError`` unless the camera and the point it faces are in the room."""
    check_inside("camera.position", room, camera.position, 0.01)
    check_inside("camera.look_at", room, camera.look_at, 0.0)


class RoomLayout(Protocol):
    """What :func:`check_room_layout` reads of an indoor description.

    The lighting and workspace descriptions have these fields; naming them here
    (rather than those classes) keeps this module below the families that use it.
    """

    @property
    def room(self) -> RoomConfig: ...
    @property
    def window(self) -> WindowConfig | None: ...
    @property
    def door(self) -> DoorConfig: ...
    @property
    def furniture(self) -> tuple[FurnitureConfig, ...]: ...
    @property
    def ceiling_lights(self) -> tuple[LightBankConfig, ...]: ...
    @property
    def max_people(self) -> int: ...
    @property
    def camera(self) -> CameraMount: ...


def check_room_layout(config: RoomLayout) -> None:
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
