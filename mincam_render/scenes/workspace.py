"""Workspace monitoring (paper Sec. 7.1): people count, zone occupancy, door state.

A furnished office (desks, chairs, shelves, a meeting table) with a hinged door
in one wall and a window in another. Up to ``max_people`` people arrive through
the door (Poisson arrivals), walk around the furniture, stop at a few places
(sitting on a free chair or standing), occlude each other and leave. The door
swings open when someone comes near it and is sometimes propped open. The two
ceiling light banks switch on and off at random, and the sun and sky through
the window follow the time of day (:mod:`.sky`, optionally time-lapsed).

Labels, computed from the scene state of each frame:

- ``people_count``: people whose pelvis is inside the walls (not in the corridor);
- ``zones``: per named floor zone, 1 when a person's footprint circle overlaps it;
- ``door_open``: 1 when the door's angle exceeds ``door.open_threshold_deg``.

The integrator depth is ``max_depth`` (default 3: direct light plus one bounce),
which keeps a frame fast; raise it for converged references.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mincam_render.core.config import Described, spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.scenes.base import CameraMount
from mincam_render.scenes.indoor import (
    DoorConfig,
    FurnitureConfig,
    FurnitureKind,
    IndoorFamily,
    IndoorState,
    LightBankConfig,
    PeopleConfig,
    RoomConfig,
    Wall,
    WindowConfig,
    ZoneConfig,
    check_room_layout,
    check_zones,
    inside_room,
    zone_overlaps,
)
from mincam_render.scenes.sky import DaylightConfig

_D, _C, _S, _T, _K = (
    FurnitureKind.DESK,
    FurnitureKind.CHAIR,
    FurnitureKind.SHELF,
    FurnitureKind.TABLE,
    FurnitureKind.CABINET,
)


def _f(
    kind: FurnitureKind,
    x: float,
    y: float,
    rot: float = 0.0,
    size: tuple[float, float, float] | None = None,
) -> FurnitureConfig:
    return FurnitureConfig(kind=kind, position_m=(x, y), rotation_deg=rot, size_m=size)


#: Default office layout for the default 6 x 5 x 2.8 m room (see scenes/workspace.toml).
DEFAULT_FURNITURE = (
    _f(_D, 1.9, 1.7, 90),
    _f(_C, 1.9, 1.0, 90),
    _f(_D, 3.5, 1.7, 90),
    _f(_C, 3.5, 1.0, 90),
    _f(_D, 3.0, 3.3, -90),
    _f(_C, 3.0, 4.0, -90),
    _f(_D, 4.6, 3.3, -90),
    _f(_C, 4.6, 4.0, -90),
    _f(_S, 0.2, 2.2, 0),
    _f(_S, 5.8, 2.1, 180),
    _f(_T, 5.0, 0.95, 0, (0.8, 0.8, 0.74)),
    _f(_C, 5.0, 1.75, -90),
    _f(_K, 0.25, 0.9, 0),
)
DEFAULT_ZONES = (
    ZoneConfig(name="entrance", rect_m=(0.0, 3.8, 1.8, 5.0)),
    ZoneConfig(name="desks_south", rect_m=(1.0, 0.4, 4.3, 2.2)),
    ZoneConfig(name="desks_north", rect_m=(2.2, 2.8, 5.4, 4.6)),
    ZoneConfig(name="meeting", rect_m=(4.4, 0.3, 6.0, 2.4)),
)
DEFAULT_BANKS = (
    LightBankConfig(
        name="west", panels_m=((1.6, 1.5), (1.6, 3.5)), mean_on_s=180.0, mean_off_s=60.0
    ),
    LightBankConfig(
        name="east", panels_m=((4.2, 1.5), (4.2, 3.5)), mean_on_s=180.0, mean_off_s=60.0
    ),
)


@dataclass(frozen=True, kw_only=True)
class WorkspaceConfig(Described):
    """Description of the workspace family (``scenes/workspace.toml``)."""

    fps: float = spec(30.0, unit="1/s", range=(1.0, 1000.0), doc="frame rate")
    room: RoomConfig = spec(default_factory=RoomConfig, doc="room size and surface albedos")
    window: WindowConfig | None = spec(
        default_factory=lambda: WindowConfig(wall=Wall.SOUTH, center_m=2.4, width_m=2.4),
        doc="window letting in sun and sky",
    )
    door: DoorConfig = spec(
        default_factory=lambda: DoorConfig(wall=Wall.NORTH, center_m=0.9), doc="hinged door"
    )
    furniture: tuple[FurnitureConfig, ...] = spec(DEFAULT_FURNITURE, doc="desks, chairs, ...")
    zones: tuple[ZoneConfig, ...] = spec(DEFAULT_ZONES, doc="named floor zones (labels)")
    ceiling_lights: tuple[LightBankConfig, ...] = spec(DEFAULT_BANKS, doc="switched light banks")
    daylight: DaylightConfig = spec(
        default_factory=lambda: DaylightConfig(start_hour=7.5, hours_per_second=0.003),
        doc="site, date and time of the daylight",
    )
    daylight_update_s: float = spec(
        1.0, unit="s", range=(0.001, 1e6), doc="the sky is recomputed this often"
    )
    people: PeopleConfig = spec(default_factory=PeopleConfig, doc="looks and behaviour")
    max_people: int = spec(8, range=(0, 64), doc="people at most in the scene at once")
    arrivals_per_min: float = spec(1.2, unit="1/min", range=(0.0, 600.0), doc="Poisson rate")
    burn_in_s: float = spec(
        300.0, unit="s", range=(0.0, 1e5), doc="simulated before frame 0 (no empty-room start)"
    )
    max_depth: int = spec(3, range=(1, 64), doc="path depth: 2 = direct light, 3 = +1 bounce")
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(5.85, 0.15, 2.6), look_at=(2.2, 3.4, 0.6), up=(0.0, 0.0, 1.0), detectors=8
        ),
        doc="camera high in the south-east corner",
    )

    def __post_init__(self) -> None:
        check_room_layout(self)
        r, d = self.room, self.door
        if self.window is not None and self.window.wall is d.wall:
            w = self.window
            if abs(w.center_m - d.center_m) < (w.width_m + d.width_m) / 2:
                raise ValueError("window: overlaps the door on the same wall")
        check_zones(r, self.zones)
        if d.open_threshold_deg >= d.max_angle_deg:
            raise ValueError(
                f"door.open_threshold_deg = {d.open_threshold_deg}: must be below "
                f"door.max_angle_deg = {d.max_angle_deg}"
            )


class WorkspaceFamily(IndoorFamily):
    """Monitoring an office: people count, zone occupancy and door state (paper Sec. 7.1)."""

    name = "workspace"
    config_type = WorkspaceConfig

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        return (
            LabelSpec(name="people_count", kind=LabelKind.COUNT, median_filter_s=2.0),
            LabelSpec(
                name="zones",
                kind=LabelKind.BINARY,
                size=len(self.config.zones),
                element_names=tuple(z.name for z in self.config.zones),
                median_filter_s=0.5,
            ),
            LabelSpec(name="door_open", kind=LabelKind.BINARY, median_filter_s=0.5),
        )

    def labels_for(self, state: IndoorState) -> dict[str, np.ndarray]:
        """Labels of any state (e.g. one placed by hand in a test)."""
        c = self.config
        inside = [(p.x, p.y, a.radius_m) for a, p in state.people if inside_room(c.room, p.x, p.y)]
        zones = [any(zone_overlaps(z, x, y, r) for x, y, r in inside) for z in c.zones]
        return {
            "people_count": np.array([len(inside)], dtype=np.float32),
            "zones": np.array(zones, dtype=np.float32),
            "door_open": np.array(
                [math.degrees(state.door_angle_rad) > c.door.open_threshold_deg], dtype=np.float32
            ),
        }

    def frame_state(self, index: int) -> JsonObject:
        st = self.state(index)
        day = self.rig.sky(st.daylight_time_s)
        return {
            "time_s": self.time_s(index),
            "people": [
                {
                    "x_m": p.x,
                    "y_m": p.y,
                    "heading_rad": p.heading_rad,
                    "sit": p.sit,
                    "height_m": a.height_m,
                    "radius_m": a.radius_m,
                    "inside": inside_room(self.config.room, p.x, p.y),
                }
                | ({"identity": a.identity} if self.config.people.roster else {})
                for a, p in st.people
            ],
            "door_angle_deg": math.degrees(st.door_angle_rad),
            "lights_on": {
                b.name: on for b, on in zip(self.config.ceiling_lights, st.lights_on, strict=True)
            },
            "sun_elevation_deg": math.degrees(
                math.asin(float(np.clip(day.sun_direction[2], -1, 1)))
            ),
            "global_horizontal_w_m2": day.global_horizontal_w_m2,
        }
