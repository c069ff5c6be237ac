"""Sun position (pvlib SPA) and clear-sky irradiance (pvlib simplified Solis) of scenes/sky.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mincam_render.core.photometry import VISIBLE_FRACTION_OF_SUNLIGHT
from mincam_render.scenes import sky


@pytest.mark.parametrize(("day", "latitude_deg"), [(172, 40.8), (355, 40.8), (80, -33.9)])
def test_solar_noon_is_due_south_or_north_at_the_closed_form_elevation(day, latitude_deg):
    """At 12 h apparent solar time the sun is on the meridian: elevation 90 - |lat - decl|.

    ``decl`` from Spencer's (1971) Fourier series, a mean year's: in 2026 it is
    0.4 deg from SPA's near the March equinox; refraction adds < 0.05 deg above
    30 deg elevation. Spencer's equation of
    time is within ~0.5 min of SPA's, and near the zenith the azimuth turns
    ~46 deg/h, hence 0.5 deg on the azimuth.
    """
    import pvlib

    elevation, azimuth = sky.solar_position_deg(day, 12.0, latitude_deg)
    decl = math.degrees(float(pvlib.solarposition.declination_spencer71(day)))
    assert elevation == pytest.approx(90.0 - abs(latitude_deg - decl), abs=0.5)
    meridian = 180.0 if latitude_deg > decl else 0.0
    assert (azimuth - meridian + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.5)


def test_morning_and_afternoon_mirror_about_noon():
    """Same elevation at 12 -/+ 3 h, azimuths mirrored about the meridian.

    To 5e-3 (0.3 deg): the equation of time is Spencer's, within ~0.5 min of SPA's.
    """
    am, pm = sky.solar_direction(172, 9.0, 40.8), sky.solar_direction(172, 15.0, 40.8)
    assert np.linalg.norm(am) == pytest.approx(1.0, rel=1e-12)
    assert am[2] == pytest.approx(pm[2], abs=5e-3)
    assert am[0] > 0 > pm[0]  # morning sun in the east (+x)
    assert am[0] == pytest.approx(-pm[0], abs=5e-3) and am[1] == pytest.approx(pm[1], abs=5e-3)


def test_night_has_no_sun_and_twilight_fades():
    assert sky.solar_direction(172, 0.0, 40.8)[2] < 0
    assert sky.sun_and_sky_irradiance(math.radians(-3.0), 0.0) == (0.0, pytest.approx(1.0))
    assert sky.sun_and_sky_irradiance(math.radians(-7.0), 0.0) == (0.0, 0.0)
    dni, dhi = sky.sun_and_sky_irradiance(math.radians(0.01), 0.0)
    assert dhi == pytest.approx(sky.TWILIGHT_DIFFUSE_W_M2)  # continuous at the horizon


def test_clear_sky_is_visible_fraction_of_solis_and_clouds_remove_the_sun():
    el = math.radians(60.0)
    dni, dhi = sky.clear_sky_irradiance(el)
    # broadband clear-sky GHI at 60 deg elevation and sea level: 850-1000 W/m^2
    ghi = (dni * math.sin(el) + dhi) / VISIBLE_FRACTION_OF_SUNLIGHT
    assert 850.0 < ghi < 1000.0
    assert 0.05 < dhi / (dni * math.sin(el)) < 0.25  # a clear sky is mostly direct sun
    assert sky.sun_and_sky_irradiance(el, 0.0) == (dni, dhi)
    dni_oc, dhi_oc = sky.sun_and_sky_irradiance(el, 1.0)
    assert dni_oc == 0.0
    assert dhi_oc == pytest.approx(0.3 * (dni * math.sin(el) + dhi), rel=1e-12)
