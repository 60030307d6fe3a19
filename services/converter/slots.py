"""Typed slots: a spoken number inside an alias, with its unit, bounds and destination.

In an orders file a slot is written ``{name}`` inside a ``voice_alias`` and declared under
``slots``::

    voice_alias: "forward {distance} (meters?|metres?)"
    slots:
      distance: {type: number, unit: m, min: 0.1, max: 5, to: x}

The number may be said in digits ("2.5") or in English words ("two point five");
`text2num` reads the words. The value is checked against the bounds in the unit the person
says, then converted to the base unit of its kind (metres, radians, seconds) and written to
`to`: ``x``, ``y``, ``yaw`` of the target pose or a parameter of the order.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from decimal import Decimal
from enum import StrEnum
from typing import Any

from text_to_num import alpha2digit  # type: ignore[import-untyped]

from voicectl.shared.errors import VoicectlError
from voicectl.shared.messages import ParamValue

MAX_GRID = 1000
"""At most this many spoken values per slot go to the recogniser's grammar."""
MAX_SPOKEN = 999_999


class SlotType(StrEnum):
    NUMBER = "number"
    INTEGER = "integer"
    ORDER = "order"
    """A name of a queued order (`OrderSlot`), for the orders of label `queue`."""


@dataclass(frozen=True)
class Unit:
    """A unit a person may speak a number in, and how it converts to its kind's base unit."""

    name: str
    kind: str
    """length, angle, time or count; the base units are m, rad, s and 1."""
    factor: float
    """Multiply a spoken value by this to get the base unit."""


UNITS = {
    unit.name: unit
    for unit in (
        Unit("m", "length", 1.0),
        Unit("cm", "length", 0.01),
        Unit("mm", "length", 0.001),
        Unit("deg", "angle", math.pi / 180),
        Unit("rad", "angle", 1.0),
        Unit("s", "time", 1.0),
        Unit("ms", "time", 0.001),
        Unit("min", "time", 60.0),
        Unit("count", "count", 1.0),
    )
}
POSE_UNIT_KINDS = {"x": "length", "y": "length", "yaw": "angle"}
"""A slot that feeds the target pose must be spoken in a unit of this kind."""

SLOT_KEYS = frozenset({"type", "unit", "min", "max", "to", "sign", "step"})
ORDER_SLOT_KEYS = frozenset({"type", "to", "like"})
FORBIDDEN_TARGETS = frozenset({"voice_alias", "label", "description", "cases", "slots", "frame"})

# English number words that text2num reads; "a" only as in "a hundred".
_ONES = [
    "zero",
    "one",
    "two",
    "three",
    "four",
    "five",
    "six",
    "seven",
    "eight",
    "nine",
    "ten",
    "eleven",
    "twelve",
    "thirteen",
    "fourteen",
    "fifteen",
    "sixteen",
    "seventeen",
    "eighteen",
    "nineteen",
]
_TENS = ["twenty", "thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety"]
_SCALES = ("hundred", "thousand")
NUMBER_WORDS = frozenset([*_ONES, "nought", *_TENS, *_SCALES])
SIGN_WORDS = frozenset({"minus", "negative"})

_WORD = "|".join(sorted(NUMBER_WORDS, key=len, reverse=True))
NUMBER_PATTERN = (
    r"(?:(?:minus|negative)\s+|-)?"
    r"(?:\d+(?:\.\d+)?"
    rf"|(?:a\s+(?=(?:hundred|thousand)(?!\S)))?(?:{_WORD})"
    rf"(?:\s+(?:and\s+|point\s+)?(?:{_WORD}))*)"
)
"""One spoken number in normalised text: digits, or a run of number words."""

_DIGITS = re.compile(r"-?\d+(?:\.\d+)?")


def read_number(text: str) -> float | None:
    """The number a run of words or digits says, or None if it is not exactly one number."""
    words = text.split()
    sign = 1.0
    if words and words[0] in SIGN_WORDS:
        sign, words = -1.0, words[1:]
    if words[:1] == ["a"] and words[1:2] in (["hundred"], ["thousand"]):
        words[0] = "one"  # text2num leaves "a hundred" alone
    if not words:
        return None
    digits = alpha2digit(" ".join(words), "en", threshold=0)
    if not _DIGITS.fullmatch(digits):
        return None
    return sign * float(digits)


def say_number(value: float) -> str:
    """English words for `value` that `read_number` reads back ('two point five')."""
    exact = Decimal(repr(value)).normalize()
    sign, rest = ("minus ", -exact) if exact < 0 else ("", exact)
    whole, _, fraction = f"{rest:f}".partition(".")
    words = _say_integer(int(whole))
    if fraction:
        words += " point " + " ".join(_ONES[int(d)] for d in fraction)
    return sign + words


def _say_integer(n: int) -> str:
    if n < 20:
        return _ONES[n]
    if n < 100:
        tens, ones = divmod(n, 10)
        return _TENS[tens - 2] + (f" {_ONES[ones]}" if ones else "")
    if n < 1000:
        hundreds, rest = divmod(n, 100)
        return f"{_ONES[hundreds]} hundred" + (f" {_say_integer(rest)}" if rest else "")
    if n < 1_000_000:
        thousands, rest = divmod(n, 1000)
        return f"{_say_integer(thousands)} thousand" + (f" {_say_integer(rest)}" if rest else "")
    raise ValueError(f"{n} is too large to say (at most {MAX_SPOKEN})")


def format_value(value: float) -> str:
    """A spoken value as a person would write it: 45, 2.5."""
    return f"{value:g}"


class SlotValueError(VoicectlError, ValueError):
    """A spoken value that does not fit its slot; the text says what is allowed."""


@dataclass(frozen=True)
class SlotSpec:
    """One typed number inside an alias."""

    name: str
    type: SlotType
    unit: Unit
    min: float
    """Smallest value a person may say, in `unit`."""
    max: float
    to: str
    """Where the converted value goes: x, y, yaw or a parameter name."""
    sign: int = 1
    """-1 flips the value after conversion ('turn right 45 degrees' is a negative yaw)."""
    step: float = 1.0
    """The recogniser listens for multiples of this within the bounds; typing is not limited."""

    @staticmethod
    def from_dict(name: str, spec: Any) -> SlotSpec:
        """Validate one slot declaration; raise ValueError saying what is wrong and allowed."""
        # {type: number, unit: m, min: 0.1, max: 5, to: x, sign: -1, step: 0.5}
        if not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise ValueError(f"slot name {name!r} must be letters, digits or '_'")
        if not isinstance(spec, dict):
            raise ValueError(f"slot '{name}': expected a mapping, got {type(spec).__name__}")
        unknown = set(spec) - SLOT_KEYS
        if unknown:
            raise ValueError(
                f"slot '{name}': unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
                f"allowed: {', '.join(sorted(SLOT_KEYS))}"
            )
        kind = spec.get("type", "number")
        if kind not in set(SlotType) or kind == SlotType.ORDER:
            raise ValueError(f"slot '{name}': type must be number, integer or order, got {kind!r}")
        slot_type = SlotType(kind)
        unit_name = spec.get("unit", "count")
        if unit_name not in UNITS:
            raise ValueError(
                f"slot '{name}': unknown unit {unit_name!r}; allowed: {', '.join(UNITS)}"
            )
        unit = UNITS[unit_name]
        bounds = [spec.get(key) for key in ("min", "max")]
        if any(b is None for b in bounds):
            raise ValueError(f"slot '{name}': 'min' and 'max' are mandatory (in {unit.name})")
        low, high = (_number(name, key, spec[key]) for key in ("min", "max"))
        if low > high:
            raise ValueError(f"slot '{name}': min {low:g} is above max {high:g}")
        if max(abs(low), abs(high)) > MAX_SPOKEN:
            raise ValueError(
                f"slot '{name}': bounds must be within -{MAX_SPOKEN} and {MAX_SPOKEN} "
                f"(numbers are said up to at most {MAX_SPOKEN})"
            )
        target = spec.get("to", name)
        if not isinstance(target, str) or not target or target in FORBIDDEN_TARGETS:
            raise ValueError(
                f"slot '{name}': 'to' must be x, y, yaw or a parameter name, got {target!r}"
            )
        wanted = POSE_UNIT_KINDS.get(target)
        if wanted is not None and unit.kind != wanted:
            raise ValueError(
                f"slot '{name}': '{target}' needs a unit of {wanted}, got {unit.name} "
                f"({unit.kind}); allowed: "
                + ", ".join(u.name for u in UNITS.values() if u.kind == wanted)
            )
        sign = spec.get("sign", 1)
        if sign not in (1, -1) or isinstance(sign, bool):
            raise ValueError(f"slot '{name}': sign must be 1 or -1, got {sign!r}")
        default_step = 1.0 if slot_type is SlotType.INTEGER else 0.5
        step = _number(name, "step", spec.get("step", default_step))
        if step <= 0 or (slot_type is SlotType.INTEGER and step != int(step)):
            raise ValueError(f"slot '{name}': step must be above 0 (whole for an integer slot)")
        slot = SlotSpec(name, slot_type, unit, low, high, target, int(sign), step)
        count = len(slot.grid(limit=MAX_GRID + 1))
        if count > MAX_GRID:
            raise ValueError(
                f"slot '{name}': more than {MAX_GRID} values between {low:g} and {high:g} in "
                f"steps of {step:g} for the recogniser; raise 'step' or narrow the bounds"
            )
        if count == 0:
            raise ValueError(
                f"slot '{name}': no multiple of step {step:g} between {low:g} and {high:g}"
            )
        return slot

    def grid(self, limit: int = MAX_GRID) -> list[float]:
        """The values the recogniser listens for: multiples of `step` within the bounds."""
        step = Decimal(repr(self.step))
        first = math.ceil(Decimal(repr(self.min)) / step)
        last = math.floor(Decimal(repr(self.max)) / step)
        return [float(k * step) for k in range(first, min(last, first + limit - 1) + 1)]

    def heard(self, limit: int = MAX_GRID) -> list[float]:
        """The values the recogniser listens for: the grid and every whole number, from zero
        (or twice a negative minimum) to twice the maximum. Wider than what is allowed on
        purpose: a grammar that listened only within the bounds turned a spoken "ten metres"
        into its nearest allowed neighbour, "two"; heard as itself, it is refused with the
        range instead."""
        low = min(0.0, 2 * self.min)
        high = max(0.0, 2 * self.max)
        step = Decimal(repr(self.step))
        multiples = {
            float(k * step)
            for k in range(
                math.ceil(Decimal(repr(low)) / step), math.floor(Decimal(repr(high)) / step) + 1
            )
        }
        whole = set(map(float, range(math.ceil(low), math.floor(high) + 1)))
        values = sorted(multiples | whole, key=lambda v: (abs(v - self.min) + abs(v - self.max), v))
        return sorted(values[:limit])

    def value(self, spoken: str, read: Callable[[str], float | None] = read_number) -> float:
        """The number `spoken` says (read by `read`, the language's reader), in `unit`;
        raises SlotValueError naming what is allowed."""
        value = read(spoken)
        if value is None:
            raise SlotValueError(f"{self.name}: '{spoken}' is not one number")
        if not self.min <= value <= self.max:
            raise SlotValueError(
                f"{self.name} {format_value(value)} is out of range: "
                f"{format_value(self.min)} to {format_value(self.max)} {self.unit.name}"
            )
        if self.type is SlotType.INTEGER and value != int(value):
            raise SlotValueError(f"{self.name} must be a whole number, got {format_value(value)}")
        return value

    def stored(self, value: float) -> ParamValue:
        """A spoken value as the order carries it: in the base unit, with the sign applied."""
        if self.type is SlotType.INTEGER and self.unit.factor == 1.0:
            return int(value) * self.sign
        return value * self.unit.factor * self.sign


@dataclass(frozen=True)
class OrderSlot:
    """A queued order named inside an alias (`{order}` of "cancel {order}"): the words of
    one of its cases ("kitchen"), or of an order without cases ("take a picture"). The
    converter spells each name out in its place once every file is loaded (refer.py), and
    the order made carries the name's key (the case's or order's name) in `to`."""

    name: str
    to: str
    like: str = ""
    """Another order slot of the same alias: this one then names another case of an order
    that one names ("not {which} {instead}")."""

    @staticmethod
    def from_dict(name: str, spec: dict[str, Any]) -> OrderSlot:
        # {type: order, to: which, like: other}
        unknown = set(spec) - ORDER_SLOT_KEYS
        if unknown:
            raise ValueError(
                f"slot '{name}': unknown key(s) {', '.join(sorted(map(str, unknown)))} for a "
                f"slot of type order; allowed: {', '.join(sorted(ORDER_SLOT_KEYS))}"
            )
        target = spec.get("to", name)
        if not isinstance(target, str) or not target or target in FORBIDDEN_TARGETS:
            raise ValueError(f"slot '{name}': 'to' must be a parameter name, got {target!r}")
        like = spec.get("like", "")
        if not isinstance(like, str):
            raise ValueError(f"slot '{name}': 'like' must name another slot, got {like!r}")
        return OrderSlot(name, target, like)


def slot_from_dict(name: str, spec: Any) -> SlotSpec | OrderSlot:
    """One slot declaration, of any type; ValueError saying what is wrong and allowed."""
    if isinstance(spec, dict) and spec.get("type") == SlotType.ORDER:
        if not re.fullmatch(r"[A-Za-z_]\w*", name):
            raise ValueError(f"slot name {name!r} must be letters, digits or '_'")
        return OrderSlot.from_dict(name, spec)
    return SlotSpec.from_dict(name, spec)


def _number(slot: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"slot '{slot}': '{key}' must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"slot '{slot}': '{key}' must be finite, got {value!r}")
    return float(value)
