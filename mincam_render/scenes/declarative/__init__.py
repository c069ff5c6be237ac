"""The declarative family of a user's Mitsuba scene (``family = "mitsuba"``).

One concept a module, each importing only those before it: ``config`` (the
description: movers, switched emitters, labels), ``motion`` (where the movers
are and which emitters are on, frame by frame), ``layout`` (what is read from
the loaded scene, and the checks that need it) and ``family``
(:class:`MitsubaFamily`).
"""

from mincam_render.scenes.declarative.config import (
    Axis,
    Box,
    EmitterSwitch,
    LabelDescription,
    LabelRule,
    MitsubaConfig,
    Mover,
)
from mincam_render.scenes.declarative.family import MitsubaFamily

__all__ = [
    "Axis",
    "Box",
    "EmitterSwitch",
    "LabelDescription",
    "LabelRule",
    "MitsubaConfig",
    "MitsubaFamily",
    "Mover",
]
