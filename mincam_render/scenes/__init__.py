"""Layer 3 -- scene families: declarative descriptions (``scenes/*.toml``) -> frames + labels."""

from mincam_render.render.capabilities import (
    DifferentialBackground,
    PeopleRemoval,
    Preview,
    SunlitWindow,
    TemporalLabels,
    View,
)
from mincam_render.scenes.base import CameraMount, SceneFamily
from mincam_render.scenes.registry import FAMILY_NAMES, load_family

__all__ = [
    "FAMILY_NAMES",
    "CameraMount",
    "DifferentialBackground",
    "PeopleRemoval",
    "Preview",
    "SceneFamily",
    "SunlitWindow",
    "TemporalLabels",
    "View",
    "load_family",
]
