"""The panel's light over a day, rendered in the scene's own light.

The panel is a flat Mitsuba ``irradiancemeter`` beside the camera board (below
its centre, facing the board's normal unless tilted). Irradiance is linear in the
emitters, so each switchable light is rendered once alone (at night, nobody in
the room, the door closed) and the daylight (sun and sky through the window, all
lights off) once per sample of the day; any schedule of the lights is then a sum
(:func:`day_irradiance`), like the families' background components.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from mincam_render.core.config import ConfigError
from mincam_render.core.strict_json import JsonObject
from mincam_render.studies.energy.config import EnergyConfig, PanelConfig, ScheduleConfig

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from mincam_render.render.irradiance import IrradianceEstimate
    from mincam_render.render.mitsuba_scene import MitsubaDict
    from mincam_render.scenes.indoor import IndoorFamily

log = logging.getLogger(__name__)
SECONDS_PER_HOUR = 3600.0
#: The sky model (scenes/sky.py) fades to dark at 6 deg below the horizon.
TWILIGHT_DEG = -6.0


@dataclass(frozen=True, kw_only=True)
class PanelPose:
    """Where the panel is: centre (m, world), front-face normal and first side (unit vectors)."""

    center_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    tangent: tuple[float, float, float]

    def as_json(self) -> JsonObject:
        """``{"center_m", "normal", "tangent"}``, each a list of 3 floats."""
        return {k: list(v) for k, v in dataclasses.asdict(self).items()}

    @classmethod
    def from_json(cls, record: JsonObject) -> PanelPose:
        """Inverse of :meth:`as_json`."""

        def vector(key: str) -> tuple[float, float, float]:
            x, y, z = (float(v) for v in record[key])
            return x, y, z

        return cls(center_m=vector("center_m"), normal=vector("normal"), tangent=vector("tangent"))


@dataclass(frozen=True, kw_only=True)
class PanelLight:
    """The panel's irradiance components in one scene (W/m^2 of visible-band light).

    Args:
        lights: ``{light name: estimate}`` with that light alone on.
        hours: local solar hours of the daylight samples, shape (T,).
        daylight: daylight estimate per sample (all lights off), length T; ``None``
            where the sun is below civil twilight (no sky light: not rendered).
        seconds: wall time of the renders (s).
    """

    lights: dict[str, IrradianceEstimate]
    hours: np.ndarray
    daylight: tuple[IrradianceEstimate | None, ...]
    seconds: float

    def as_json(self) -> JsonObject:
        """Every estimate as ``{"mean_w_m2", "stderr_w_m2", "spp"}`` (null: not rendered)."""

        def est(e: IrradianceEstimate | None) -> JsonObject | None:
            return None if e is None else dataclasses.asdict(e)

        return {
            "lights": {name: est(e) for name, e in self.lights.items()},
            "hours": [float(h) for h in self.hours],
            "daylight": [est(e) for e in self.daylight],
            "seconds": self.seconds,
        }

    @classmethod
    def from_json(cls, record: JsonObject) -> PanelLight:
        """Inverse of :meth:`as_json`."""
        from mincam_render.render.irradiance import IrradianceEstimate

        def est(r: JsonObject | None) -> IrradianceEstimate | None:
            return None if r is None else IrradianceEstimate(**r)

        lights = {name: est(r) for name, r in record["lights"].items()}
        return cls(
            lights=cast("dict[str, IrradianceEstimate]", lights),
            hours=np.asarray(record["hours"], dtype=np.float64),
            daylight=tuple(est(r) for r in record["daylight"]),
            seconds=float(record["seconds"]),
        )

    def max_relative_error(self) -> float:
        """Largest standard error / mean of the components rendered (0 if none)."""
        ests = [*self.lights.values(), *(d for d in self.daylight if d is not None)]
        return max((e.relative_error for e in ests if e.mean_w_m2 > 0), default=0.0)

    def max_relative_error_total(self, schedule: ScheduleConfig) -> float:
        """Largest standard error / mean of the scheduled total at the sample hours.

        The components' errors are independent (separate renders): they add in quadrature.
        """
        var = np.array([0.0 if d is None else d.stderr_w_m2**2 for d in self.daylight])
        for name, est in self.lights.items():
            var = var + est.stderr_w_m2**2 * lights_on(schedule, name, self.hours)
        total = day_irradiance(self, schedule, self.hours)
        lit = total > 0
        return float(np.max(np.sqrt(var[lit]) / total[lit])) if np.any(lit) else 0.0


def panel_pose(camera_position: ArrayLike, frame: ArrayLike, panel: PanelConfig) -> PanelPose:
    """The panel below the board centre by ``offset_m``, facing the board's normal (+ tilt).

    Args:
        camera_position: board centre (m, world), shape (3,).
        frame: the camera's ``(right, up, forward)`` unit vectors (world), shape (3, 3).
        panel: offset and tilt.
    """
    right, up, fwd = np.asarray(frame, dtype=np.float64)
    tilt = math.radians(panel.tilt_deg)
    normal = math.cos(tilt) * fwd + math.sin(tilt) * up
    center = np.asarray(camera_position, dtype=np.float64) - panel.offset_m * up
    return PanelPose(
        center_m=tuple(float(v) for v in center),  # type: ignore[arg-type]
        normal=tuple(float(v) for v in normal),  # type: ignore[arg-type]
        tangent=tuple(float(v) for v in right),  # type: ignore[arg-type]
    )


def day_family(family: str, config: EnergyConfig) -> IndoorFamily:
    """Family ``family`` with daylight in real time from midnight and the render depth set.

    Frame time ``t`` seconds is local solar hour ``t / 3600``.

    Raises:
        ConfigError: an unknown family or a bad description.
        ValueError: a family that is not an indoor scene (no rig).
    """
    from mincam_render.scenes.indoor import IndoorFamily
    from mincam_render.scenes.registry import FAMILY_NAMES, family_class, load_family

    path = Path(family)
    # a shipped name, a description file (naming its family), a registered name or module:Class
    name = family if family in FAMILY_NAMES or not path.is_file() else _family_key(path)
    if not issubclass(family_class(name), IndoorFamily):
        raise ValueError(
            f"family {name!r} is not an indoor scene (no lights or window to schedule): "
            "the energy study needs one (workspace, lighting)"
        )
    daylight: dict[str, float] = {"start_hour": 0.0, "hours_per_second": 1.0 / SECONDS_PER_HOUR}
    if config.schedule.overcast is not None:
        daylight["overcast"] = config.schedule.overcast
    # nobody is rendered (components are lit rooms, empty): no burn-in of the people
    overrides = {"max_depth": config.render.max_depth, "burn_in_s": 0.0, "daylight": daylight}
    fam = load_family(family, seed=config.render.seed, num_frames=1, overrides=overrides)
    return cast("IndoorFamily", fam)  # checked above, by its class


def _family_key(path: Path) -> str:
    """The ``family`` key of a scene description (TOML); ConfigError if unreadable."""
    try:
        family = tomllib.loads(path.read_text()).get("family")
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the scene description ({err})") from None
    if not isinstance(family, str):
        raise ConfigError(f'{path}: missing top-level key family = "<name>"')
    return family


def render_panel_light(fam: IndoorFamily, config: EnergyConfig) -> tuple[PanelPose, PanelLight]:
    """Render the panel's irradiance components in the scene of ``fam`` (from :func:`day_family`).

    Returns:
        The panel's pose and its light: each switchable light alone, and the daylight
        at each sample of the day (``config.schedule.step_min``).
    """
    from mincam_render.render.irradiance import measure_irradiance

    rig = fam.rig
    pose, meter = _panel_meter(fam, config)
    r = config.render
    start = time.perf_counter()
    scene = fam.build_scene()

    def measure(key: str) -> IrradianceEstimate:
        fam.set_background_component(scene, key)
        return measure_irradiance(scene, meter, spp=r.spp, batches=r.batches, seed=r.seed)

    check_light_names(config.schedule, [li.name for li in rig.lights])
    lights = {li.name: measure(f"light={li.key}") for li in rig.lights}
    hours = day_hours(config.schedule)
    days: list[IrradianceEstimate | None] = []
    for h in hours:
        sun_up = (
            rig.window is not None and _sun_elevation_deg(rig.daylight_config, h) > TWILIGHT_DEG
        )
        days.append(measure(f"daylight_s={h * SECONDS_PER_HOUR:.10g}") if sun_up else None)
    light = PanelLight(
        lights=lights, hours=hours, daylight=tuple(days), seconds=time.perf_counter() - start
    )
    log.info(
        "%s: panel irradiance rendered in %.1f s, max relative error %.2f %%",
        fam.name,
        light.seconds,
        100 * light.max_relative_error(),
    )
    return pose, light


def _panel_meter(fam: IndoorFamily, config: EnergyConfig) -> tuple[PanelPose, MitsubaDict]:
    """The panel's pose beside the family's camera, and its irradiance meter (a Mitsuba dict)."""
    from mincam_render.render.mitsuba_scene import irradiance_meter

    cam = fam.camera()
    pose = panel_pose(np.asarray(cam.position), cam.frame, config.panel)
    side = math.sqrt(config.panel.area_m2)
    return pose, irradiance_meter(pose.center_m, pose.normal, pose.tangent, (side, side))


@dataclass(frozen=True, kw_only=True)
class DepthRow:
    """One component's panel irradiance at one path depth (W/m^2), against the deepest."""

    depth: int
    component: str
    irradiance_w_m2: float
    stderr_w_m2: float
    relative_to_deepest: float

    def as_json(self) -> JsonObject:
        """The row's fields in order."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class DepthCheck:
    """Is the description's path depth deep enough? Rows per depth and component."""

    family: str
    rows: tuple[DepthRow, ...]

    def as_json(self) -> JsonObject:
        """``{"family", "rows"}``."""
        return {"family": self.family, "rows": [r.as_json() for r in self.rows]}


def depth_check(family: str, config: EnergyConfig, depths: Sequence[int]) -> DepthCheck:
    """The panel's irradiance of one light alone (and noon daylight) at ``depths``.

    The panel sees lit walls, so its irradiance needs interreflections: each
    component is rendered with the description's samples at every depth and
    compared with the deepest (``depths[-1]``). The components are the family's
    first light alone and, if it has a window, the daylight at noon.
    """
    from mincam_render.render.irradiance import measure_irradiance

    measured: list[tuple[int, str, IrradianceEstimate]] = []
    for depth in depths:
        render = dataclasses.replace(config.render, max_depth=depth)
        cfg = dataclasses.replace(config, render=render)
        fam = day_family(family, cfg)
        _, meter = _panel_meter(fam, cfg)
        scene = fam.build_scene()
        keys = [f"light={fam.rig.lights[0].key}"]
        if fam.rig.window is not None:
            keys.append("daylight_s=43200")
        for key in keys:
            fam.set_background_component(scene, key)
            r = cfg.render
            est = measure_irradiance(scene, meter, spp=r.spp, batches=r.batches, seed=r.seed)
            measured.append((depth, key, est))
    deepest = {key: est.mean_w_m2 for depth, key, est in measured if depth == depths[-1]}
    rows = tuple(
        DepthRow(
            depth=depth,
            component=key,
            irradiance_w_m2=est.mean_w_m2,
            stderr_w_m2=est.stderr_w_m2,
            relative_to_deepest=est.mean_w_m2 / deepest[key] - 1.0,
        )
        for depth, key, est in measured
    )
    return DepthCheck(family=family, rows=rows)


def _sun_elevation_deg(daylight_config: object, hour: float) -> float:
    from mincam_render.scenes.sky import solar_direction

    c = daylight_config
    sun = solar_direction(c.day_of_year, hour % 24.0, c.latitude_deg)  # type: ignore[attr-defined]
    return math.degrees(math.asin(max(-1.0, min(1.0, float(sun[2])))))


def check_light_names(schedule: ScheduleConfig, names: list[str]) -> None:
    """Raise ``ValueError`` if a per-light schedule names a light the scene does not have."""
    for i, light in enumerate(schedule.lights):
        if light.name not in names:
            raise ValueError(
                f"schedule.lights[{i}].name = {light.name!r}: the scene's lights are "
                f"{', '.join(names) or '(none)'}"
            )


def day_hours(schedule: ScheduleConfig) -> np.ndarray:
    """Sample hours of the day: ``0, step, ..., 24 - step`` (h)."""
    n = round(24 * 60 / schedule.step_min)
    return np.arange(n) * (schedule.step_min / 60.0)


def lights_on(schedule: ScheduleConfig, name: str, hours: np.ndarray) -> np.ndarray:
    """Whether light ``name`` is on at ``hours`` (bool, same shape); overnight if off < on."""
    on, off = schedule.hours_on(name)
    h = np.mod(hours, 24.0)
    return (h >= on) & (h < off) if on <= off else (h >= on) | (h < off)


def day_irradiance(light: PanelLight, schedule: ScheduleConfig, hours: np.ndarray) -> np.ndarray:
    """Panel irradiance (W/m^2) at ``hours``: scheduled lights + daylight (linear in time).

    Args:
        light: the rendered components.
        schedule: when each light is on.
        hours: local solar hours (any shape; wrapped into [0, 24)).
    """
    h = np.mod(np.asarray(hours, dtype=np.float64), 24.0)
    day = np.array([0.0 if d is None else d.mean_w_m2 for d in light.daylight])
    samples = np.append(light.hours, 24.0)
    total = np.interp(h, samples, np.append(day, day[0]))
    for name, est in light.lights.items():
        total = total + est.mean_w_m2 * lights_on(schedule, name, h)
    return total
