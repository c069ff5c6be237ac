"""Photometric <-> radiometric conversions for scene descriptions.

Scenes are rendered in radiometric units of the detector's band: watts of
visible light (about 400-700 nm). Descriptions may give lamps in lumens and
illuminance in lux; these conversions use a luminous efficacy of *visible-band*
radiation for white light, so that "hundreds of lux indoors" and "tens of
thousands of lux outdoors" land at realistic detector signals.
"""

from __future__ import annotations

import math

#: Luminous efficacy of white light's visible-band radiant power (lm per W of
#: 400-700 nm radiation). Daylight and white LEDs are both ~250-320 lm/W_vis;
#: we use one value so lumens and lux convert consistently.
WHITE_LIGHT_EFFICACY_LM_PER_W = 300.0
#: Fraction of broadband sunlight (W/m^2) in the 400-700 nm band.
VISIBLE_FRACTION_OF_SUNLIGHT = 0.43


def lumens_to_watts(lumens: float) -> float:
    """Visible-band radiant power (W) of a white source of ``lumens`` (lm)."""
    return lumens / WHITE_LIGHT_EFFICACY_LM_PER_W


def lux_to_irradiance(lux: float) -> float:
    """Visible-band irradiance (W/m^2) of white light of illuminance ``lux`` (lx)."""
    return lux / WHITE_LIGHT_EFFICACY_LM_PER_W


def irradiance_to_lux(irradiance_w_m2: float) -> float:
    """Illuminance (lx) of white light of visible-band irradiance (W/m^2)."""
    return irradiance_w_m2 * WHITE_LIGHT_EFFICACY_LM_PER_W


def lambertian_radiance(power_w: float, area_m2: float) -> float:
    r"""Radiance (W m^-2 sr^-1) of a one-sided Lambertian emitter of ``power_w`` on ``area_m2``.

    .. math:: L = \Phi / (\pi A)
    """
    if area_m2 <= 0:
        raise ValueError(f"area_m2 = {area_m2!r} must be > 0")
    return power_w / (math.pi * area_m2)


def rectangle_projected_solid_angle(
    half_width_m: float, half_height_m: float, distance_m: float
) -> float:
    r"""Projected solid angle (sr) of a rectangle facing a point on its axis.

    The rectangle (half-sides ``half_width_m``, ``half_height_m``) is centred on
    the normal of a small receiver ``distance_m`` away and parallel to it; a
    Lambertian rectangle of uniform radiance ``L`` gives the receiver the
    irradiance ``E = L * Omega``. Sum of the four corner rectangles' form
    factors (each ``pi F``), with ``X = a / d``, ``Y = b / d``:

    .. math:: \Omega = 2 \left[ \frac{X}{\sqrt{1+X^2}} \arctan\frac{Y}{\sqrt{1+X^2}}
              + \frac{Y}{\sqrt{1+Y^2}} \arctan\frac{X}{\sqrt{1+Y^2}} \right]

    It tends to ``pi`` (a whole hemisphere) as the rectangle grows, and to
    ``area / d^2`` when it is small.
    """
    for name, v in (
        ("half_width_m", half_width_m),
        ("half_height_m", half_height_m),
        ("distance_m", distance_m),
    ):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"{name} = {v!r} m: need a finite length > 0")
    x, y = half_width_m / distance_m, half_height_m / distance_m
    sx, sy = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    return 2 * (x / sx * math.atan(y / sx) + y / sy * math.atan(x / sy))
