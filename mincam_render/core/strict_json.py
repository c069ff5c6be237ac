"""Strict JSON: what every file we write holds, readable by any conforming parser.

Python's :mod:`json` writes ``NaN`` and ``Infinity`` by default, which are not
JSON (RFC 8259): JavaScript's ``JSON.parse``, ``jq`` and most other languages'
parsers refuse the file. :func:`dumps` writes a non-finite number as ``null``;
inside an object it also writes why, beside it, as ``"<key>_null_reason"``
(unless the writer already gave a reason), and it logs where it found one: a
value the writer did not expect to be missing is a bug to fix at its source.
Writers that know why a value is missing (the trivial predictor has no
training loss) write ``None`` and their own reason.

Numpy scalars and arrays, enums and tuples become their JSON equivalents, like
the JSON defaults this replaces; anything else is written as its ``str``.
No numpy import: numbers are recognised through :mod:`numbers` and ``tolist``.
"""

from __future__ import annotations

import enum
import json
import logging
import math
import numbers
from typing import Any

log = logging.getLogger(__name__)

#: A JSON object as written to or read from disk (a manifest's record, a frame's
#: state in shard metadata): string keys, JSON values. For records whose schema
#: belongs to their writer (a family's frame state) or that are read before they
#: are validated; a result with a fixed schema is a dataclass instead.
JsonObject = dict[str, Any]

#: Suffix of the key that says why a value beside it is null.
NULL_REASON_SUFFIX = "_null_reason"


def _reason(value: float) -> str:
    return "not a number (NaN)" if math.isnan(value) else f"infinite ({value})"


def to_strict(obj: Any, where: str = "$") -> Any:
    """A copy of ``obj`` that :func:`json.dumps` writes with ``allow_nan=False``.

    Args:
        obj: nested dicts, lists, tuples, numbers (numpy's too), strings, enums.
        where: the JSON path of ``obj`` in the document, for the log.

    Returns:
        The copy: non-finite floats are None (with ``<key>_null_reason`` in a
        dict), numpy values Python ones, enums their values, tuples lists.
    """
    if isinstance(obj, enum.Enum):
        return to_strict(obj.value, where)
    if isinstance(obj, dict):
        return _strict_dict(obj, where)
    if isinstance(obj, list | tuple | set):
        return [to_strict(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    if hasattr(obj, "tolist") and not isinstance(obj, str | bytes):  # numpy arrays and scalars
        return to_strict(obj.tolist(), where)
    if isinstance(obj, bool | str) or obj is None:
        return obj
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        value = float(obj)
        if not math.isfinite(value):
            log.warning("%s = %s written as null (JSON has no such number)", where, value)
            return None
        return obj
    return obj


def _strict_dict(obj: dict, where: str) -> dict:
    out: dict = {}
    for key, value in obj.items():
        name = key.value if isinstance(key, enum.Enum) else key
        out[name] = to_strict(value, f"{where}.{name}")
        reason_key = f"{name}{NULL_REASON_SUFFIX}"
        if out[name] is None and _non_finite(value) and reason_key not in obj:
            out[reason_key] = _reason(float(value))
    return out


def _non_finite(value: Any) -> bool:
    return (
        isinstance(value, numbers.Real)
        and not isinstance(value, bool)
        and not math.isfinite(float(value))
    )


def dumps(obj: Any, *, indent: int | None = 2, sort_keys: bool = False) -> str:
    """Strict JSON text of ``obj`` (:func:`to_strict`; other objects as their ``str``).

    Raises:
        ValueError: never for numbers (they are made strict first); a circular reference.
    """
    return json.dumps(
        to_strict(obj), indent=indent, sort_keys=sort_keys, allow_nan=False, default=str
    )


def loads(text: str | bytes) -> Any:
    """Parse JSON text as strictly as other languages do: ``NaN`` and ``Infinity`` refused.

    Raises:
        ValueError: not JSON, or a non-finite number in it.
    """

    def refuse(constant: str) -> Any:
        raise ValueError(f"{constant} is not JSON (RFC 8259)")

    return json.loads(text, parse_constant=refuse)
