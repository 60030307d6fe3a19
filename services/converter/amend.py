"""Corrections: an order made again with another number or another case, as a `replace`
edit says ("go forward two meters, no, three"; "not the kitchen, the bathroom").

The order is made again by its own command, so the correction passes through the same
slots, bounds and cases as the words it replaces would have: "no, thirty" for a drive of
at most 10 m is refused with the range, "no, the bathroom" for a turn is refused, and a
turn of 45 degrees corrected to the right stays 45 degrees.
"""

from __future__ import annotations

from collections.abc import Iterable

from voicectl.shared.edits import ReplaceEdit, UnitKind
from voicectl.shared.errors import VoicectlError
from voicectl.shared.messages import Order

from .model import Command
from .slots import SlotSpec, SlotValueError, format_value

_KINDS = {"length": "a length", "angle": "an angle", "time": "a time", "count": "a number"}


class AmendRefused(VoicectlError, ValueError):
    """A correction that does not fit the order it corrects; the text says why."""


class Amender:
    """Makes orders again with the commands that made them; build once per order set."""

    def __init__(self, commands: Iterable[Command]) -> None:
        self._commands = {(c.order.name, c.case.name if c.case else None): c for c in commands}

    def amend(self, order: Order, change: ReplaceEdit) -> Order:
        """`order` as `change` says it should have been; AmendRefused saying why not."""
        made = self._commands.get((order.order, order.case))
        if made is None:
            raise AmendRefused(f"'{order.description}' is not an order of these orders files")
        if change.instead is not None:
            return self._instead(made, order, change.instead)
        assert change.value is not None  # one or the other (ReplaceEdit)
        return self._value(made, order, change.value, change.unit)

    def _value(self, made: Command, order: Order, value: float, unit: UnitKind) -> Order:
        if not made.slots:
            raise AmendRefused(f"'{order.description}' has no number to change")
        if len(made.slots) > 1:
            raise AmendRefused(f"'{order.description}' has several numbers: say it all again")
        ((name, slot),) = made.slots.items()
        if unit and slot.unit.kind != unit:
            raise AmendRefused(
                f"'{order.description}' takes {_KINDS.get(slot.unit.kind, 'a number')}, "
                f"not {_KINDS[unit]}"
            )
        try:
            return made.to_order({name: format_value(value)})
        except SlotValueError as exc:
            raise AmendRefused(str(exc)) from None

    def _instead(self, made: Command, order: Order, case: str) -> Order:
        other = self._commands.get((order.order, case))
        if other is None or other.case is None:
            raise AmendRefused(f"'{order.description}' has no {case.replace('_', ' ')}")
        spoken: dict[str, str | None] = {}
        for name in other.slots:
            said = made.slots.get(name)
            if said is None:
                raise AmendRefused(f"say the whole order: '{other.order.description}' needs {name}")
            spoken[name] = format_value(said_value(said, order))
        try:
            return other.to_order(spoken)
        except SlotValueError as exc:
            raise AmendRefused(str(exc)) from None


def said_value(slot: SlotSpec, order: Order) -> float:
    """The number a person said for `slot` to make `order`: what the slot stored, back in
    the unit they said it in."""
    pose = order.target_pose
    if slot.to in ("x", "y", "yaw") and pose is not None:
        stored = float(getattr(pose, slot.to))
    else:
        raw = order.params.get(slot.to, 0.0)
        stored = float(raw) if isinstance(raw, int | float) else 0.0
    value = stored / (slot.unit.factor * slot.sign)
    return round(value, 9)
