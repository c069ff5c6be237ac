r"""Our sun position and clear-sky irradiance (scenes/sky.py) against pvlib, before replacing them.

For several latitudes, days of the year and local solar hours: the sun's
elevation and azimuth of :func:`mincam_render.scenes.sky.solar_direction`
(declination by Cooper's formula, hour angle from the solar hour, no refraction)
against pvlib's NREL SPA (``pvlib.solarposition.get_solarposition``, apparent
elevation with refraction) at the UTC time whose apparent solar time at
longitude 0 equals that solar hour (``equation_of_time_spencer71``); and the
clear-sky global horizontal irradiance of
:func:`~mincam_render.scenes.sky.direct_normal_irradiance` /
:func:`~mincam_render.scenes.sky.diffuse_horizontal_irradiance` (visible band,
divided by ``VISIBLE_FRACTION_OF_SUNLIGHT`` to compare with broadband) against
pvlib's simplified Solis model (aerosol optical depth 0.1 at 700 nm, 1 cm of
precipitable water) at the same SPA elevation. Writes
``benchmarks/results/sun_position.json``: per-case values and the max and RMS
differences.

Needs pvlib (not a dependency of the package): ``.venv/bin/pip install pvlib``.

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
from bench_patches_paper import machine  # noqa: E402

from mincam_render.core.photometry import VISIBLE_FRACTION_OF_SUNLIGHT  # noqa: E402
from mincam_render.scenes.sky import (  # noqa: E402
    diffuse_horizontal_irradiance,
    direct_normal_irradiance,
    solar_direction,
)

LATITUDES_DEG = (0.0, 40.8, 60.0, -33.9)
DAYS = (1, 80, 172, 266, 355)
SOLAR_HOURS = (7.0, 9.0, 12.0, 15.0, 17.0)
YEAR = 2026


def ours(day: int, hour: float, lat: float) -> tuple[float, float, float]:
    """Elevation (deg), azimuth (deg from north, clockwise), broadband GHI (W/m^2)."""
    east, north, up = solar_direction(day, hour, lat)
    elevation = math.degrees(math.asin(up))
    azimuth = math.degrees(math.atan2(east, north)) % 360.0
    el = math.radians(elevation)
    ghi_visible = direct_normal_irradiance(el, 0.0) * max(0.0, up)
    ghi_visible += diffuse_horizontal_irradiance(el, 0.0) if up > 0 else 0.0
    return elevation, azimuth, ghi_visible / VISIBLE_FRACTION_OF_SUNLIGHT


def pvlib_case(day: int, hour: float, lat: float) -> tuple[float, float, float]:
    """The same quantities from pvlib (SPA position, simplified Solis clear sky)."""
    import pandas as pd
    import pvlib

    eot_min = float(pvlib.solarposition.equation_of_time_spencer71(day))
    utc_hour = hour - eot_min / 60.0
    t = pd.Timestamp(f"{YEAR}-01-01", tz="UTC") + pd.Timedelta(days=day - 1, hours=utc_hour)
    pos = pvlib.solarposition.get_solarposition(pd.DatetimeIndex([t]), lat, 0.0)
    elevation = float(pos["apparent_elevation"].iloc[0])
    azimuth = float(pos["azimuth"].iloc[0])
    sky = pvlib.clearsky.simplified_solis(max(elevation, 0.0))
    ghi = float(np.nan_to_num(sky["ghi"])) if elevation > 0 else 0.0
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
    out.write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
