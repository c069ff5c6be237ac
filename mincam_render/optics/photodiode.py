"""Photodiode presets: the angular response of the paper's prototype diode.

The Hamamatsu S9119-01 of the prototype is broader than Lambert's cosine (0.555
vs 0.500 at 60 deg, 0.240 vs 0.174 at 80 deg). Its response is the polynomial
fit distributed with the paper's reference code (``data/S9119-01-directivity.mat``),
copied with its source and notes to ``optics/data/S9119-01_directivity.json``.
"""

from __future__ import annotations

import enum
import functools
import json
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from typing import Any

import numpy as np

from mincam_render.optics.camera import DirectionalResponse

#: The package's copy of the S9119-01 directivity fit (source and notes inside).
S9119_01_DATA = "data/S9119-01_directivity.json"
#: Angles (deg) of the :class:`DirectionalResponse` table of the S9119-01: every degree.
_TABLE_ANGLES_DEG = np.arange(0.0, 91.0)
#: Last angle (deg) where ``f = total / cos`` is tabulated; held from there to 90 deg.
_LAST_DIVIDED_DEG = 89.0


@dataclass(frozen=True, kw_only=True)
class DirectivityFit:
    """A diode's directivity as a polynomial fit (the record of :data:`S9119_01_DATA`).

    Attributes:
        detector: the diode.
        quantity: what the fit gives (total relative response, cosine included).
        angle_unit: the unit of the polynomial's variable (``"deg"``).
        form: how to evaluate it.
        coefficients: highest power first (``numpy.polyval``).
        valid_range_deg: ``(lo, hi)`` angles of the fit (deg).
        notes: what to know about it.
        source: where it comes from.
    """

    detector: str
    quantity: str
    angle_unit: str
    form: str
    coefficients: tuple[float, ...]
    valid_range_deg: tuple[float, float]
    notes: tuple[str, ...]
    source: str

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> DirectivityFit:
        """The fit of a record as the JSON file holds it."""
        lo, hi = record["valid_range_deg"]
        return cls(
            detector=record["detector"],
            quantity=record["quantity"],
            angle_unit=record["angle_unit"],
            form=record["form"],
            coefficients=tuple(record["coefficients"]),
            valid_range_deg=(lo, hi),
            notes=tuple(record["notes"]),
            source=record["source"],
        )


@functools.cache
def s9119_01_data() -> DirectivityFit:
    """The S9119-01 directivity fit: coefficients, angle unit, source, notes."""
    text = resources.files("mincam_render.optics").joinpath(S9119_01_DATA).read_text()
    return DirectivityFit.from_json(json.loads(text))


def s9119_01_total_response(theta_deg: np.ndarray) -> np.ndarray:
    """Total relative response (cosine included) at ``theta_deg`` from the normal (deg).

    As the paper's code does: the fitted polynomial evaluated at ``|theta|`` and
    divided by its maximum over [0, 90] deg (0.9908 near 6 deg), so the response
    is symmetric and at most 1.

    Args:
        theta_deg: angles from the detector normal, any shape, in [-90, 90] (deg).

    Returns:
        Relative response, same shape, float64.
    """
    coefficients = s9119_01_data().coefficients
    peak = float(np.polyval(coefficients, np.linspace(0.0, 90.0, 9001)).max())
    return np.polyval(coefficients, np.abs(np.asarray(theta_deg, np.float64))) / peak


@functools.cache
def s9119_01_response() -> DirectionalResponse:
    """:class:`DirectionalResponse` of the S9119-01: ``f = total / cos`` every degree.

    ``f`` grows without bound toward 90 deg (the fit stays 0.097 there while the
    cosine goes to 0), so it is held at its 89-degree value (6.3) from 89 to 90
    deg: ``cos * f`` then falls to 0 at grazing incidence instead of 0.097, for
    rays that carry no power through a mask anyway.
    """
    angles = np.minimum(_TABLE_ANGLES_DEG, _LAST_DIVIDED_DEG)
    f = s9119_01_total_response(angles) / np.cos(np.radians(angles))
    return DirectionalResponse(
        angles_deg=tuple(float(a) for a in _TABLE_ANGLES_DEG),
        relative_sensitivity=tuple(float(v) for v in f),
    )


class DiodeResponse(enum.Enum):
    """Angular response of a camera's photodiodes."""

    COSINE = "cosine"  #: Lambert's cosine only
    S9119_01 = "S9119-01"  #: Hamamatsu S9119-01, the paper's prototype

    def directional_response(self) -> DirectionalResponse | None:
        """The camera's ``directional_response``: None for a pure cosine."""
        return s9119_01_response() if self is DiodeResponse.S9119_01 else None
