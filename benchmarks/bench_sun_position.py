r"""The hand-written sun position and clear-sky irradiance of format v3 against pvlib (v4).

Until dataset format 3, ``scenes/sky.py`` computed the sun's position by
Cooper's declination and the hour angle of the solar hour (no refraction) and
the clear-sky irradiance by Meinel's attenuation with the Kasten-Young air mass;
those formulas are kept here (``v3_*``) as the "before". Since format 4 the
package uses pvlib: :func:`mincam_render.scenes.sky.solar_position_deg` (NREL
SPA, apparent elevation with refraction, at the UTC time whose apparent solar
time at longitude 0 equals the solar hour) and
:func:`~mincam_render.scenes.sky.clear_sky_irradiance` (simplified Solis,
aerosol optical depth 0.1 at 700 nm, 1 cm of precipitable water). For several
latitudes, days of the year and local solar hours this compares the two
(visible-band irradiance divided by ``VISIBLE_FRACTION_OF_SUNLIGHT`` to compare
broadband). Writes ``benchmarks/results/sun_position.json``: per-case values and
the max and RMS differences.

Usage:
    python benchmarks/bench_sun_position.py
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from provenance import machine  # noqa: E402

from mincam_render.core import strict_json
from mincam_render.core.photometry import VISIBLE_FRACTION_OF_SUNLIGHT  # noqa: E402
from mincam_render.scenes.sky import (  # noqa: E402
    clear_sky_irradiance,
    solar_position_deg,
)

LATITUDES_DEG = (0.0, 40.8, 60.0, -33.9)
DAYS = (1, 80, 172, 266, 355)
SOLAR_HOURS = (7.0, 9.0, 12.0, 15.0, 17.0)
YEAR = 2026


def v3_sun(day: int, hour: float, lat: float) -> tuple[float, float, float]:
    """Elevation, azimuth (deg from north, clockwise) and up component, format v3."""
    decl = math.radians(23.44) * math.sin(2.0 * math.pi * (284 + day) / 365.0)
    hour_angle = math.radians(15.0 * (hour - 12.0))
    la = math.radians(lat)
    up = math.sin(la) * math.sin(decl) + math.cos(la) * math.cos(decl) * math.cos(hour_angle)
    east = -math.cos(decl) * math.sin(hour_angle)
    north = math.cos(la) * math.sin(decl) - math.sin(la) * math.cos(decl) * math.cos(hour_angle)
    norm = math.sqrt(east**2 + north**2 + up**2)
    return math.degrees(math.asin(up / norm)), math.degrees(math.atan2(east, north)) % 360.0, up


def v3_clear_sky_ghi(elevation_rad: float) -> float:
    """Broadband clear-sky GHI (W/m^2) of format v3: Meinel DNI, 15 % diffuse + 2 W/m^2."""
    zenith_deg = 90.0 - math.degrees(elevation_rad)
    if zenith_deg >= 90.0:
        return 0.0
    am = 1.0 / (math.cos(math.radians(zenith_deg)) + 0.50572 * (96.07995 - zenith_deg) ** -1.6364)
    dni = 1361.0 * VISIBLE_FRACTION_OF_SUNLIGHT * 0.7 ** (am**0.678)
    direct_h = dni * math.sin(elevation_rad)
    return (direct_h + 0.15 * direct_h + 2.0) / VISIBLE_FRACTION_OF_SUNLIGHT


def ours(day: int, hour: float, lat: float) -> tuple[float, float, float]:
    """Format v3: elevation (deg), azimuth (deg from north, clockwise), broadband GHI (W/m^2)."""
    elevation, azimuth, up = v3_sun(day, hour, lat)
    return elevation, azimuth, v3_clear_sky_ghi(math.radians(elevation)) if up > 0 else 0.0


def pvlib_case(day: int, hour: float, lat: float) -> tuple[float, float, float]:
    """Format v4, the package's pvlib functions (SPA position, simplified Solis clear sky)."""
    elevation, azimuth = solar_position_deg(day, hour, lat)
    el = math.radians(elevation)
    dni, dhi = clear_sky_irradiance(el)
    ghi = (dni * math.sin(el) + dhi) / VISIBLE_FRACTION_OF_SUNLIGHT if elevation > 0 else 0.0
    return elevation, azimuth, ghi


def main() -> None:
    cases = []
    for lat in LATITUDES_DEG:
        for day in DAYS:
            for hour in SOLAR_HOURS:
                a, b = ours(day, hour, lat), pvlib_case(day, hour, lat)
                d_az = (a[1] - b[1] + 180.0) % 360.0 - 180.0
                cases.append({
                    "latitude_deg": lat, "day_of_year": day, "solar_hour": hour,
                    "ours": {"elevation_deg": a[0], "azimuth_deg": a[1], "ghi_w_m2": a[2]},
                    "pvlib": {"elevation_deg": b[0], "azimuth_deg": b[1], "ghi_w_m2": b[2]},
                    "elevation_error_deg": a[0] - b[0],
                    # azimuth is undefined near the zenith: compared for 0 < elevation < 80 deg
                    "azimuth_error_deg": d_az if 0 < b[0] < 80 else None,
                    "ghi_ratio": a[2] / b[2] if b[2] > 50.0 else None,
                })  # fmt: skip
    el = np.array([c["elevation_error_deg"] for c in cases])
    az = np.array([c["azimuth_error_deg"] for c in cases if c["azimuth_error_deg"] is not None])
    ratio = np.array([c["ghi_ratio"] for c in cases if c["ghi_ratio"] is not None])
    summary = {
        "elevation_error_deg": {"max_abs": float(np.abs(el).max()), "rms": float(np.sqrt((el**2).mean()))},
        "azimuth_error_deg_elevation_0_80": {"max_abs": float(np.abs(az).max()), "rms": float(np.sqrt((az**2).mean()))},
        "ghi_ratio_ours_over_pvlib_above_50_w_m2": {
            "min": float(ratio.min()), "median": float(np.median(ratio)), "max": float(ratio.max()),
        },
        "cases": len(cases),
    }  # fmt: skip
    import pvlib

    res = {"machine": machine(), "pvlib": pvlib.__version__, "summary": summary, "cases": cases}
    out = Path(__file__).parent / "results" / "sun_position.json"
    out.write_text(strict_json.dumps(res, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
