"""Room lighting estimation (paper Sec. 7.2): on/off state of five lights.

A living-room-like space with three floor lamps (glowing drum shades) and two
banks of overhead panels, each switched on and off by its own random process
(exponential on and off durations). Fluxes are those of real fixtures (lumens,
converted with :mod:`mincam_render.core.photometry`). The camera hangs high on the
south wall looking down into the room, and no emitter is in its view: the
description is rejected when any point of a lamp shade or ceiling panel
projects inside a detector's mask (occlusion is not relied on), so the states
must be inferred from the shading. People come in through a door, walk, sit
and stand about, and leave, casting shadows and hiding parts of the room.
An optional window lets daylight in (none by default).

Label ``lights``: 1 per light that is on, ordered as the overhead banks then
the floor lamps of the description (``element_names``).

The integrator depth is ``max_depth`` (default 3: direct light plus one bounce;
the lights reach the camera only by reflection, so 2 is the least that works).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mincam_render.core.config import Described, spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.strict_json import JsonObject
from mincam_render.render.fidelity.signal import SignalSource
from mincam_render.render.precision import ErrorScale
from mincam_render.scenes.base import CameraMount
from mincam_render.scenes.indoor import (
    DoorConfig,
    FloorLampConfig,
    FurnitureConfig,
    FurnitureKind,
    IndoorFamily,
    IndoorState,
    LightBankConfig,
    PeopleConfig,
    RoomConfig,
    Wall,
    WindowConfig,
    check_inside,
    check_room_layout,
    lamp_surface_points,
    points_in_view,
)
from mincam_render.scenes.sky import DaylightConfig


def _f(
    kind: FurnitureKind,
    x: float,
    y: float,
    rot: float = 0.0,
    size: tuple[float, float, float] | None = None,
) -> FurnitureConfig:
    return FurnitureConfig(kind=kind, position_m=(x, y), rotation_deg=rot, size_m=size)


_K = FurnitureKind
DEFAULT_FURNITURE = (
    _f(_K.SOFA, 3.5, 5.5, -90),
    _f(_K.TABLE, 3.5, 4.2, 0, (0.6, 1.2, 0.45)),
    _f(_K.CHAIR, 2.3, 4.2, 0),
    _f(_K.CHAIR, 4.7, 4.2, 180),
    _f(_K.DESK, 5.6, 2.0, 0),
    _f(_K.CHAIR, 4.95, 2.0, 0),
    _f(_K.SHELF, 6.8, 3.6, 180),
    _f(_K.CABINET, 0.3, 1.8, 0),
)
DEFAULT_LAMPS = (
    FloorLampConfig(name="lamp_southwest", position_m=(0.45, 0.45)),
    FloorLampConfig(name="lamp_southeast", position_m=(6.55, 0.45)),
    FloorLampConfig(name="lamp_west", position_m=(0.45, 3.2)),
)
DEFAULT_BANKS = (
    LightBankConfig(
        name="overhead_south",
        panels_m=((2.0, 1.8), (3.5, 1.8), (5.0, 1.8)),
        mean_on_s=45.0,
        mean_off_s=45.0,
    ),
    LightBankConfig(
        name="overhead_north",
        panels_m=((2.0, 4.3), (3.5, 4.3), (5.0, 4.3)),
        mean_on_s=45.0,
        mean_off_s=45.0,
    ),
)


@dataclass(frozen=True, kw_only=True)
class LightingConfig(Described):
    """Description of the lighting family (``scenes/lighting.toml``)."""

    fps: float = spec(30.0, unit="1/s", range=(1.0, 1000.0), doc="frame rate")
    room: RoomConfig = spec(
        default_factory=lambda: RoomConfig(size_m=(7.0, 6.0, 2.8)), doc="room size and albedos"
    )
    window: WindowConfig | None = spec(None, doc="optional window (daylight); none by default")
    daylight: DaylightConfig = spec(default_factory=DaylightConfig, doc="used with a window")
    daylight_update_s: float = spec(1.0, unit="s", range=(0.001, 1e6), doc="sky update period")
    door: DoorConfig = spec(
        default_factory=lambda: DoorConfig(wall=Wall.WEST, center_m=5.0), doc="hinged door"
    )
    furniture: tuple[FurnitureConfig, ...] = spec(DEFAULT_FURNITURE, doc="sofa, table, ...")
    floor_lamps: tuple[FloorLampConfig, ...] = spec(DEFAULT_LAMPS, doc="switched floor lamps")
    ceiling_lights: tuple[LightBankConfig, ...] = spec(DEFAULT_BANKS, doc="switched banks")
    people: PeopleConfig = spec(default_factory=PeopleConfig, doc="looks and behaviour")
    max_people: int = spec(5, range=(0, 64), doc="people at most in the scene at once")
    arrivals_per_min: float = spec(1.2, unit="1/min", range=(0.0, 600.0), doc="Poisson rate")
    burn_in_s: float = spec(300.0, unit="s", range=(0.0, 1e5), doc="simulated before frame 0")
    max_depth: int = spec(3, range=(2, 64), doc="path depth: 2 = direct light, 3 = +1 bounce")
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(3.5, 0.12, 2.5), look_at=(3.5, 3.2, 0.0), up=(0.0, 0.0, 1.0), detectors=8
        ),
        doc="camera high on the south wall, looking down into the room",
    )

    def __post_init__(self) -> None:
        check_room_layout(self)
        r = self.room
        names = [b.name for b in self.ceiling_lights] + [lp.name for lp in self.floor_lamps]
        if len(set(names)) != len(names):
            raise ValueError(f"light names must be unique, got {names}")
        if not names:
            raise ValueError("floor_lamps, ceiling_lights: need at least one light")
        cam = self.camera.camera()
        for i, lamp in enumerate(self.floor_lamps):
            check_inside(f"floor_lamps[{i}].position_m", r, lamp.position_m, lamp.shade_radius_m)
            if lamp.shade_center_height_m + lamp.shade_height_m / 2 > r.size_m[2]:
                raise ValueError(f"floor_lamps[{i}]: shade above the ceiling")
            if points_in_view(cam, lamp_surface_points(lamp)).any():
                raise ValueError(
                    f"floor_lamps[{i}] ({lamp.name!r} at {list(lamp.position_m)}): the lamp is in "
                    "the "
                    "camera's view; lights must be seen only through their shading"
                )
        for i, bank in enumerate(self.ceiling_lights):
            if points_in_view(cam, panel_points(r, bank)).any():
                raise ValueError(
                    f"ceiling_lights[{i}] ({bank.name!r}): a panel is in the camera's view"
                )


def panel_points(room: RoomConfig, bank: LightBankConfig, n: int = 5) -> np.ndarray:
    """Grid points on a bank's panels (for view checks), shape (N, 3)."""
    z = room.size_m[2] - 0.01
    u = np.linspace(-0.5, 0.5, n)
    pts = []
    for x, y in bank.panels_m:
        gx, gy = np.meshgrid(x + u * bank.panel_size_m[0], y + u * bank.panel_size_m[1])
        pts.append(np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)], -1))
    return np.concatenate(pts)


class LightingFamily(IndoorFamily):
    """Estimating which of five lights are on from shading (paper Sec. 7.2)."""

    name = "lighting"
    config_type = LightingConfig
    # A frame with one floor lamp on is ~10x dimmer than one with both banks on,
    # and a frame with every light off (no window) is dark. Relative to each
    # probe frame, whichever three states the probes happen to hit set the plan:
    # 15 spp at one episode length, 783 spp at another (Monte Carlo error 0.03
    # vs 0.10 at 4 spp). Relative to the mean over the probes, a dim frame
    # counts by its absolute error, which is what separates light states.
    total_error_scale = ErrorScale.MEAN
    planning_error_scale = ErrorScale.MEAN
    # the lights are the labels: each light's own light is the signal
    label_signal = SignalSource.LIGHTS

    @property
    def floor_lamps(self) -> tuple:
        return self.config.floor_lamps

    @property
    def light_names(self) -> tuple[str, ...]:
        return tuple(li.name for li in self.rig.lights)

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        return (
            LabelSpec(
                name="lights",
                kind=LabelKind.BINARY,
                size=len(self.rig.lights),
                element_names=self.light_names,
                median_filter_s=0.5,
            ),
        )

    def labels_for(self, state: IndoorState) -> dict[str, np.ndarray]:
        """Labels of any state (e.g. one set by hand in a test)."""
        return {"lights": np.array(state.lights_on, dtype=np.float32)}

    def frame_state(self, index: int) -> JsonObject:
        st = self.state(index)
        return {
            "time_s": self.time_s(index),
            "people": [
                {
                    "x_m": p.x,
                    "y_m": p.y,
                    "heading_rad": p.heading_rad,
                    "sit": p.sit,
                    "height_m": a.height_m,
                }
                for a, p in st.people
            ],
            "door_angle_deg": math.degrees(st.door_angle_rad),
            "lights_on": dict(zip(self.light_names, st.lights_on, strict=True)),
        }
