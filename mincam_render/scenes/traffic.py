"""Traffic monitoring (paper Sec. 7.3): mean speed of vehicles moving left and right.

A straight street along world +x (metres, +z up, +y north) with
``lanes_per_direction`` lanes each way (right-hand traffic: +x lanes at y < 0),
a painted median, raised sidewalks and rows of buildings, seen from a camera
mounted a few metres up on a pole or building facade looking down at the road.
Daylight follows the sun over the day (:mod:`.sky`: the sun as a directional
light, a CIE sky as an environment map), recomputed every ``daylight_update_s``
seconds of sequence time.

Vehicle trajectories come from Eclipse SUMO (:mod:`.sumo`), simulated once in
the constructor (seeded) and interpolated to the frame times. Vehicles are
low-poly trimesh-style meshes (body boxes in the vehicle's colour, dark glass
band and wheels) of six shapes; each vehicle gets its own size jitter and body
albedo. The scene holds a fixed pool of ``max_vehicles`` vehicle slots (two
meshes each); per frame the vehicles nearest the camera fill the slots and the
rest are collapsed to a point below the ground.

Labels (from the state, never by hand): among vehicles whose footprint-centre
(at half height) projects inside the board's field of view and lies in front
of it, the mean speed (mph) of those *travelling* left / right as seen from the
camera (stopped vehicles count with speed 0; 0 when there are none) and their
counts. The paper median-filters the speeds over 2 s at evaluation, then sets
predicted speeds to 0 where the true speed is below 3 mph; the task's headline
is the speed RMSE pooled over both directions (``LabelSpec.headline``).
"""

from __future__ import annotations

import enum
import functools
import logging
import math
import re
from dataclasses import dataclass

import mitsuba as mi
import numpy as np

from mincam_render.core.config import Described, check_min_max, spec
from mincam_render.core.labels import LabelKind, LabelSpec
from mincam_render.core.photometry import irradiance_to_lux
from mincam_render.core.seeds import stream_seed
from mincam_render.core.strict_json import JsonObject
from mincam_render.optics.camera import FreeformCamera
from mincam_render.render import mitsuba_scene as ms
from mincam_render.render.capabilities import Preview, TemporalLabels, View
from mincam_render.render.fidelity.signal import SignalSource
from mincam_render.render.precision import ErrorScale
from mincam_render.scenes import sky
from mincam_render.scenes.base import CameraMount, SceneFamily
from mincam_render.scenes.sumo import (
    EASTBOUND,
    SumoRoad,
    SumoVehicleType,
    Trajectories,
    require_sumo,
    simulate,
)

log = logging.getLogger(__name__)

#: 1 m/s in miles per hour (1 mile = 1609.344 m).
MPH_PER_M_S = 3600.0 / 1609.344
#: The paper's evaluation sets predicted speeds to 0 where the true speed is below
#: this (supplement, "Traffic Monitoring": its detector's labels were unreliable at
#: the edge of the view). Our labels are exact, so the rule only makes the figures
#: comparable with the paper's; metrics also give the RMSE without it.
ZERO_BELOW_TRUE_MPH = 3.0

_SUN_KEY = "sun"
_SKY_KEY = "sky"
#: Per-frame parameters, checked against mi.traverse when the scene is built.
SUN_DIRECTION_PARAM = f"{_SUN_KEY}.to_world"
SUN_IRRADIANCE_PARAM = f"{_SUN_KEY}.irradiance.value"
SKY_RADIANCE_PARAM = f"{_SKY_KEY}.data"


def vehicle_body_key(slot: int) -> str:
    """Scene key of the body mesh (vehicle colour) of pool slot ``slot``."""
    return f"vehicle{slot:03d}_body"


def vehicle_trim_key(slot: int) -> str:
    """Scene key of the trim mesh (glass band and wheels) of pool slot ``slot``."""
    return f"vehicle{slot:03d}_trim"


def vertex_param(key: str) -> str:
    """Per-frame vertex positions parameter of mesh ``key``."""
    return f"{key}.vertex_positions"


def albedo_param(key: str) -> str:
    """Per-frame diffuse albedo parameter of mesh ``key``."""
    return f"{key}.bsdf.reflectance.value"


#: Where unused pool slots are collapsed to (a point well below the ground, m).
PARKED_POINT_M = (0.0, 0.0, -100.0)
#: Albedos of the vehicle trim: tinted glass seen from outside and tyres.
TRIM_ALBEDO = 0.05


class VehicleShape(enum.Enum):
    """Body layouts of the vehicle meshes."""

    SEDAN = "sedan"
    HATCHBACK = "hatchback"
    SUV = "suv"
    VAN = "van"
    TRUCK = "truck"  # box truck: cab + cargo box
    BUS = "bus"


#: SUMO vehicle class of each shape (affects SUMO's defaults and lane permissions).
_SUMO_CLASS = {
    VehicleShape.SEDAN: "passenger",
    VehicleShape.HATCHBACK: "passenger",
    VehicleShape.SUV: "passenger",
    VehicleShape.VAN: "delivery",
    VehicleShape.TRUCK: "truck",
    VehicleShape.BUS: "bus",
}


@dataclass(frozen=True, kw_only=True)
class VehicleType(Described):
    """A vehicle type: its shape, size, share of the demand and driving behaviour (SUMO vType)."""

    name: str = spec(doc="identifier (letters, digits, _ and -)")
    shape: VehicleShape = spec(doc="mesh layout: sedan, hatchback, suv, van, truck, bus")
    share: float = spec(1.0, range=(0.0, 1e6), doc="relative share of the demand")
    length_m: float = spec(4.6, unit="m", range=(2.0, 25.0), doc="bumper to bumper")
    width_m: float = spec(1.8, unit="m", range=(1.0, 3.0), doc="body width")
    height_m: float = spec(1.45, unit="m", range=(1.0, 4.5), doc="ground to roof")
    max_speed_m_s: float = spec(50.0, unit="m/s", range=(1.0, 70.0), doc="vehicle top speed")
    speed_factor: tuple[float, float] = spec(
        (1.0, 0.1),
        range=(0.0, 2.0),
        doc="mean, std of desired speed / speed limit (normal clipped to [0.2, 2])",
    )
    accel_m_s2: float = spec(2.6, unit="m/s^2", range=(0.1, 10.0), doc="max acceleration")
    decel_m_s2: float = spec(4.5, unit="m/s^2", range=(0.1, 10.0), doc="comfortable deceleration")
    sigma: float = spec(0.5, range=(0.0, 1.0), doc="Krauss driver imperfection")
    min_gap_m: float = spec(2.5, unit="m", range=(0.1, 20.0), doc="standstill gap to the leader")

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", self.name):
            raise ValueError(
                f"name = {self.name!r}: allowed letters, digits, _ and -, starting with a letter"
            )
        if self.speed_factor[0] <= 0.0:
            raise ValueError(f"speed_factor = {list(self.speed_factor)}: mean must be > 0")

    def sumo(self) -> SumoVehicleType:
        """The SUMO vType of this vehicle type."""
        return SumoVehicleType(
            name=self.name,
            vclass=_SUMO_CLASS[self.shape],
            share=self.share,
            length_m=self.length_m,
            width_m=self.width_m,
            height_m=self.height_m,
            max_speed_m_s=self.max_speed_m_s,
            speed_factor_mean=self.speed_factor[0],
            speed_factor_dev=self.speed_factor[1],
            accel_m_s2=self.accel_m_s2,
            decel_m_s2=self.decel_m_s2,
            sigma=self.sigma,
            min_gap_m=self.min_gap_m,
        )


def _default_vehicle_types() -> tuple[VehicleType, ...]:
    # Sizes of common US models; shares of a typical urban mix; SUMO's defaults
    # for trucks and buses (slower, weaker acceleration, larger gaps).
    return (
        VehicleType(
            name="sedan",
            shape=VehicleShape.SEDAN,
            share=0.40,
            length_m=4.8,
            width_m=1.85,
            height_m=1.45,
        ),
        VehicleType(
            name="hatchback",
            shape=VehicleShape.HATCHBACK,
            share=0.15,
            length_m=4.2,
            width_m=1.78,
            height_m=1.50,
        ),
        VehicleType(
            name="suv",
            shape=VehicleShape.SUV,
            share=0.28,
            length_m=4.9,
            width_m=1.95,
            height_m=1.75,
        ),
        VehicleType(
            name="van",
            shape=VehicleShape.VAN,
            share=0.08,
            length_m=5.9,
            width_m=2.0,
            height_m=2.4,
            max_speed_m_s=40.0,
            accel_m_s2=2.0,
            decel_m_s2=4.0,
        ),
        VehicleType(
            name="truck",
            shape=VehicleShape.TRUCK,
            share=0.06,
            length_m=8.0,
            width_m=2.5,
            height_m=3.4,
            max_speed_m_s=25.0,
            speed_factor=(0.95, 0.05),
            accel_m_s2=1.3,
            decel_m_s2=4.0,
            min_gap_m=3.0,
        ),
        VehicleType(
            name="bus",
            shape=VehicleShape.BUS,
            share=0.03,
            length_m=12.0,
            width_m=2.55,
            height_m=3.1,
            max_speed_m_s=25.0,
            speed_factor=(0.9, 0.05),
            accel_m_s2=1.2,
            decel_m_s2=4.0,
            min_gap_m=3.0,
        ),
    )


@dataclass(frozen=True, kw_only=True)
class TrafficConfig(Described):
    """Description of the traffic family (``scenes/traffic.toml``)."""

    fps: float = spec(30.0, unit="1/s", range=(1.0, 1000.0), doc="frame rate")
    # --- road ------------------------------------------------------------------
    lanes_per_direction: int = spec(2, range=(1, 4), doc="lanes each way")
    lane_width_m: float = spec(3.5, unit="m", range=(2.5, 5.0), doc="lane width")
    median_width_m: float = spec(1.0, unit="m", range=(0.0, 10.0), doc="painted median")
    shoulder_width_m: float = spec(
        0.5, unit="m", range=(0.0, 5.0), doc="asphalt beside the outer lane"
    )
    sidewalk_width_m: float = spec(3.0, unit="m", range=(0.0, 20.0), doc="each side")
    curb_height_m: float = spec(0.15, unit="m", range=(0.0, 0.5), doc="sidewalk above the road")
    road_length_m: float = spec(600.0, unit="m", range=(100.0, 5000.0), doc="simulated road length")
    scenery_half_length_m: float = spec(
        150.0,
        unit="m",
        range=(20.0, 2500.0),
        doc="road, sidewalks and buildings drawn to |x| <= this",
    )
    buildings: bool = spec(True, doc="rows of buildings behind the sidewalks")
    building_setback_m: float = spec(
        0.0, unit="m", range=(0.0, 50.0), doc="sidewalk edge to facades"
    )
    building_height_m: tuple[float, float] = spec(
        (6.0, 20.0), unit="m", range=(2.0, 200.0), doc="min, max"
    )
    building_width_m: tuple[float, float] = spec(
        (8.0, 25.0), unit="m", range=(2.0, 200.0), doc="min, max"
    )
    # --- albedos (monochrome, visible band) ----------------------------------
    asphalt_albedo: float = spec(0.12, range=(0.0, 1.0), doc="aged asphalt")
    marking_albedo: float = spec(0.55, range=(0.0, 1.0), doc="white lane lines")
    centre_line_albedo: float = spec(0.35, range=(0.0, 1.0), doc="yellow centre lines")
    sidewalk_albedo: float = spec(0.30, range=(0.0, 1.0), doc="concrete")
    ground_albedo: float = spec(0.18, range=(0.0, 1.0), doc="everything beyond")
    building_albedo: tuple[float, float] = spec((0.2, 0.45), range=(0.0, 1.0), doc="min, max")
    body_albedos: tuple[float, ...] = spec(
        (0.75, 0.04, 0.20, 0.50, 0.08, 0.12, 0.30), range=(0.0, 1.0), doc="vehicle paint palette"
    )
    body_albedo_weights: tuple[float, ...] = spec(
        (0.25, 0.22, 0.18, 0.15, 0.09, 0.09, 0.02),
        range=(0.0, 1.0),
        doc="probability of each paint",
    )
    # --- traffic (SUMO) -----------------------------------------------------
    speed_limit_m_s: float = spec(15.6, unit="m/s", range=(1.0, 40.0), doc="35 mph")
    demand_veh_per_h: tuple[float, float] = spec(
        (600.0, 600.0), unit="veh/h", range=(0.0, 5000.0), doc="Poisson arrivals (+x, -x)"
    )
    vehicle_types: tuple[VehicleType, ...] = spec(default_factory=_default_vehicle_types, doc="mix")
    signal_cycle_s: float = spec(90.0, unit="s", range=(0.0, 600.0), doc="0 = no signals")
    signal_green_fraction: float = spec(0.55, range=(0.05, 0.95), doc="green share of a cycle")
    signal_distance_m: float = spec(
        80.0, unit="m", range=(10.0, 2000.0), doc="camera to each stop line"
    )
    warmup_s: float = spec(120.0, unit="s", range=(0.0, 3600.0), doc="simulated before frame 0")
    sumo_step_s: float = spec(0.1, unit="s", range=(0.01, 1.0), doc="SUMO step; frames interpolate")
    # --- rendering ----------------------------------------------------------
    render_half_length_m: float = spec(
        60.0, unit="m", range=(5.0, 1000.0), doc="vehicles drawn to |x| <= this"
    )
    max_vehicles: int = spec(48, range=(1, 1000), doc="vehicle pool size (nearest drawn)")
    daylight: sky.DaylightConfig = spec(
        default_factory=lambda: sky.DaylightConfig(start_hour=9.0, hours_per_second=1.0 / 3600.0),
        doc="site, date, time of day, time-lapse, overcast",
    )
    daylight_update_s: float = spec(1.0, unit="s", range=(0.0, 3600.0), doc="0 = every frame")
    max_depth: int = spec(3, range=(1, 16), doc="path depth (2 = direct light only)")
    camera: CameraMount = spec(
        default_factory=lambda: CameraMount(
            position=(0.0, -10.8, 6.0), look_at=(0.0, 1.0, 0.0), up=(0.0, 0.0, 1.0), detectors=8
        ),
        doc="on the near facade, 6 m up, looking down at the street",
    )

    @property
    def road_half_width_m(self) -> float:
        """Centre line to curb (m)."""
        return (
            0.5 * self.median_width_m
            + self.lanes_per_direction * self.lane_width_m
            + self.shoulder_width_m
        )

    @property
    def facade_y_m(self) -> float:
        """Centre line to the building facades (m)."""
        return self.road_half_width_m + self.sidewalk_width_m + self.building_setback_m

    def __post_init__(self) -> None:
        check_min_max(self, "building_height_m", "building_width_m", "building_albedo")
        if len(self.body_albedos) == 0 or len(self.body_albedos) != len(self.body_albedo_weights):
            raise ValueError(
                f"body_albedo_weights has {len(self.body_albedo_weights)} values: needs one per "
                f"body_albedos entry ({len(self.body_albedos)}, at least 1)"
            )
        if sum(self.body_albedo_weights) <= 0:
            raise ValueError("body_albedo_weights: at least one weight must be > 0")
        if not self.vehicle_types or sum(t.share for t in self.vehicle_types) <= 0:
            raise ValueError("vehicle_types: needs at least one type with share > 0")
        names = [t.name for t in self.vehicle_types]
        if len(set(names)) != len(names):
            raise ValueError(f"vehicle_types: names must be unique, got {names}")
        half = 0.5 * self.road_length_m
        if self.signal_cycle_s > 0:
            if self.signal_distance_m > half - 20.0:
                raise ValueError(
                    f"signal_distance_m = {self.signal_distance_m} m: must be at most "
                    f"road_length_m / 2 - 20 = {half - 20.0:g} m"
                )
            if self.signal_cycle_s * (1 - self.signal_green_fraction) < 4.0:
                raise ValueError(
                    f"signal_cycle_s = {self.signal_cycle_s} s: yellow (3 s) + red need "
                    "at least 4 s "
                    "of the cycle; lengthen it or lower signal_green_fraction"
                )
        if self.render_half_length_m > half:
            raise ValueError(
                f"render_half_length_m = {self.render_half_length_m} m: at most "
                f"road_length_m / 2 = {half:g} m"
            )
        if self.scenery_half_length_m < self.render_half_length_m:
            raise ValueError(
                f"scenery_half_length_m = {self.scenery_half_length_m} m: at least "
                f"render_half_length_m = {self.render_half_length_m} m"
            )
        x, y, z = self.camera.position
        if abs(y) <= self.road_half_width_m or z < 2.0:
            raise ValueError(
                f"camera.position = {[x, y, z]} m: mount it beside the road (|y| > "
                f"{self.road_half_width_m:g} m) and at least 2 m up (z >= 2)"
            )
        if self.buildings and abs(y) > self.facade_y_m:
            raise ValueError(
                f"camera.position = {[x, y, z]} m: inside a building (facades at |y| = "
                f"{self.facade_y_m:g} m); move it toward the road or set buildings = false"
            )
        if self.camera.look_at[2] >= z:
            raise ValueError(
                f"camera.look_at = {list(self.camera.look_at)} m: "
                f"must be below the camera (z < {z:g})"
            )

    def sumo_road(self) -> SumoRoad:
        """The SUMO description of this street."""
        return SumoRoad(
            length_m=self.road_length_m,
            lanes=self.lanes_per_direction,
            lane_width_m=self.lane_width_m,
            median_width_m=self.median_width_m,
            speed_limit_m_s=self.speed_limit_m_s,
            demand_veh_per_h=self.demand_veh_per_h,
            vehicle_types=tuple(t.sumo() for t in self.vehicle_types),
            signal_distance_m=self.signal_distance_m,
            signal_cycle_s=self.signal_cycle_s,
            signal_green_fraction=self.signal_green_fraction,
        )


# ---- labels ----------------------------------------------------------------------


def in_view(camera: FreeformCamera, points_m: np.ndarray) -> np.ndarray:
    """Which world points lie in front of the board and inside its field of view.

    The view is the pyramid from the board centre through the mask edges
    (``camera.fov_deg`` across, square).

    Args:
        camera: the camera (its pose and mask geometry).
        points_m: ``(N, 3)`` world points (m).

    Returns:
        ``(N,)`` bool.
    """
    right, up, fwd = camera.frame
    rel = np.asarray(points_m, dtype=np.float64).reshape(-1, 3) - np.asarray(camera.position)
    depth = rel @ fwd
    tan_half = 0.5 * camera.mask_size_m / camera.mask_distance_m
    return (
        (depth > 0)
        & (np.abs(rel @ right) <= tan_half * depth)
        & (np.abs(rel @ up) <= tan_half * depth)
    )


def traffic_labels(
    camera: FreeformCamera, center_m: np.ndarray, yaw_rad: np.ndarray, speed_m_s: np.ndarray
) -> dict[str, np.ndarray]:
    """Labels of one frame from an explicit vehicle state.

    Args:
        camera: the camera defining "in view" and "left/right".
        center_m: ``(N, 3)`` vehicle centres (m, world).
        yaw_rad: ``(N,)`` headings, counter-clockwise from world +x (rad).
        speed_m_s: ``(N,)`` speeds (m/s, >= 0).

    Returns:
        ``speed_left_mph``, ``speed_right_mph`` (mean speed of in-view vehicles
        travelling left / right in the camera's view, 0 when none) and
        ``count_left``, ``count_right``; each a float32 array of shape (1,).
    """
    center_m = np.asarray(center_m, dtype=np.float64).reshape(-1, 3)
    yaw = np.asarray(yaw_rad, dtype=np.float64).reshape(-1)
    speed = np.asarray(speed_m_s, dtype=np.float64).reshape(-1)
    seen = in_view(camera, center_m)
    right = camera.frame[0]
    # direction of travel, not of velocity: a vehicle stopped in a queue counts at 0 mph
    goes_right = np.cos(yaw) * right[0] + np.sin(yaw) * right[1] > 0
    out = {}
    sides = (("left", seen & ~goes_right), ("right", seen & goes_right))
    for side, mask in sides:
        n = int(mask.sum())
        mean = float(speed[mask].mean()) * MPH_PER_M_S if n else 0.0
        out[f"speed_{side}_mph"] = np.array([mean], dtype=np.float32)
    for side, mask in sides:
        out[f"count_{side}"] = np.array([int(mask.sum())], dtype=np.float32)
    return out


# ---- vehicle meshes --------------------------------------------------------------


@dataclass(frozen=True)
class _BoxLayout:
    """A vehicle shape's boxes in units of its (L, W, H): see :data:`_LAYOUTS`."""

    body: tuple[tuple[float, float, float, float, float], ...]
    glass: tuple[float, float, float, float, float]
    axles: tuple[float, float]
    wheel_r: float


# Box layouts in units of (L, W, H), vehicle frame: x forward from the centre,
# y left, z up from the ground. Each: (x0, x1, half-width fraction, z0, z1).
# Three body boxes (a zero box where a shape needs fewer), a glass band
# wrapped around one of them, and the wheels: (axle x fractions, radius m).
_Z = (0.0, 0.0, 0.0, 0.0, 0.0)
_LAYOUTS: dict[VehicleShape, _BoxLayout] = {
    VehicleShape.SEDAN: _BoxLayout(
        body=((-0.5, 0.5, 0.5, 0.16, 0.60), (-0.30, 0.18, 0.45, 0.60, 1.0), _Z),
        glass=(-0.30, 0.18, 0.45, 0.64, 0.93),
        axles=(-0.31, 0.31), wheel_r=0.32,
    ),
    VehicleShape.HATCHBACK: _BoxLayout(
        body=((-0.5, 0.5, 0.5, 0.16, 0.58), (-0.48, 0.15, 0.45, 0.58, 1.0), _Z),
        glass=(-0.48, 0.15, 0.45, 0.62, 0.93),
        axles=(-0.32, 0.32), wheel_r=0.31,
    ),
    VehicleShape.SUV: _BoxLayout(
        body=((-0.5, 0.5, 0.5, 0.17, 0.58), (-0.47, 0.20, 0.46, 0.58, 1.0), _Z),
        glass=(-0.47, 0.20, 0.46, 0.62, 0.93),
        axles=(-0.30, 0.31), wheel_r=0.37,
    ),
    VehicleShape.VAN: _BoxLayout(
        body=((-0.5, 0.5, 0.5, 0.13, 0.45), (-0.5, 0.32, 0.48, 0.45, 1.0), _Z),
        glass=(0.12, 0.32, 0.48, 0.52, 0.85),
        axles=(-0.33, 0.30), wheel_r=0.36,
    ),
    VehicleShape.TRUCK: _BoxLayout(
        body=(
            (-0.5, 0.5, 0.45, 0.12, 0.26),  # chassis
            (0.30, 0.5, 0.48, 0.14, 0.72),  # cab
            (-0.5, 0.28, 0.5, 0.26, 1.0),  # cargo box
        ),
        glass=(0.30, 0.5, 0.48, 0.46, 0.68),
        axles=(-0.30, 0.38), wheel_r=0.50,
    ),
    VehicleShape.BUS: _BoxLayout(
        body=((-0.5, 0.5, 0.5, 0.10, 0.36), (-0.5, 0.5, 0.5, 0.36, 1.0), _Z),
        glass=(-0.48, 0.5, 0.5, 0.42, 0.85),
        axles=(-0.28, 0.30), wheel_r=0.50,
    ),
}  # fmt: skip
#: The glass band stands this far proud of its box (m), so it covers the sides.
_GLASS_PROUD_M = 0.02
_WHEEL_WIDTH_M = 0.22
_WHEEL_SECTIONS = 10


@functools.cache
def _unit_parts() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unit box (+-0.5) and unit wheel (radius 1, width 1, axis y) from trimesh."""
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    cyl = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=_WHEEL_SECTIONS)
    # rotate the cylinder's axis from z to y (a proper rotation keeps faces outward)
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return (
        np.asarray(box.vertices, dtype=np.float64),
        np.asarray(box.faces, dtype=np.int64),
        np.asarray(cyl.vertices, dtype=np.float64) @ rot.T,
        np.asarray(cyl.faces, dtype=np.int64),
    )


def _concat_faces(parts: list[tuple[int, np.ndarray]]) -> np.ndarray:
    out, base = [], 0
    for nv, faces in parts:
        out.append(faces + base)
        base += nv
    return np.concatenate(out).astype(np.uint32)


@functools.cache
def vehicle_faces() -> tuple[np.ndarray, np.ndarray]:
    """Face arrays ``(F, 3)`` of the body and trim meshes (the same for every shape)."""
    bv, bf, cv, cf = _unit_parts()
    body = _concat_faces([(len(bv), bf)] * 3)
    trim = _concat_faces([(len(bv), bf)] + [(len(cv), cf)] * 4)
    return body, trim


def vehicle_vertices(
    shape: VehicleShape, length_m: float, width_m: float, height_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Body and trim vertices ``(V, 3)`` of a vehicle in its own frame (m).

    Vehicle frame: x forward from the footprint centre, y left, z up from the
    ground. Faces are :func:`vehicle_faces`.
    """
    bv, _, cv, _ = _unit_parts()
    lay = _LAYOUTS[shape]
    L, W, H = length_m, width_m, height_m

    def box(
        x0: float, x1: float, hw: float, z0: float, z1: float, proud: float = 0.0
    ) -> np.ndarray:
        centre = np.array([(x0 + x1) / 2 * L, 0.0, (z0 + z1) / 2 * H])
        ext = np.array([(x1 - x0) * L + 2 * proud, 2 * hw * W + 2 * proud, (z1 - z0) * H])
        if ext[0] <= 2 * proud:  # a zero box stays zero
            ext = np.zeros(3)
        return centre + bv * ext

    body = np.concatenate([box(*b) for b in lay.body])
    r = lay.wheel_r
    wheels = []
    for ax in lay.axles:
        for side in (-1.0, 1.0):
            c = np.array([ax * L, side * (W / 2 - _WHEEL_WIDTH_M / 2 - 0.01), r])
            wheels.append(c + cv * np.array([r, _WHEEL_WIDTH_M, r]))
    x0, x1, hw, z0, z1 = lay.glass
    trim = np.concatenate([box(x0, x1, hw, z0, z1, proud=_GLASS_PROUD_M), *wheels])
    return body, trim


def _place(vertices: np.ndarray, center_xy: np.ndarray, yaw: float, z0: float = 0.0) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty_like(vertices)
    out[:, 0] = c * vertices[:, 0] - s * vertices[:, 1] + center_xy[0]
    out[:, 1] = s * vertices[:, 0] + c * vertices[:, 1] + center_xy[1]
    out[:, 2] = vertices[:, 2] + z0
    return out


def _quads(
    rects: list[tuple[float, float, float, float]], z: float
) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal quads ``(x0, x1, y0, y1)`` at height ``z``, facing up."""
    r = np.asarray(rects, dtype=np.float64).reshape(-1, 4)
    n = len(r)
    v = np.empty((n, 4, 3))
    v[:, 0] = np.stack([r[:, 0], r[:, 2], np.full(n, z)], 1)
    v[:, 1] = np.stack([r[:, 1], r[:, 2], np.full(n, z)], 1)
    v[:, 2] = np.stack([r[:, 1], r[:, 3], np.full(n, z)], 1)
    v[:, 3] = np.stack([r[:, 0], r[:, 3], np.full(n, z)], 1)
    base = 4 * np.arange(n)[:, None]
    f = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]])
    return v.reshape(-1, 3), f


def _boxes(boxes: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """One mesh of axis-aligned boxes given as (min corner, max corner)."""
    bv, bf, _, _ = _unit_parts()
    verts = [(lo + hi) / 2 + bv * (hi - lo) for lo, hi in boxes]
    return np.concatenate(verts), _concat_faces([(len(bv), bf)] * len(boxes)).astype(np.int64)


# ---- the family --------------------------------------------------------------------


class TrafficFamily(SceneFamily, TemporalLabels, Preview):
    """Traffic speed monitoring (paper Sec. 7.3): a two-way street with SUMO traffic."""

    name = "traffic"
    config_type = TrafficConfig
    history_frames = 30  # the paper's 1 s of history at 30 fps
    # the speed is read from what changes between frames over that history
    label_signal = SignalSource.FRAME_STEPS
    # Planned on the frame steps: 1 % of the total (35 spp) left noise 1.73
    # times the steps' signal and was rejected by the task check; the design
    # protocol's cameras learn the speed from renders at 4x those samples,
    # whose noise the planner measures at 0.53 of the steps' signal (its pilot's
    # 3.12 at 4 spp, scaled to 140 spp). No level above 4x is checked: the
    # target is 4x's, not the loosest the task accepts (docs/fidelity.md).
    planning_error_scale = ErrorScale.SIGNAL
    signal_target_error = 0.53

    def __init__(self, config: TrafficConfig, *, seed: int, num_frames: int) -> None:
        super().__init__(config, seed=seed, num_frames=num_frames)
        require_sumo()  # fail early, naming the extra
        self._camera = config.camera.camera()
        duration = (num_frames - 1) / config.fps
        self.trajectories: Trajectories = simulate(
            config.sumo_road(),
            seed=seed,
            duration_s=duration,
            warmup_s=config.warmup_s,
            step_s=config.sumo_step_s,
            # margin so vehicles entering the drawn region interpolate between two steps
            record_half_length_m=config.render_half_length_m + 20.0,
        )
        # per-vehicle appearance, a function of (seed, vehicle index) only
        nveh = len(self.trajectories.vehicle_type)
        self._dims = np.empty((nveh, 3))
        self._albedo = np.empty(nveh)
        weights = np.asarray(config.body_albedo_weights, dtype=np.float64)
        weights = weights / weights.sum()
        for i, t in enumerate(self.trajectories.vehicle_type):
            vt = config.vehicle_types[int(t)]
            rng = np.random.default_rng(stream_seed(seed, "traffic/vehicle", i))
            jitter = 1.0 + rng.uniform(-0.04, 0.04, size=3)
            self._dims[i] = np.array([vt.length_m, vt.width_m, vt.height_m]) * jitter
            self._albedo[i] = config.body_albedos[int(rng.choice(len(weights), p=weights))]
        self._warned_pool = False

    # ---- SceneFamily API ---------------------------------------------------------

    @property
    def fps(self) -> float:
        return self.config.fps

    @property
    def labels(self) -> tuple[LabelSpec, ...]:
        return (
            *(
                LabelSpec(
                    name=f"speed_{side}_mph",
                    kind=LabelKind.REGRESSION,
                    unit="mph",
                    zero_below_true=ZERO_BELOW_TRUE_MPH,
                    headline="mean speed",
                )
                for side in ("left", "right")
            ),
            LabelSpec(name="count_left", kind=LabelKind.COUNT),
            LabelSpec(name="count_right", kind=LabelKind.COUNT),
        )

    def camera(self) -> FreeformCamera:
        return self._camera

    def vehicles(self, index: int) -> dict[str, np.ndarray]:
        """Vehicles near the camera at frame ``index`` (numpy).

        Returns:
            ``vehicle (N,)`` index, ``type (N,)`` index into ``vehicle_types``,
            ``center_m (N, 3)`` centre of the bounding box (m), ``yaw_rad (N,)``,
            ``speed_m_s (N,)``, ``dims_m (N, 3)`` length/width/height,
            ``albedo (N,)``; sorted by vehicle index.
        """
        self.check_index(index)
        st = self.trajectories.at(self.time_s(index))
        v = st["vehicle"]
        dims = self._dims[v]
        center = np.concatenate([st["center_m"], dims[:, 2:3] / 2], axis=1)
        return {
            "vehicle": v,
            "type": self.trajectories.vehicle_type[v],
            "center_m": center,
            "yaw_rad": st["yaw_rad"],
            "speed_m_s": st["speed_m_s"].astype(np.float64),
            "dims_m": dims,
            "albedo": self._albedo[v],
        }

    def labels_for_state(
        self, center_m: np.ndarray, yaw_rad: np.ndarray, speed_m_s: np.ndarray
    ) -> dict[str, np.ndarray]:
        """Labels from an explicit vehicle state (see :func:`traffic_labels`)."""
        return traffic_labels(self._camera, center_m, yaw_rad, speed_m_s)

    def frame_labels(self, index: int) -> dict[str, np.ndarray]:
        """Labels of frame ``index`` without touching a scene."""
        veh = self.vehicles(index)
        return self.labels_for_state(veh["center_m"], veh["yaw_rad"], veh["speed_m_s"])

    def daylight_at(self, index: int) -> sky.Daylight:
        """Sun and sky of frame ``index`` (sampled every ``daylight_update_s``)."""
        t = self.time_s(index)
        step = self.config.daylight_update_s
        if step > 0:
            t = math.floor(t / step + 1e-9) * step
        return _daylight(self.config.daylight, round(t, 9))

    def build_scene(self) -> mi.Scene:
        c = self.config
        shapes: dict[str, ms.MitsubaDict | mi.Mesh] = {}
        day = self.daylight_at(0)
        shapes[_SUN_KEY] = ms.directional_light(
            -day.sun_direction, max(day.sun_irradiance_w_m2, 0.0)
        )
        shapes[_SKY_KEY] = ms.environment_map(day.sky_radiance_w_m2_sr, sky.envmap_to_world())
        shapes.update(self._static_shapes())
        body_faces, trim_faces = vehicle_faces()
        parked = np.tile(np.asarray(PARKED_POINT_M), (1, 1))
        nb = int(body_faces.max()) + 1
        nt = int(trim_faces.max()) + 1
        for slot in range(c.max_vehicles):
            shapes[vehicle_body_key(slot)] = ms.mesh(
                vehicle_body_key(slot), np.repeat(parked, nb, 0), body_faces, reflectance=0.5
            )
            shapes[vehicle_trim_key(slot)] = ms.mesh(
                vehicle_trim_key(slot),
                np.repeat(parked, nt, 0),
                trim_faces,
                reflectance=TRIM_ALBEDO,
            )
        scene = ms.load_scene(ms.scene_dict(shapes, max_depth=c.max_depth))
        params = mi.traverse(scene)
        keys = [SUN_DIRECTION_PARAM, SUN_IRRADIANCE_PARAM, SKY_RADIANCE_PARAM]
        for slot in range(c.max_vehicles):
            keys += [vertex_param(vehicle_body_key(slot)), vertex_param(vehicle_trim_key(slot))]
            keys.append(albedo_param(vehicle_body_key(slot)))
        missing = [k for k in keys if k not in params]
        if missing:
            raise RuntimeError(f"scene has no parameter {missing[0]!r}")
        sky_now = np.asarray(params[SKY_RADIANCE_PARAM])
        sky_ours = np.asarray(ms.environment_map_data(day.sky_radiance_w_m2_sr))
        if sky_now.shape != sky_ours.shape or not np.allclose(
            sky_now, sky_ours, rtol=1e-4, atol=1e-6
        ):
            raise RuntimeError(
                f"{SKY_RADIANCE_PARAM!r} layout differs from ms.environment_map_data"
            )
        return scene

    def set_frame(self, scene: mi.Scene, index: int) -> dict[str, np.ndarray]:
        veh = self.vehicles(index)
        params = mi.traverse(scene)
        # nearest to the camera first, so in-view vehicles always get a slot
        cam_x = self._camera.position[0]
        order = np.argsort(np.abs(veh["center_m"][:, 0] - cam_x), kind="stable")
        order = order[np.abs(veh["center_m"][order, 0]) <= self.config.render_half_length_m]
        if len(order) > self.config.max_vehicles and not self._warned_pool:
            log.warning(
                "traffic frame %d: %d vehicles within render_half_length_m, pool holds %d; "
                "the farthest are not drawn (raise max_vehicles)",
                index, len(order), self.config.max_vehicles,
            )  # fmt: skip
            self._warned_pool = True
        order = order[: self.config.max_vehicles]
        body_faces, trim_faces = vehicle_faces()
        nb = int(body_faces.max()) + 1
        nt = int(trim_faces.max()) + 1
        parked_b = np.tile(np.asarray(PARKED_POINT_M, dtype=np.float32), nb)
        parked_t = np.tile(np.asarray(PARKED_POINT_M, dtype=np.float32), nt)
        for slot in range(self.config.max_vehicles):
            bkey, tkey = vehicle_body_key(slot), vehicle_trim_key(slot)
            if slot < len(order):
                j = order[slot]
                shape = self.config.vehicle_types[int(veh["type"][j])].shape
                body, trim = vehicle_vertices(shape, *veh["dims_m"][j])
                xy, yaw = veh["center_m"][j, :2], float(veh["yaw_rad"][j])
                params[vertex_param(bkey)] = mi.Float(
                    _place(body, xy, yaw).astype(np.float32).ravel()
                )
                params[vertex_param(tkey)] = mi.Float(
                    _place(trim, xy, yaw).astype(np.float32).ravel()
                )
                params[albedo_param(bkey)] = float(veh["albedo"][j])
            else:
                params[vertex_param(bkey)] = mi.Float(parked_b)
                params[vertex_param(tkey)] = mi.Float(parked_t)
        day = self.daylight_at(index)
        params[SUN_DIRECTION_PARAM] = ms.directional_light_to_world(-day.sun_direction)
        params[SUN_IRRADIANCE_PARAM] = float(max(day.sun_irradiance_w_m2, 0.0))
        params[SKY_RADIANCE_PARAM] = ms.environment_map_data(day.sky_radiance_w_m2_sr)
        params.update()
        return self.labels_for_state(veh["center_m"], veh["yaw_rad"], veh["speed_m_s"])

    def frame_state(self, index: int) -> JsonObject:
        veh = self.vehicles(index)
        seen = in_view(self._camera, veh["center_m"])
        labels = self.labels_for_state(veh["center_m"], veh["yaw_rad"], veh["speed_m_s"])
        day = self.daylight_at(index)
        dcfg = self.config.daylight
        sid = self.trajectories.sumo_id
        return {
            "time_s": self.time_s(index),
            "solar_hour": (dcfg.start_hour + dcfg.hours_per_second * self.time_s(index)) % 24.0,
            "sun_elevation_deg": math.degrees(
                math.asin(float(np.clip(day.sun_direction[2], -1, 1)))
            ),
            "global_horizontal_lux": irradiance_to_lux(day.global_horizontal_w_m2),
            "labels": {k: float(v[0]) for k, v in labels.items()},
            "vehicles": [
                {
                    "id": sid[int(v)],
                    "type": self.config.vehicle_types[int(veh["type"][j])].name,
                    "center_m": [float(x) for x in veh["center_m"][j]],
                    "yaw_rad": float(veh["yaw_rad"][j]),
                    "speed_m_s": float(veh["speed_m_s"][j]),
                    "direction": "+x" if self.trajectories.direction[int(v)] == EASTBOUND else "-x",
                    "in_view": bool(seen[j]),
                }
                for j, v in enumerate(veh["vehicle"])
            ],
        }

    def birdseye_view(self) -> View:
        c = self.config
        span = 2.0 * c.facade_y_m + 10.0
        height = span / (2.0 * math.tan(math.radians(30.0)))
        return View((0.0, 0.0, height), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 60.0)

    # ---- static scenery ----------------------------------------------------------

    def _static_shapes(self) -> dict[str, ms.MitsubaDict | mi.Mesh]:
        c = self.config
        hx = c.scenery_half_length_m
        hw = c.road_half_width_m
        out: dict[str, ms.MitsubaDict | mi.Mesh] = {
            "ground": ms.rectangle(
                (0.0, 0.0, -0.02), (0.0, 0.0, 1.0), (4 * hx, 4 * hx), ms.diffuse(c.ground_albedo)
            ),
            "road": ms.rectangle(
                (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (2 * hx, 2 * hw), ms.diffuse(c.asphalt_albedo)
            ),
        }
        # markings: white dashed lane lines (3 m dash, 9 m gap, US), solid edge
        # lines, double yellow centre line
        lines, centre = [], []
        m = 0.5 * c.median_width_m
        z = 0.004
        for sgn in (-1.0, 1.0):
            for k in range(1, c.lanes_per_direction):
                y = sgn * (m + k * c.lane_width_m)
                for x0 in np.arange(-hx, hx, 12.0):
                    lines.append((x0, x0 + 3.0, y - 0.06, y + 0.06))
            y_edge = sgn * (m + c.lanes_per_direction * c.lane_width_m)
            lines.append((-hx, hx, y_edge - 0.075, y_edge + 0.075))
            y_c = sgn * max(m - 0.1, 0.1)
            centre.append((-hx, hx, y_c - 0.05, y_c + 0.05))
        v, f = _quads(lines, z)
        out["markings"] = ms.mesh("markings", v, f, reflectance=c.marking_albedo)
        v, f = _quads(centre, z)
        out["centre_line"] = ms.mesh("centre_line", v, f, reflectance=c.centre_line_albedo)
        if c.sidewalk_width_m > 0:
            walks = [
                (
                    np.array([-hx, -hw - c.sidewalk_width_m, -0.02]),
                    np.array([hx, -hw, c.curb_height_m]),
                ),
                (
                    np.array([-hx, hw, -0.02]),
                    np.array([hx, hw + c.sidewalk_width_m, c.curb_height_m]),
                ),
            ]
            v, f = _boxes(walks)
            out["sidewalks"] = ms.mesh("sidewalks", v, f, reflectance=c.sidewalk_albedo)
        if c.buildings:
            rng = np.random.default_rng(stream_seed(self.seed, "traffic/buildings"))
            for side, sgn in (("south", -1.0), ("north", 1.0)):
                x, k = -hx, 0
                while x < hx:
                    w = rng.uniform(*c.building_width_m)
                    h = rng.uniform(*c.building_height_m)
                    a = rng.uniform(*c.building_albedo)
                    y0 = c.facade_y_m
                    lo = np.array([x, y0 if sgn > 0 else -y0 - 15.0, -0.02])
                    hi = np.array([min(x + w, hx), y0 + 15.0 if sgn > 0 else -y0, h])
                    v, f = _boxes([(lo, hi)])
                    key = f"building_{side}_{k:02d}"
                    out[key] = ms.mesh(key, v, f, reflectance=a)
                    x += w + rng.uniform(0.0, 3.0)  # alleys between some buildings
                    k += 1
        return out


@functools.lru_cache(maxsize=64)
def _daylight(config: sky.DaylightConfig, time_s: float) -> sky.Daylight:
    return sky.daylight(config, time_s)
