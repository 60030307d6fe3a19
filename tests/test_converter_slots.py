"""Typed slots: spoken numbers read with text2num, units, bounds, the recogniser's values."""

from __future__ import annotations

import math
import re
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.converter.slots import (
    MAX_GRID,
    SlotSpec,
    SlotType,
    SlotValueError,
    read_number,
    say_number,
)
from voicectl.services.converter.text import normalise


@pytest.mark.parametrize(
    ("spoken", "value"),
    [
        ("2.5", 2.5),
        ("45", 45.0),
        ("-3", -3.0),
        ("two point five", 2.5),
        ("zero point five", 0.5),
        ("nought point five", 0.5),
        ("ten", 10.0),
        ("one", 1.0),  # text2num leaves small numbers alone unless asked not to
        ("forty five", 45.0),
        ("a hundred", 100.0),
        ("one hundred and twenty", 120.0),
        ("minus three", -3.0),
        ("negative zero point two five", -0.25),
        ("one thousand two hundred", 1200.0),
    ],
)
def test_numbers_are_read_from_digits_and_words(spoken: str, value: float) -> None:
    assert read_number(spoken) == value


@pytest.mark.parametrize(
    "spoken", ["one two three", "five point", "point five", "a", "", "ten and"]
)
def test_anything_but_one_number_is_refused(spoken: str) -> None:
    assert read_number(spoken) is None


def test_hyphenated_words_become_separate_words_first() -> None:
    assert read_number(normalise("Forty-five")) == 45.0


@given(st.integers(min_value=-999_999, max_value=999_999))
def test_every_integer_said_reads_back(number: int) -> None:
    assert read_number(say_number(number)) == number


@given(st.integers(min_value=0, max_value=99_999), st.integers(min_value=1, max_value=99))
def test_decimals_said_read_back(whole: int, hundredths: int) -> None:
    value = whole + hundredths / 100
    assert read_number(say_number(value)) == pytest.approx(value)


def test_numbers_are_said_the_way_people_say_them() -> None:
    assert say_number(2.5) == "two point five"
    assert say_number(0.5) == "zero point five"
    assert say_number(45) == "forty five"
    assert say_number(180.0) == "one hundred eighty"
    assert say_number(-1.05) == "minus one point zero five"


def slot(**spec: Any) -> SlotSpec:
    return SlotSpec.from_dict("angle", {"min": 1, "max": 180, **spec})


def test_degrees_become_radians_and_sign_flips_after_bounds() -> None:
    right = slot(unit="deg", to="yaw", sign=-1)
    assert right.value("ninety") == 90.0
    assert right.stored(90.0) == pytest.approx(-math.pi / 2)


def test_out_of_range_says_the_allowed_range_with_its_unit() -> None:
    distance = SlotSpec.from_dict("distance", {"unit": "m", "min": 0.1, "max": 5, "to": "x"})
    with pytest.raises(SlotValueError, match=r"^distance 7 is out of range: 0.1 to 5 m$"):
        distance.value("seven")
    with pytest.raises(SlotValueError, match="'one two' is not one number"):
        distance.value("one two")


def test_integer_slots_refuse_fractions_and_store_ints() -> None:
    count = SlotSpec.from_dict("count", {"type": "integer", "min": 1, "max": 20})
    assert count.type is SlotType.INTEGER
    assert count.stored(count.value("three")) == 3
    assert isinstance(count.stored(3.0), int)
    with pytest.raises(SlotValueError, match="whole number"):
        count.value("two point five")


def test_minutes_become_seconds() -> None:
    wait = SlotSpec.from_dict("wait", {"unit": "min", "min": 1, "max": 10})
    assert wait.stored(wait.value("two")) == 120.0


def test_grid_lists_multiples_of_step_within_bounds() -> None:
    distance = SlotSpec.from_dict("d", {"unit": "m", "min": 0.1, "max": 2, "step": 0.5})
    assert distance.grid() == [0.5, 1.0, 1.5, 2.0]
    assert SlotSpec.from_dict("n", {"type": "integer", "min": -2, "max": 2}).grid() == [
        -2,
        -1,
        0,
        1,
        2,
    ]


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"unit": "m", "max": 5}, "'min' and 'max' are mandatory"),
        ({"unit": "m"}, "'min' and 'max' are mandatory"),
        ({"min": 1, "max": 2, "unit": "parsec"}, "unknown unit 'parsec'; allowed: m, cm"),
        ({"min": 1, "max": 2, "unit": "m", "to": "yaw"}, "'yaw' needs a unit of angle"),
        ({"min": 1, "max": 2, "unit": "deg", "to": "x"}, "'x' needs a unit of length"),
        ({"min": 3, "max": 2}, "min 3 is above max 2"),
        ({"min": 1, "max": 2, "type": "text"}, "type must be number, integer or order"),
        ({"min": 1, "max": 2, "sign": 2}, "sign must be 1 or -1"),
        ({"min": 1, "max": 2, "to": "label"}, "'to' must be x, y, yaw or a parameter name"),
        ({"min": 1, "max": 2, "colour": "red"}, "unknown key(s) colour; allowed:"),
        ({"min": "one", "max": 2}, "'min' must be a number"),
        ({"min": 0, "max": 10_000, "step": 1}, f"more than {MAX_GRID} values"),
        ({"min": 0.1, "max": 0.2, "step": 1}, "no multiple of step 1"),
        ({"min": 1, "max": 2, "type": "integer", "step": 0.5}, "step must be above 0"),
        ({"min": 0, "max": 2_000_000, "step": 100_000}, "at most 999999"),
        ("fast", "expected a mapping"),
    ],
)
def test_bad_slot_declarations_say_what_is_allowed(spec: Any, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        SlotSpec.from_dict("s", spec)
