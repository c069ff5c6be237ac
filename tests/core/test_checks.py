"""The shared scalar checks: what they accept, what they refuse, and what they say."""

import math
import re

import numpy as np
import pytest

from mincam_render.core.checks import check_int, check_number


@pytest.mark.parametrize(
    ("value", "kwargs"),
    [
        (1, {"lo": 1, "hi": 64}),
        (64, {"lo": 1, "hi": 64}),
        (0, {"lo": 0}),
        (-5, {"hi": -5}),
        (2**63 - 1, {"lo": 0, "hi": 2**63, "hi_open": True}),
        (7, {}),
    ],
)
def test_int_within_inclusive_bounds_is_returned(value, kwargs):
    assert check_int("n", value, **kwargs) == value


@pytest.mark.parametrize(
    ("value", "kwargs"),
    [
        (0, {"lo": 1, "hi": 64}),
        (65, {"lo": 1, "hi": 64}),
        (2**63, {"lo": 0, "hi": 2**63, "hi_open": True}),
        (1, {"lo": 1, "lo_open": True}),
        (True, {}),
        (False, {"lo": 0, "hi": 1}),
        (2.0, {}),
        ("3", {}),
        (None, {}),
        (np.int64(3), {}),
        (np.bool_(True), {"numpy": True}),
        (np.float64(3.0), {"numpy": True}),
    ],
)
def test_int_refused(value, kwargs):
    with pytest.raises(ValueError, match=r"^n = .*: allowed an integer"):
        check_int("n", value, **kwargs)


@pytest.mark.parametrize("kind", [np.int8, np.int32, np.int64, np.uint16])
def test_numpy_ints_accepted_only_when_asked_and_returned_as_int(kind):
    got = check_int("n", kind(5), 1, 8, numpy=True)
    assert got == 5 and type(got) is int
    with pytest.raises(ValueError, match="n = "):
        check_int("n", kind(9), 1, 8, numpy=True)


@pytest.mark.parametrize(
    ("value", "kwargs"),
    [
        (0.0, {"lo": 0.0, "hi": 1.0}),
        (1.0, {"lo": 0.0, "hi": 1.0}),
        (3, {"lo": 0.0, "hi": 10.0}),
        (np.float64(0.5), {"lo": 0.0, "hi": 1.0}),  # a float subclass
        (0.5, {"lo": 0.0, "hi": 1.0, "lo_open": True, "hi_open": True}),
        (-1e300, {}),
    ],
)
def test_number_within_inclusive_bounds_is_returned_as_float(value, kwargs):
    got = check_number("x", value, **kwargs)
    assert got == float(value) and type(got) is float


@pytest.mark.parametrize(
    ("value", "kwargs"),
    [
        (-1e-12, {"lo": 0.0, "hi": 1.0}),
        (1.0 + 1e-12, {"lo": 0.0, "hi": 1.0}),
        (0.0, {"lo": 0.0, "hi": 1.0, "lo_open": True}),
        (1.0, {"lo": 0.0, "hi": 1.0, "hi_open": True}),
        (math.nan, {}),
        (math.inf, {"lo": 0.0}),
        (-math.inf, {}),
        (True, {}),
        ("0.5", {}),
        (None, {}),
        (np.float32(0.5), {"lo": 0.0, "hi": 1.0}),
        (np.int64(1), {"lo": 0.0, "hi": 1.0}),
        (np.float32(np.nan), {"numpy": True}),
        (np.bool_(True), {"numpy": True}),
    ],
)
def test_number_refused(value, kwargs):
    with pytest.raises(ValueError, match=r"^x = .*: allowed a (finite )?number"):
        check_number("x", value, **kwargs)


@pytest.mark.parametrize("value", [np.float32(0.25), np.float16(1.0), np.int16(0), np.uint8(1)])
def test_numpy_numbers_accepted_when_asked(value):
    assert check_number("x", value, 0.0, 1.0, numpy=True) == float(value)


MESSAGES = [
    (check_int, ("spp", 0, 1, 1 << 20), {}, "spp = 0: allowed an integer in [1, 2^20]"),
    (
        check_int,
        ("seed", -1, 0, 2**63),
        {"hi_open": True},
        "seed = -1: allowed an integer in [0, 2^63)",
    ),
    (
        check_int,
        ("history", 0, 1),
        {"unit": "frames"},
        "history = 0: allowed an integer >= 1 frames",
    ),
    (check_int, ("k", True), {"hi": 4}, "k = True: allowed an integer <= 4"),
    (check_int, ("k", 2.5), {}, "k = 2.5: allowed an integer"),
    (
        check_number,
        ("blur_mm", math.nan, 0, 16),
        {"unit": "mm"},
        "blur_mm = nan: allowed a number in [0, 16] mm",
    ),
    (
        check_number,
        ("lr", 1.0, 0.0, 1.0),
        {"lo_open": True, "hi_open": True},
        "lr = 1.0: allowed a number in (0, 1)",
    ),
    (
        check_number,
        ("g", 1e13, 1.0, 1e12),
        {"unit": "V/A"},
        "g = 10000000000000.0: allowed a number in [1, 1e+12] V/A",
    ),
    (
        check_number,
        ("dt_s", math.inf, 0),
        {"lo_open": True, "unit": "s"},
        "dt_s = inf: allowed a finite number > 0 s",
    ),
    (
        check_number,
        ("t", 0.0),
        {"hi": 0.0, "hi_open": True},
        "t = 0.0: allowed a finite number < 0",
    ),
]


@pytest.mark.parametrize(("check", "args", "kwargs", "message"), MESSAGES)
def test_message_names_argument_value_range_and_unit_on_one_line(check, args, kwargs, message):
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        check(*args, **kwargs)
