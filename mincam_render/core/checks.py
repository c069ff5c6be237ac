"""Checks of scalar arguments: an integer or a finite number within bounds, a plain name.

Every refusal is one ``ValueError`` line naming the argument, its value and what
is allowed, e.g. ``spp = 0: allowed an integer in [1, 2^20]`` or
``mask_blur_mm = nan: allowed a number in [0, 16] mm``. A bool is
never a number here (``True`` is not a sample count). Numpy scalars are
accepted only where the caller asks (``numpy=True``); without it ``check_number``
takes ``int`` and ``float`` (``numpy.float64`` is a ``float``), ``check_int``
only ``int``. The :mod:`numbers` ABCs stand for numpy's scalar types, so this
module imports no numpy.
"""

from __future__ import annotations

import math
import numbers


def check_int(
    name: str,
    value: object,
    lo: int | None = None,
    hi: int | None = None,
    *,
    unit: str = "",
    lo_open: bool = False,
    hi_open: bool = False,
    numpy: bool = False,
) -> int:
    """``value`` as an ``int`` if it is an integer within the bounds, else ``ValueError``.

    Args:
        name: the argument as the message names it (``"TrainConfig.batch_size"``).
        value: what was given.
        lo: lower bound, or None for none.
        hi: upper bound, or None for none.
        unit: shown after the allowed range (``"frames"``).
        lo_open: ``lo`` itself is refused.
        hi_open: ``hi`` itself is refused.
        numpy: numpy integer scalars are accepted too.

    Raises:
        ValueError: a bool, a non-integer, or a value outside the bounds.
    """
    kind = numbers.Integral if numpy else int
    if isinstance(value, bool) or not isinstance(value, kind):
        raise _refuse(name, value, "an integer", lo, hi, unit, lo_open, hi_open)
    v = int(value)
    if not _within(v, lo, hi, lo_open, hi_open):
        raise _refuse(name, value, "an integer", lo, hi, unit, lo_open, hi_open)
    return v


def check_number(
    name: str,
    value: object,
    lo: float | None = None,
    hi: float | None = None,
    *,
    unit: str = "",
    lo_open: bool = False,
    hi_open: bool = False,
    numpy: bool = False,
) -> float:
    """``value`` as a ``float`` if it is a finite number within the bounds, else ``ValueError``.

    Args:
        name: the argument as the message names it (``"TrainConfig.privacy_weight"``).
        value: what was given.
        lo: lower bound, or None for none.
        hi: upper bound, or None for none.
        unit: shown after the allowed range (``"mm"``).
        lo_open: ``lo`` itself is refused.
        hi_open: ``hi`` itself is refused.
        numpy: numpy integer and floating scalars are accepted too.

    Raises:
        ValueError: a bool, a non-number, NaN or infinity, or a value outside the bounds.
    """
    what = "a number" if lo is not None and hi is not None else "a finite number"
    kind = numbers.Real if numpy else int | float
    if isinstance(value, bool) or not isinstance(value, kind):
        raise _refuse(name, value, what, lo, hi, unit, lo_open, hi_open)
    v = float(value)
    if not (math.isfinite(v) and _within(v, lo, hi, lo_open, hi_open)):
        raise _refuse(name, value, what, lo, hi, unit, lo_open, hi_open)
    return v


def check_name(name: str, value: object) -> str:
    """``value`` if it names one file or folder inside another, else ``ValueError``.

    A task or design name becomes a folder below an output directory: one path
    component, so nothing is written outside that directory. Refused: an empty
    name, a path separator (slash or backslash), a NUL byte, and a leading dot
    (``.``, ``..``, hidden files).

    Args:
        name: the argument as the message names it (``"--task"``).
        value: what was given.

    Raises:
        ValueError: not a string, or not a plain name.
    """
    if not (isinstance(value, str) and _plain(value)):
        raise ValueError(
            f"{name} = {value!r}: allowed a plain name (one folder name: no '/', '\\' or "
            "leading '.'), e.g. patches"
        )
    return value


def _plain(value: str) -> bool:
    """One path component: not empty, no separator, NUL, surrounding space or leading dot."""
    unsafe = {"/", "\\", "\0"}
    return value == value.strip() != "" and not value.startswith(".") and not set(value) & unsafe


def _within(v: float, lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> bool:
    above = lo is None or (v > lo if lo_open else v >= lo)
    below = hi is None or (v < hi if hi_open else v <= hi)
    return above and below


def _refuse(
    name: str,
    value: object,
    what: str,
    lo: float | None,
    hi: float | None,
    unit: str,
    lo_open: bool,
    hi_open: bool,
) -> ValueError:
    if lo is not None and hi is not None:
        left, right = "(" if lo_open else "[", ")" if hi_open else "]"
        bounds = f" in {left}{_show(lo)}, {_show(hi)}{right}"
    elif lo is not None:
        bounds = f" {'>' if lo_open else '>='} {_show(lo)}"
    elif hi is not None:
        bounds = f" {'<' if hi_open else '<='} {_show(hi)}"
    else:
        bounds = ""
    return ValueError(f"{name} = {value!r}: allowed {what}{bounds} {unit}".rstrip())


def _show(bound: float) -> str:
    """A bound as people write it: ``2^20`` for a large power of two, else ``%g``."""
    if isinstance(bound, int) and bound >= 1 << 16 and bound & (bound - 1) == 0:
        return f"2^{bound.bit_length() - 1}"
    return str(bound) if isinstance(bound, int) else f"{bound:g}"
