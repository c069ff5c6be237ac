"""Daylight in physical units: sun position, direct sun and a CIE sky (numpy).

Used by outdoor scenes and by windows of indoor scenes, in place of Mitsuba's
``sunsky`` (which needs RGB or spectral variants; our detectors are monochrome).
World frame: +z up, +y north, +x east. Irradiances and radiances are in the
detector's visible band (see :mod:`mincam_render.core.photometry`).

- Sun position: pvlib's NREL SPA (apparent elevation, with refraction) at the
  scene's latitude, longitude 0, for the scene's local apparent solar time
  (:func:`solar_position_deg` states the time convention).
- Clear-sky irradiance: pvlib's simplified Solis model (direct normal and
  diffuse horizontal); clouds scale the direct sun by ``1 - overcast`` and blend
  the diffuse part toward an overcast sky.
- Sky radiance: the CIE standard general sky luminance distribution (ISO
  15469), clear type 12 blended with overcast type 1 by ``overcast``, scaled to
  the diffuse horizontal irradiance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from mincam_render.core.config import Described, spec
from mincam_render.core.photometry import VISIBLE_FRACTION_OF_SUNLIGHT

if TYPE_CHECKING:
    import mitsuba as mi

# CIE standard general sky parameters (a, b, c, d, e), ISO 15469:2004.
_CIE_CLEAR = (-1.0, -0.32, 10.0, -3.0, 0.45)  # type 12, clear, low turbidity
_CIE_OVERCAST = (4.0, -0.70, 0.0, -1.0, 0.0)  # type 1, overcast, steep gradation
#: Global horizontal irradiance of an overcast sky / that of the clear sky.
_OVERCAST_TRANSMISSION = 0.3


@dataclass(frozen=True, kw_only=True)
class DaylightConfig(Described):
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


#: Year of the calendar the scenes' ``day_of_year`` falls in (not a leap year).
SOLAR_YEAR = 2026
#: Clear-sky atmosphere of pvlib's simplified Solis model: aerosol optical depth
#: at 700 nm, precipitable water (cm), pressure (Pa); a clean sea-level site.
SOLIS_AOD700 = 0.1
SOLIS_PRECIPITABLE_WATER_CM = 1.0
SOLIS_PRESSURE_PA = 101325.0
#: Diffuse horizontal irradiance (visible, W/m^2) of the sky at sunset, fading to 0
#: at 6 degrees below the horizon (civil twilight).
TWILIGHT_DIFFUSE_W_M2 = 2.0


def solar_position_deg(
    day_of_year: int, solar_hour: float, latitude_deg: float
) -> tuple[float, float]:
    """Apparent elevation and azimuth (deg, azimuth clockwise from north) of the sun.

    pvlib's NREL SPA (``pvlib.solarposition.get_solarposition``) at latitude
    ``latitude_deg``, longitude 0, sea level, with atmospheric refraction at
    standard pressure and 12 C. ``solar_hour`` is local apparent solar time
    (12 = the sun on the meridian): at longitude 0 it is the UTC time plus the
    equation of time (Spencer 1971) of ``day_of_year`` in :data:`SOLAR_YEAR`, so
    the instant passed to SPA is ``UTC = solar_hour - EoT``.
    """
    import pandas as pd
    import pvlib

    eot_min = float(pvlib.solarposition.equation_of_time_spencer71(day_of_year))
    start = pd.Timestamp(f"{SOLAR_YEAR}-01-01", tz="UTC")
    when = start + pd.Timedelta(days=day_of_year - 1, hours=solar_hour - eot_min / 60.0)
    pos = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([when]), latitude_deg, 0.0)
    return float(pos["apparent_elevation"].iloc[0]), float(pos["azimuth"].iloc[0])


def solar_direction(day_of_year: int, solar_hour: float, latitude_deg: float) -> np.ndarray:
    """Unit vector toward the sun (+z up, +y north, +x east); z < 0 at night.

    From :func:`solar_position_deg` (pvlib SPA, apparent elevation).
    """
    elevation_deg, azimuth_deg = solar_position_deg(day_of_year, solar_hour, latitude_deg)
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])


def clear_sky_irradiance(elevation_rad: float) -> tuple[float, float]:
    """Visible-band clear-sky ``(direct normal, diffuse horizontal)`` irradiance (W/m^2).

    pvlib's simplified Solis model (``pvlib.clearsky.simplified_solis``, the
    ``SOLIS_*`` atmosphere) at apparent elevation ``elevation_rad`` (rad), times
    ``VISIBLE_FRACTION_OF_SUNLIGHT``; the diffuse part is at least the twilight
    level at the horizon. Below the horizon: no direct sun, and the diffuse
    twilight fading to 0 at -6 degrees.
    """
    import pvlib

    el_deg = math.degrees(elevation_rad)
    if el_deg <= 0.0:
        return 0.0, max(0.0, 1.0 + el_deg / 6.0) * TWILIGHT_DIFFUSE_W_M2
    sky = pvlib.clearsky.simplified_solis(
        el_deg,
        aod700=SOLIS_AOD700,
        precipitable_water=SOLIS_PRECIPITABLE_WATER_CM,
        pressure=SOLIS_PRESSURE_PA,
    )
    dni = float(np.nan_to_num(sky["dni"])) * VISIBLE_FRACTION_OF_SUNLIGHT
    dhi = float(np.nan_to_num(sky["dhi"])) * VISIBLE_FRACTION_OF_SUNLIGHT
    return dni, max(dhi, TWILIGHT_DIFFUSE_W_M2)


def sun_and_sky_irradiance(elevation_rad: float, overcast: float) -> tuple[float, float]:
    """Visible-band ``(direct normal, diffuse horizontal)`` irradiance (W/m^2) under clouds.

    The clear sky of :func:`clear_sky_irradiance` with the direct sun scaled by
    ``1 - overcast`` and the diffuse part blended toward an overcast sky that
    passes ``_OVERCAST_TRANSMISSION`` of the clear global horizontal irradiance.
    """
    dni, dhi = clear_sky_irradiance(elevation_rad)
    if elevation_rad <= 0:
        return 0.0, dhi
    clear_global = dni * math.sin(elevation_rad) + dhi
    diffuse = (1.0 - overcast) * dhi + overcast * _OVERCAST_TRANSMISSION * clear_global
    return dni * (1.0 - overcast), diffuse


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
    dni, dhi = sun_and_sky_irradiance(elevation, config.overcast)

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
