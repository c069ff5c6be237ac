"""Find a scene family -- shipped, registered by another package, or named by its class.

A description (TOML) names its family in the top-level key ``family``, and the
command line takes the same references wherever it takes a family:

- a shipped task family: ``patches``, ``workspace``, ``lighting``, ``traffic``
  (each with its description ``scenes/<name>.toml``, package data), or
  ``mitsuba``, the declarative family of a user's Mitsuba scene
  (:mod:`mincam_render.scenes.declarative`);
- a family another installed package registers in the entry-point group
  ``mincam_render.families`` (its ``pyproject.toml``:
  ``[project.entry-points."mincam_render.families"]`` ``shelf =
  "shelfpkg.family:ShelfFamily"``), read with :mod:`importlib.metadata`;
- ``"module:Class"``, a :class:`~mincam_render.scenes.base.SceneFamily` subclass
  importable here (installed, or on ``PYTHONPATH``).

A family given by name alone, without a description, is its description
class's defaults. Datasets record :func:`family_reference`, so their worker
processes find the same class again.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import inspect
import logging
import os
import re
import tomllib
from pathlib import Path
from typing import Any

from mincam_render.core.config import ConfigError, merge, parse
from mincam_render.core.package_data import shipped_path
from mincam_render.scenes.base import SceneFamily

log = logging.getLogger(__name__)

#: The shipped task families, each with its description ``scenes/<name>.toml``.
_SHIPPED = {
    "patches": "mincam_render.scenes.patches:PatchesFamily",
    "workspace": "mincam_render.scenes.workspace:WorkspaceFamily",
    "lighting": "mincam_render.scenes.lighting:LightingFamily",
    "traffic": "mincam_render.scenes.traffic:TrafficFamily",
}
#: Every family of this package: the task families and the declarative ``mitsuba``.
_BUILT_IN = {**_SHIPPED, "mitsuba": "mincam_render.scenes.declarative.family:MitsubaFamily"}
#: The shipped task families' names.
FAMILY_NAMES = tuple(_SHIPPED)
#: The entry-point group through which other packages register families.
ENTRY_POINT_GROUP = "mincam_render.families"
_CLASS_REFERENCE = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")


def registered_families() -> dict[str, importlib.metadata.EntryPoint]:
    """``{name: entry point}`` of the families installed packages register.

    A registered name that is a built-in family's is ignored (with a warning):
    the built-in names mean what this package ships.
    """
    found = {}
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _BUILT_IN:
            log.warning("ignoring entry point %s = %s: a built-in family's name", ep.name, ep.value)
        else:
            found[ep.name] = ep
    return found


def known_families() -> tuple[str, ...]:
    """Names a description or the command line may give: built-in, then registered ones."""
    return (*_BUILT_IN, *sorted(registered_families()))


def family_class(reference: str) -> type[SceneFamily]:
    """The class of a family: a built-in or registered name, or ``"module:Class"``.

    Raises:
        ConfigError: an unknown name, a class that cannot be imported, or one that
            is not a concrete :class:`SceneFamily` with a description dataclass.
    """
    if reference in _BUILT_IN:
        target, origin = _BUILT_IN[reference], "built-in family"
    elif _CLASS_REFERENCE.match(reference):
        target, origin = reference, "family class"
    elif (ep := registered_families().get(reference)) is not None:
        target, origin = ep.value, f"entry point {reference!r} of {ENTRY_POINT_GROUP}"
    else:
        raise ConfigError(
            f"unknown scene family {reference!r}; known: {', '.join(known_families())} "
            f'(or "module:Class" of a SceneFamily subclass)'
        )
    cls = _import_class(target, origin)
    _check_family_class(cls, target)
    if origin.startswith("entry point") and cls.name != reference:
        raise ConfigError(
            f"{origin} loads {target}, whose name is {cls.name!r}: register it as {cls.name!r}"
        )
    return cls


def _import_class(target: str, origin: str) -> Any:
    module_name, _, qualname = target.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
    except ImportError as err:
        raise ConfigError(f"{origin} {target}: cannot import {module_name!r} ({err})") from None
    for part in qualname.split("."):
        if not hasattr(obj, part):
            raise ConfigError(f"{origin} {target}: module {module_name!r} has no {qualname!r}")
        obj = getattr(obj, part)
    return obj


def _check_family_class(cls: Any, target: str) -> None:
    """ConfigError unless ``cls`` is a concrete family with a name and a description class."""
    if not (isinstance(cls, type) and issubclass(cls, SceneFamily)):
        raise ConfigError(f"{target} is not a SceneFamily subclass (mincam_render.scenes)")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(cls.__abstractmethods__))
        raise ConfigError(f"{target} does not implement {missing} (SceneFamily)")
    if not isinstance(getattr(cls, "name", None), str) or not cls.name:
        raise ConfigError(f"{target}: set the class variable name = '<family name>'")
    config_type = getattr(cls, "config_type", None)
    if not (isinstance(config_type, type) and dataclasses.is_dataclass(config_type)):
        raise ConfigError(f"{target}: set the class variable config_type to a dataclass")


def family_reference(cls: type[SceneFamily]) -> str:
    """How a dataset names ``cls`` so another process finds it: its name, or ``module:Class``.

    The name where it leads back to ``cls`` (built-in or registered), else
    ``"module:Class"``.
    """
    try:
        if family_class(cls.name) is cls:
            return cls.name
    except ConfigError:
        pass
    return f"{cls.__module__}:{cls.__qualname__}"


def load_family(
    name_or_path: str | os.PathLike,
    *,
    seed: int,
    num_frames: int,
    overrides: dict | None = None,
) -> SceneFamily:
    """Instantiate a family from a name, a ``"module:Class"`` or a description (TOML) path.

    A description's top-level ``family`` key names the family; the rest is the
    family's description (file paths in it are relative to its folder). A
    shipped name reads its shipped description; any other name or class its
    description class's defaults. ``overrides`` (nested dict) replace values.

    Raises:
        ConfigError: missing file, unknown family, or an invalid description.
    """
    source, table, base_dir = _description(name_or_path)
    family = table.pop("family", None)
    if not isinstance(family, str):
        raise ConfigError(
            f'{source}: missing top-level key family = "<name>" '
            f'({", ".join(known_families())}, or "module:Class")'
        )
    cls = family_class(family)
    config: Any = parse(
        cls.config_type, merge(table, overrides or {}), source=source, base_dir=base_dir
    )
    try:
        return cls(config, seed=seed, num_frames=num_frames)
    except ConfigError as err:  # a check that needs the scene, e.g. an id it lacks
        raise ConfigError(f"{source}: {err}") from None


def _description(name_or_path: str | os.PathLike) -> tuple[str, dict, Path | None]:
    """``(source, table, folder of its file paths)`` of a family name, class or TOML path."""
    name = str(name_or_path)
    path = shipped_path(f"{name}.toml") if name in _SHIPPED else Path(name_or_path)
    if not path.is_file():
        if name in _BUILT_IN or _CLASS_REFERENCE.match(name) or name in registered_families():
            return name, {"family": name}, None
        raise ConfigError(
            f"{path}: scene description not found (give a family name: "
            f"{', '.join(known_families())}, a module:Class, or a .toml path)"
        )
    try:
        table = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the scene description ({err})") from None
    return str(path), table, path.resolve().parent
