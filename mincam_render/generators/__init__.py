"""Scene families: declarative descriptions (``scenes/*.toml``) -> frames + labels."""

from .base import CameraMount, LabelKind, LabelSpec, SceneFamily, View
from .registry import FAMILY_NAMES, SCENES_DIR, load_family

__all__ = [
    "FAMILY_NAMES",
    "SCENES_DIR",
    "CameraMount",
    "LabelKind",
    "LabelSpec",
    "SceneFamily",
    "View",
    "load_family",
]
