"""Strict JSON: non-finite numbers become null with a reason; parsers of other languages agree."""

from __future__ import annotations

import enum
import json
import math

import numpy as np
import pytest

from mincam_render.core import strict_json


class Colour(enum.Enum):
    RED = "red"


def test_non_finite_numbers_become_null_with_a_reason_beside_them():
    doc = {"loss": float("nan"), "gain": np.float32("inf"), "ok": 1.5, "n": np.int64(3)}
    out = strict_json.loads(strict_json.dumps(doc))
    assert out == {
        "loss": None,
        "loss_null_reason": "not a number (NaN)",
        "gain": None,
        "gain_null_reason": "infinite (inf)",
        "ok": 1.5,
        "n": 3,
    }


def test_a_writers_own_reason_is_kept_and_lists_hold_plain_nulls():
    doc = {"loss": math.nan, "loss_null_reason": "not trained", "xs": [1.0, -math.inf]}
    out = strict_json.loads(strict_json.dumps(doc))
    assert out == {"loss": None, "loss_null_reason": "not trained", "xs": [1.0, None]}


def test_numpy_arrays_enums_and_tuples_are_written_like_json_defaults():
    doc = {"a": np.arange(3, dtype=np.float32), "c": Colour.RED, "t": (1, 2), Colour.RED: 0}
    assert strict_json.loads(strict_json.dumps(doc)) == {
        "a": [0.0, 1.0, 2.0], "c": "red", "t": [1, 2], "red": 0
    }  # fmt: skip


def test_finite_documents_are_written_as_json_writes_them():
    doc = {"b": [1, 2.5, "x", None, True], "a": {"z": 1e-30}}
    for indent, sort_keys in ((2, False), (1, True), (None, False)):
        assert strict_json.dumps(doc, indent=indent, sort_keys=sort_keys) == json.dumps(
            doc, indent=indent, sort_keys=sort_keys
        )


@pytest.mark.parametrize("text", ["NaN", '{"a": Infinity}', "[-Infinity]"])
def test_the_strict_parser_refuses_what_python_would_accept(text):
    json.loads(text)  # Python's own parser takes it
    with pytest.raises(ValueError, match="not JSON"):
        strict_json.loads(text)
