"""Find a family by name or description file and instantiate it."""

from __future__ import annotations

import importlib
import os
import tomllib
from pathlib import Path
from typing import Any

from mincam_render.core.config import ConfigError, merge, parse
from mincam_render.core.package_data import shipped_path
from mincam_render.scenes.base import SceneFamily

#: family name -> "module:Class"
_FAMILIES = {
    "patches": "mincam_render.scenes.patches:PatchesFamily",
    "workspace": "mincam_render.scenes.workspace:WorkspaceFamily",
    "lighting": "mincam_render.scenes.lighting:LightingFamily",
    "traffic": "mincam_render.scenes.traffic:TrafficFamily",
}
FAMILY_NAMES = tuple(_FAMILIES)


def family_class(name: str) -> type[SceneFamily]:
    """The class implementing family ``name``."""
    if name not in _FAMILIES:
        raise ConfigError(f"unknown scene family {name!r}; known: {', '.join(FAMILY_NAMES)}")
    module, cls = _FAMILIES[name].split(":")
    return getattr(importlib.import_module(module), cls)


def load_family(
    name_or_path: str | os.PathLike,
    *,
    seed: int,
    num_frames: int,
    overrides: dict | None = None,
) -> SceneFamily:
    """Instantiate a family from a shipped name (``"workspace"``) or a TOML path.

    The TOML's top-level ``family`` key names the family; the rest is the
    family's description. ``overrides`` (nested dict) replace file values.

    Raises:
        ConfigError: missing file, unknown family, or an invalid description.
    """
    path = Path(name_or_path)
    if str(name_or_path) in _FAMILIES:
        path = shipped_path(f"{name_or_path}.toml")
    if not path.is_file():
        raise ConfigError(
            f"{path}: scene description not found (give a family name: "
            f"{', '.join(FAMILY_NAMES)}, or a .toml path)"
        )
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    family = table.pop("family", None)
    if not isinstance(family, str):
        raise ConfigError(
            f'{path}: missing top-level key family = "<name>" ({", ".join(FAMILY_NAMES)})'
        )
    cls = family_class(family)
    config: Any = parse(cls.config_type, merge(table, overrides or {}), source=str(path))
    return cls(config, seed=seed, num_frames=num_frames)
