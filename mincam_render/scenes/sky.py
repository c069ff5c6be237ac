"""Daylight in physical units: sun position, direct sun and a CIE sky (numpy).

Used by outdoor scenes and by windows of indoor scenes, in place of Mitsuba's
``sunsky`` (which needs RGB or spectral variants; our detectors are monochrome).
World frame: +z up, +y north, +x east. Irradiances and radiances are in the
detector's visible band (see :mod:`mincam_render.core.photometry`).

- Sun position: declination and hour angle (Cooper's formula), local solar time.
- Direct normal irradiance: Meinel's clear-sky attenuation ``0.7^(AM^0.678)``
  with the Kasten-Young air mass, scaled by ``1 - overcast``.
- Sky radiance: the CIE standard general sky luminance distribution (ISO
  15469), clear type 12 blended with overcast type 1 by ``overcast``, scaled so
  its diffuse horizontal irradiance follows an empirical clear/overcast split.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.config import spec
from mincam_render.core.photometry import SOLAR_CONSTANT_W_M2, VISIBLE_FRACTION_OF_SUNLIGHT

if TYPE_CHECKING:
    import mitsuba as mi

# CIE standard general sky parameters (a, b, c, d, e), ISO 15469:2004.
_CIE_CLEAR = (-1.0, -0.32, 10.0, -3.0, 0.45)  # type 12, clear, low turbidity
_CIE_OVERCAST = (4.0, -0.70, 0.0, -1.0, 0.0)  # type 1, overcast, steep gradation
#: Diffuse / direct-horizontal ratio of a clear sky, and overcast global / clear global.
_CLEAR_DIFFUSE_RATIO = 0.15
_OVERCAST_TRANSMISSION = 0.3


@dataclass(frozen=True, kw_only=True)
class DaylightConfig:
    """Where and when: site latitude, date, time span of the sequence, cloudiness."""

    latitude_deg: float = spec(40.8, unit="deg", range=(-66.0, 66.0), doc="site latitude")
    day_of_year: int = spec(172, range=(1, 365), doc="1 = Jan 1; 172 = June 21")
    start_hour: float = spec(7.0, unit="h", range=(0.0, 24.0), doc="local solar time at frame 0")
    hours_per_second: float = spec(
        0.0, unit="h/s", range=(0.0, 3600.0), doc="time-lapse: solar hours per sequence second"
    )
    overcast: float = spec(0.0, range=(0.0, 1.0), doc="0 = clear sky, 1 = fully overcast")
    ground_albedo: float = spec(0.2, range=(0.0, 1.0), doc="albedo of the ground below the horizon")
    north_deg: float = spec(
        0.0, unit="deg", range=(-360.0, 360.0), doc="rotation of north from +y about +z"
    )


def solar_direction(day_of_year: int, solar_hour: float, latitude_deg: float) -> np.ndarray:
    """Unit vector toward the sun (+z up, +y north, +x east); z < 0 at night."""
    decl = math.radians(23.44) * math.sin(2.0 * math.pi * (284 + day_of_year) / 365.0)
    hour_angle = math.radians(15.0 * (solar_hour - 12.0))
    lat = math.radians(latitude_deg)
    # east, north, up components of the sun direction
    up = math.sin(lat) * math.sin(decl) + math.cos(lat) * math.cos(decl) * math.cos(hour_angle)
    east = -math.cos(decl) * math.sin(hour_angle)
    north = math.cos(lat) * math.sin(decl) - math.sin(lat) * math.cos(decl) * math.cos(hour_angle)
    v = np.array([east, north, up])
    return v / np.linalg.norm(v)


def air_mass(elevation_rad: float) -> float:
    """Kasten-Young relative optical air mass (infinite below the horizon)."""
    zenith_deg = 90.0 - math.degrees(elevation_rad)
    if zenith_deg >= 90.0:
        return math.inf
    return 1.0 / (math.cos(math.radians(zenith_deg)) + 0.50572 * (96.07995 - zenith_deg) ** -1.6364)


def direct_normal_irradiance(elevation_rad: float, overcast: float) -> float:
    """Visible-band direct normal irradiance of the sun (W/m^2)."""
    am = air_mass(elevation_rad)
    if not math.isfinite(am):
        return 0.0
    return (
        SOLAR_CONSTANT_W_M2 * VISIBLE_FRACTION_OF_SUNLIGHT * 0.7 ** (am**0.678) * (1.0 - overcast)
    )


def diffuse_horizontal_irradiance(elevation_rad: float, overcast: float) -> float:
    """Visible-band diffuse irradiance of the sky on a horizontal plane (W/m^2)."""
    if elevation_rad <= 0:
        # civil twilight: fade over 6 degrees below the horizon
        return max(0.0, 1.0 + math.degrees(elevation_rad) / 6.0) * 2.0
    clear_direct_h = direct_normal_irradiance(elevation_rad, 0.0) * math.sin(elevation_rad)
    clear_diffuse = _CLEAR_DIFFUSE_RATIO * clear_direct_h + 2.0
    overcast_diffuse = _OVERCAST_TRANSMISSION * (clear_direct_h + clear_diffuse)
    return (1.0 - overcast) * clear_diffuse + overcast * overcast_diffuse


def _cie_relative(
    params: tuple[float, float, float, float, float],
    zenith: np.ndarray,
    gamma: np.ndarray,
    sun_zenith: float,
) -> np.ndarray:
    a, b, c, d, e = params

    def grad(z: np.ndarray) -> np.ndarray:
        return 1.0 + a * np.exp(b / np.maximum(np.cos(z), 1e-3))

    def indic(g: np.ndarray) -> np.ndarray:
        return 1.0 + c * (np.exp(d * g) - math.exp(d * math.pi / 2)) + e * np.cos(g) ** 2

    return indic(gamma) * grad(zenith) / (indic(np.array(sun_zenith)) * grad(np.array(0.0)))


@dataclass(frozen=True)
class Daylight:
    """Sun and sky of one instant (visible band)."""

    sun_direction: np.ndarray  # unit vector toward the sun (world)
    sun_irradiance_w_m2: float  # direct normal irradiance
    sky_radiance_w_m2_sr: np.ndarray  # lat-long map, Mitsuba envmap layout (local +y up)
    diffuse_horizontal_w_m2: float

    @property
    def global_horizontal_w_m2(self) -> float:
        """Direct + diffuse irradiance on a horizontal plane (W/m^2)."""
        return (
            self.sun_irradiance_w_m2 * max(0.0, float(self.sun_direction[2]))
            + self.diffuse_horizontal_w_m2
        )


def envmap_directions(height: int, width: int) -> np.ndarray:
    """World directions (+z up) of the texel centres of Mitsuba's envmap, shape (H, W, 3).

    Mitsuba's envmap maps a local direction ``v`` (local +y up) to
    ``u = atan2(v.x, -v.z) / 2pi``, ``v = acos(v.y) / pi``. With the envmap's
    ``to_world`` from :func:`envmap_to_world` (local +y -> world +z,
    local +z -> world -y), local (x, y, z) is world (x, -z, y).
    """
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = 2.0 * math.pi * u
    theta = math.pi * v
    uu, tt = np.meshgrid(phi, theta)
    lx = np.sin(tt) * np.sin(uu)
    lz = -np.sin(tt) * np.cos(uu)
    ly = np.cos(tt)
    return np.stack([lx, -lz, ly], axis=-1)


def envmap_to_world() -> mi.ScalarTransform4f:
    """The envmap ``to_world`` used with :func:`envmap_directions` (Mitsuba transform)."""
    import mitsuba as mi

    from mincam_render.render.backend import use_variant

    use_variant()
    return mi.ScalarTransform4f().rotate([1, 0, 0], 90.0)


def daylight(
    config: DaylightConfig, time_s: float, *, height: int = 64, width: int = 128
) -> Daylight:
    """Sun and sky ``time_s`` seconds after the start of the sequence."""
    hour = config.start_hour + config.hours_per_second * time_s
    sun = solar_direction(config.day_of_year, hour % 24.0, config.latitude_deg)
    rot = math.radians(config.north_deg)
    c, s = math.cos(rot), math.sin(rot)
    sun = np.array([c * sun[0] - s * sun[1], s * sun[0] + c * sun[1], sun[2]])
    elevation = math.asin(max(-1.0, min(1.0, sun[2])))
    dni = direct_normal_irradiance(elevation, config.overcast)
    dhi = diffuse_horizontal_irradiance(elevation, config.overcast)

    dirs = envmap_directions(height, width)
    zenith = np.arccos(np.clip(dirs[..., 2], -1.0, 1.0))
    gamma = np.arccos(np.clip(dirs @ sun, -1.0, 1.0))
    sun_zenith = min(math.acos(max(-1.0, min(1.0, sun[2]))), math.radians(89.0))
    upper = dirs[..., 2] > 0
    rel = (1.0 - config.overcast) * _cie_relative(_CIE_CLEAR, zenith, gamma, sun_zenith)
    rel = rel + config.overcast * _cie_relative(_CIE_OVERCAST, zenith, gamma, sun_zenith)
    rel = np.where(upper, np.maximum(rel, 0.0), 0.0)
    # normalise: DHI = sum L cos(zenith) dOmega over the upper hemisphere
    d_omega = (
        (2 * math.pi / width)
        * (math.pi / height)
        * np.sin((np.arange(height) + 0.5) / height * math.pi)
    )
    integral = float((rel * np.maximum(dirs[..., 2], 0.0) * d_omega[:, None]).sum())
    sky = rel * (dhi / integral) if integral > 0 else rel * 0.0
    ground = config.ground_albedo * (dni * max(0.0, sun[2]) + dhi) / math.pi
    sky = np.where(upper, sky, ground)
    return Daylight(sun, dni, sky.astype(np.float32), dhi)
