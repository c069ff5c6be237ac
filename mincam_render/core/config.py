"""Reading declarative scene descriptions (TOML) into validated, frozen dataclasses.

A description class is a frozen, keyword-only dataclass whose fields carry
metadata ``{"unit": "m", "range": (lo, hi), "doc": "..."}``. :func:`parse` maps a
TOML table onto it, recursing into nested dataclasses and tuples of them, and
rejects unknown keys, wrong types and out-of-range values with a
:class:`ConfigError` naming the file, the field path and the reason.

A description class also derives from :class:`Described`, so the ``spec``
ranges hold however an instance is made: from a file, by direct construction
or by ``dataclasses.replace`` (all three run ``__post_init__``). Why this, and
not pydantic or attrs: the ranges are already data on the fields (``spec``),
read by :func:`parse`, the docs and the CLI; a check generated from that same
data cannot drift from them, and it keeps the descriptions plain stdlib
dataclasses (``dataclasses.fields``/``replace``/``asdict`` and
:func:`to_dict` work unchanged, and showing the defaults imports nothing new).
"""

from __future__ import annotations

import dataclasses
import enum
import math
import os
import tomllib
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from mincam_render.core.checks import check_number

T = TypeVar("T")

#: A TOML table as :mod:`tomllib` reads it (a scene description or a part of
#: one): free-form by design, its schema is the dataclass :func:`parse` reads it into.
TomlTable = dict[str, Any]
#: Values replacing a scene description's (``--set KEY=VALUE``, a scene file's
#: overrides): a partial :data:`TomlTable`, nested by the dotted keys.
SceneOverrides = TomlTable


class ConfigError(ValueError):
    """A scene description is malformed; the message names file, field and reason."""


def spec(
    default: Any = dataclasses.MISSING,
    *,
    unit: str = "",
    range: tuple | None = None,  # noqa: A002
    doc: str = "",
    default_factory: Any = dataclasses.MISSING,
) -> Any:
    """A dataclass field with unit, allowed range and documentation metadata."""
    md = {"unit": unit, "range": range, "doc": doc}
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=md)
    return dataclasses.field(default=default, metadata=md)


def check_ranges(obj: object) -> None:
    """Raise ``ValueError`` naming the first field of ``obj`` outside its ``spec`` range.

    Numbers are checked, and each number of a tuple field (as :func:`parse`
    checks them); None, booleans, strings and nested descriptions are not (a
    nested description checked itself when it was made).

    Args:
        obj: a dataclass instance whose fields carry ``spec`` metadata.

    Raises:
        ValueError: ``"<field> = <value>: allowed a number in [lo, hi] <unit>"``.
    """
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        rng = f.metadata.get("range")
        if rng is None:
            continue
        value = getattr(obj, f.name)
        named = (
            [(f"{f.name}[{i}]", v) for i, v in enumerate(value)]
            if isinstance(value, tuple)
            else [(f.name, value)]
        )
        for name, v in named:
            if isinstance(v, int | float) and not isinstance(v, bool):
                check_number(name, v, *rng, unit=f.metadata.get("unit", ""))


class Described:
    """Base of the description dataclasses: their ``spec`` ranges hold however they are made.

    Each subclass's ``__post_init__`` (its own, an inherited one, or none) is
    wrapped so that :func:`check_ranges` runs first; the class's own checks
    (relations between fields) follow. ``dataclasses.replace`` and direct
    construction run ``__post_init__`` as :func:`parse` does, so
    ``dataclasses.replace(WorkspaceConfig(), max_depth=999)`` raises
    ``ValueError`` naming ``max_depth``.
    """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = getattr(cls, "__post_init__", None)

        def __post_init__(self: Any) -> None:
            check_ranges(self)
            if own is not None:
                own(self)

        __post_init__.__doc__ = "Check the ``spec`` ranges, then the class's own checks."
        cls.__post_init__ = __post_init__  # type: ignore[attr-defined]


def check_min_max(config: object, *names: str) -> None:
    """Raise ValueError where a ``(min, max)`` field of ``config`` has min above max."""
    for name in names:
        lo, hi = getattr(config, name)
        if lo > hi:
            raise ValueError(f"{name} = {[lo, hi]}: min must not exceed max")


def _fail(source: str, path: str, value: Any, reason: str) -> ConfigError:
    return ConfigError(f"{source}: {path} = {value!r}: {reason}")


def _check_range(source: str, path: str, value: Any, md: Mapping[str, Any]) -> None:
    rng = md.get("range")
    unit = md.get("unit", "")
    if rng is not None and isinstance(value, int | float) and not isinstance(value, bool):
        lo, hi = rng
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise _fail(source, path, value, f"allowed range [{lo}, {hi}] {unit}".rstrip())


def _convert(
    source: str, path: str, tp: Any, value: Any, md: dict, base_dir: Path | None = None
) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors: list[ConfigError] = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _convert(source, path, a, value, md, base_dir)
            except ConfigError as err:
                errors.append(err)
        raise errors[-1] if len(errors) == 1 else _fail(source, path, value, "no allowed type fits")
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise _fail(source, path, value, f"expected a table of {tp.__name__} fields")
        return parse(tp, value, source=source, path=path, base_dir=base_dir)
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise _fail(source, path, value, "expected an array")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(
                _convert(source, f"{path}[{i}]", args[0], v, md, base_dir)
                for i, v in enumerate(value)
            )
        if len(value) != len(args):
            raise _fail(source, path, value, f"expected an array of {len(args)} values")
        return tuple(
            _convert(source, f"{path}[{i}]", a, v, md, base_dir)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        )
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise _fail(source, path, value, f"expected a number{_unit(md)}")
        if not math.isfinite(float(value)):
            raise _fail(source, path, value, "expected a finite number")
        _check_range(source, path, float(value), md)
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _fail(source, path, value, "expected an integer")
        _check_range(source, path, value, md)
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise _fail(source, path, value, "expected true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise _fail(source, path, value, "expected a string")
        return value
    if tp is Path:
        if not isinstance(value, str | Path) or not str(value):
            raise _fail(source, path, value, "expected a file path (a string)")
        # relative to the description's folder, so a description and its files move together
        return Path(value) if base_dir is None else (base_dir / value).resolve()
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            allowed = ", ".join(repr(m.value) for m in tp)
            raise _fail(source, path, value, f"allowed values: {allowed}") from None
    raise _fail(source, path, value, f"unsupported field type {tp!r}")


def _unit(md: dict) -> str:
    return f" in {md['unit']}" if md.get("unit") else ""


def parse(
    cls: type[T],
    table: dict,
    *,
    source: str = "<dict>",
    path: str = "",
    base_dir: Path | None = None,
) -> T:
    """Build ``cls`` from a TOML table, validating keys, types and ranges.

    ``base_dir``: the folder relative file paths (fields typed ``Path``) are
    resolved against, the description file's; None keeps them as given.

    Raises:
        ConfigError: unknown key, missing required key, wrong type or range, or
            a ``ValueError`` raised by the class's own ``__post_init__``.
    """
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(typing.cast(Any, cls)) if f.init}
    prefix = f"{path}." if path else ""
    unknown = sorted(set(table) - set(fields))
    if unknown:
        raise ConfigError(
            f"{source}: unknown key '{prefix}{unknown[0]}' in {cls.__name__}; allowed: "
            f"{', '.join(sorted(fields))}"
        )
    kwargs = {}
    for name, f in fields.items():
        if name not in table:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ConfigError(f"{source}: missing required key {prefix}{name}")
            continue
        value = table[name]
        default = _default_of(f)
        if isinstance(value, dict) and _is_instance(default):
            # a partial table overlays the field's default: [camera] detectors = 16
            value = merge(_as_table(default), value)
        kwargs[name] = _convert(
            source, f"{prefix}{name}", hints[name], value, dict(f.metadata), base_dir
        )
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except ValueError as err:
        raise ConfigError(f"{source}: {prefix.rstrip('.') or cls.__name__}: {err}") from None


def _default_of(f: dataclasses.Field) -> Any:
    """A field's default value (built from its factory), or ``dataclasses.MISSING``."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def _is_instance(value: Any) -> bool:
    """Whether ``value`` is a dataclass instance (not a dataclass type)."""
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _as_table(obj: Any) -> TomlTable:
    """A dataclass instance as the table :func:`parse` reads back into an equal instance."""
    return {
        f.name: _as_table(v) if _is_instance(v := getattr(obj, f.name)) else v
        for f in dataclasses.fields(obj)
        if f.init
    }


def load_toml(cls: type[T], path: str | os.PathLike, overrides: dict | None = None) -> T:
    """Read a TOML file into ``cls``; ``overrides`` (nested dict) replace file values."""
    path = Path(path)
    try:
        table = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: scene description not found") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    if overrides:
        table = merge(table, overrides)
    return parse(cls, table, source=str(path), base_dir=path.parent)


def merge(base: dict, over: dict) -> dict:
    """Recursively overlay ``over`` on ``base`` (new dict)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def to_dict(obj: Any) -> Any:
    """JSON-ready dict of a description (enums as values, tuples as lists).

    A description may leave out fields that are off (``description_omits()``,
    e.g. an unused option added after a dataset format): resolved descriptions,
    and so dataset identities and fidelity-plan keys, stay as they were.
    """
    if dataclasses.is_dataclass(obj):
        omits: tuple[str, ...] = getattr(obj, "description_omits", tuple)()
        return {
            f.name: to_dict(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if f.name not in omits
        }
    if isinstance(obj, tuple | list):
        return [to_dict(v) for v in obj]
    if isinstance(obj, __import__("enum").Enum):
        return obj.value
    if isinstance(obj, Path):
        return str(obj)
    return obj
