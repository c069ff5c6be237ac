"""Layer 3 -- scene families: declarative descriptions (``scenes/*.toml``) -> frames + labels."""

from mincam_render.scenes.base import CameraMount, SceneFamily, View
from mincam_render.scenes.registry import FAMILY_NAMES, load_family

__all__ = [
    "FAMILY_NAMES",
    "CameraMount",
    "SceneFamily",
    "View",
    "load_family",
]
