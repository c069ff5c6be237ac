"""Option types, callbacks and decorators shared by the commands.

Nothing here creates files or imports torch or Mitsuba: options are parsed (and
``--help`` shown) before any of that.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click

from mincam_render.core.config import SceneOverrides


class FiniteFloat(click.FloatRange):
    """A float range that also refuses NaN and infinities (click's FloatRange passes NaN)."""

    name = "finite float"

    def convert(
        self, value: Any, param: click.Parameter | None, ctx: click.Context | None
    ) -> float:
        """The float, or a usage error naming the option."""
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        return number


def vec3(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[float, ...] | None:
    """Callback: ``"x,y,z"`` (metres) -> a tuple of three floats; None stays None."""
    if value is None:
        return None
    try:
        parts = [float(p) for p in value.split(",")]
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not three comma-separated numbers, e.g. 0,0,1"
        ) from None
    if len(parts) != 3:
        raise click.BadParameter(f"{value!r} has {len(parts)} numbers; expected x,y,z (metres)")
    return tuple(parts)


def grid(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, int]:
    """Callback: ``"ROWSxCOLS"`` -> ``(rows, cols)``, each in [1, 64]."""
    try:
        r, c = (int(p) for p in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not ROWSxCOLS, e.g. 4x6") from None
    if not (1 <= r <= 64 and 1 <= c <= 64):
        raise click.BadParameter(f"{value!r}: rows and columns must each be in [1, 64], e.g. 4x6")
    return (r, c)


def optional_grid(
    ctx: click.Context, param: click.Parameter, value: str | None
) -> tuple[int, int] | None:
    """Callback: like :func:`grid`, and None stays None."""
    return None if value is None else grid(ctx, param, value)


def int_list(ctx: click.Context, param: click.Parameter, value: str | None) -> list[int] | None:
    """Callback: ``"1,2,4"`` -> ``[1, 2, 4]`` (each >= 1); None (the default) stays None."""
    if value is None:  # the option's default: decided by the command
        return None
    try:
        out = [int(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not comma-separated integers, e.g. 1,2,4,8"
        ) from None
    if not out or min(out) < 1:
        raise click.BadParameter(f"{value!r}: need integers >= 1")
    return out


def float_list(ctx: click.Context, param: click.Parameter, value: str) -> tuple[float, ...]:
    """Callback: ``"0,0.5,1"`` -> ``(0.0, 0.5, 1.0)``, finite numbers."""
    try:
        out = tuple(float(v) for v in value.split(",") if v.strip())
    except ValueError:
        raise click.BadParameter(
            f"{value!r} is not comma-separated numbers, e.g. 0,0.5,1"
        ) from None
    if not out or not all(math.isfinite(v) for v in out):
        raise click.BadParameter(f"{value!r}: need finite numbers, e.g. 0,0.5,1")
    return out


def grid_list(ctx: click.Context, param: click.Parameter, value: str) -> list[tuple[int, int]]:
    """Callback: ``"2x2,4x4"`` -> ``[(2, 2), (4, 4)]``."""
    try:
        return [grid(ctx, param, v.strip()) for v in value.split(",") if v.strip()]
    except click.BadParameter:
        raise click.BadParameter(f"{value!r} is not a list of ROWSxCOLS, e.g. 2x2,4x4") from None


def scene_settings(
    ctx: click.Context, param: click.Parameter, values: tuple[str, ...]
) -> SceneOverrides:
    """Callback: repeated ``KEY=VALUE`` (TOML values, dotted keys) -> a nested override dict."""
    import tomllib

    out: SceneOverrides = {}
    for item in values:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise click.BadParameter(f"{item!r} is not KEY=VALUE, e.g. camera.detectors=8")
        try:
            value = tomllib.loads(f"v = {raw}")["v"]
        except tomllib.TOMLDecodeError:
            value = raw  # a bare string
        node = out
        parts = key.strip().split(".")
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = value
    return out


def with_detectors(overrides: SceneOverrides, detectors: int | None) -> SceneOverrides:
    """``overrides`` with ``camera.detectors`` set (the ``--detectors`` shorthand); None: as is.

    Raises:
        click.BadParameter: ``--set camera.detectors`` is given too, with another
            value or not an integer (neither silently wins).
    """
    if detectors is None:
        return overrides
    camera = overrides.get("camera", {})
    if not isinstance(camera, dict):
        raise click.BadParameter(
            f"camera={camera!r} is not a table of camera fields; give one field as "
            "camera.KEY=VALUE",
            param_hint="--set",
        )
    given = camera.get("detectors", detectors)
    if isinstance(given, bool) or not isinstance(given, int):
        raise click.BadParameter(
            f"camera.detectors={given!r}: expected an integer (and --detectors "
            f"{detectors} sets it too: give one of the two)",
            param_hint="--set",
        )
    if given != detectors:
        raise click.BadParameter(
            f"{detectors} disagrees with --set camera.detectors={given}: give one of the two",
            param_hint="--detectors",
        )
    return {**overrides, "camera": {**camera, "detectors": detectors}}


def out_option(help_text: str, default: str | None = None) -> Callable:
    """``--out DIRECTORY``: with a default shown in the help, or required without one.

    The directory is only a path here; the command creates it when it writes.
    """
    given = {"required": True} if default is None else {"default": Path(default)}
    return click.option(
        "--out",
        type=click.Path(file_okay=False, path_type=Path),
        show_default=default is not None or None,
        help=help_text,
        **given,
    )


def apply_options(options: Sequence[Callable]) -> Callable:
    """A decorator applying click ``options`` so that ``--help`` lists them in this order."""

    def decorate(f: Callable) -> Callable:
        for option in reversed(options):
            f = option(f)
        return f

    return decorate


def field_default(cls: type, name: str) -> Any:
    """The default of dataclass ``cls``'s field ``name``: an option filling it shows this."""
    field = {f.name: f for f in dataclasses.fields(cls)}[name]
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    if field.default is dataclasses.MISSING:
        raise ValueError(f"{cls.__name__}.{name} has no default")
    return field.default


#: Where a comparison's training runs run (``pipeline``, ``study``, ``report privacy``).
executor_options = [
    click.option(
        "--train-workers",
        type=click.IntRange(1, 256),
        default=1,
        show_default=True,
        help="Training runs at once, each in a local worker process with its own copy of "
        "the episodes and cores / N torch threads (1 = one after the other in this "
        "process). Every run's figures are the same either way.",
    ),
    click.option(
        "--ray",
        "ray_address",
        default=None,
        metavar="ADDRESS",
        help="Render the episodes and train the runs as Ray tasks on this cluster "
        "('local' starts one; needs the ray extra); the data and every run's files "
        "travel through Ray, no shared file system needed.",
    ),
]
