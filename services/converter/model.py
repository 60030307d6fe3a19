"""What an orders file says, once read and checked: orders, their cases, commands."""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from voicectl.shared.messages import Order, ParamValue, TargetPose

from .expand import Expansion
from .language import numbers_of
from .patterns import PLACEHOLDER, combined
from .slots import OrderSlot, SlotSpec, format_value

POSE_KEYS = ("x", "y", "yaw")


@dataclass(frozen=True)
class CaseSpec:
    """One variant of an order ('left' of 'rotation') and what it changes."""

    name: str
    alias: str
    description: str
    values: dict[str, ParamValue]
    slots: dict[str, SlotSpec] = field(default_factory=dict)
    line: int | None = None
    confirm: bool | None = None
    """Overrides the order's `confirm` when set."""
    refs: dict[str, OrderSlot] = field(default_factory=dict)
    """Its slots that name a queued order (orders of label `queue` only)."""


@dataclass(frozen=True)
class OrderSpec:
    """One order as written in an orders file."""

    name: str
    alias: str
    label: str
    description: str
    values: dict[str, ParamValue]
    cases: tuple[CaseSpec, ...] = ()
    source: str = ""
    """The file it came from, for error messages."""
    slots: dict[str, SlotSpec] = field(default_factory=dict)
    line: int | None = None
    confirm: bool = False
    """Read back and wait for a spoken yes before it runs (hands-free listening)."""
    refs: dict[str, OrderSlot] = field(default_factory=dict)
    """Its slots that name a queued order (orders of label `queue` only)."""
    language: str = "en"
    """The language of its file: how its numbers are said and read."""

    def confirms(self, case: CaseSpec | None) -> bool:
        return case.confirm if case is not None and case.confirm is not None else self.confirm

    def target_pose(
        self, case: CaseSpec | None, filled: dict[str, ParamValue] | None = None
    ) -> TargetPose | None:
        merged = self.merged_values(case, filled)
        frame = merged.get("frame")
        if not isinstance(frame, str):
            return None
        pose = {k: float(merged.get(k, 0.0)) for k in POSE_KEYS}
        return TargetPose(frame=frame, **pose)

    def params(
        self, case: CaseSpec | None, filled: dict[str, ParamValue] | None = None
    ) -> dict[str, ParamValue]:
        merged = self.merged_values(case, filled)
        if "frame" in merged:
            return {k: v for k, v in merged.items() if k != "frame" and k not in POSE_KEYS}
        return merged

    def merged_values(
        self, case: CaseSpec | None, filled: dict[str, ParamValue] | None = None
    ) -> dict[str, ParamValue]:
        """The order's values, overridden by the case's, overridden by slot values."""
        return {**self.values, **(case.values if case else {}), **(filled or {})}

    def example(self, case: CaseSpec) -> str:
        """The case's description with an example number for each slot ("forward 0.5 m"),
        for hints: a person reads it, so no raw placeholders."""
        slots = {**self.slots, **case.slots}
        refs = {**self.refs, **case.refs}

        def number(found: re.Match[str]) -> str:
            slot = slots.get(found[1])
            if found[1] in refs:
                return f"[{found[1]}]"  # a name of an order in the queue
            return format_value(slot.grid()[0]) if slot is not None else found[0]

        return PLACEHOLDER.sub(number, case.description)

    def full_description(self, case: CaseSpec | None) -> str:
        return f"{self.description} {case.description}" if case else self.description


@dataclass(frozen=True)
class Command:
    """Something a person can say: an order without cases, or an order and one case.

    Also used for the alias of an order with cases alone, which is not a whole command
    but lets the parser say which cases are missing.
    """

    order: OrderSpec
    case: CaseSpec | None
    aliases: tuple[str, ...]
    """The order's alias, then the case's: said one after the other."""
    slots: dict[str, SlotSpec]
    """The number slots of the pattern, by name."""
    expansion: Expansion
    refs: dict[str, OrderSlot] = field(default_factory=dict)
    """Slots naming a queued order: a command with some is a template, which the
    converter turns into one command per name once every file is loaded (refer.py)."""

    @property
    def name(self) -> str:
        return f"{self.order.name}/{self.case.name}" if self.case else self.order.name

    def pattern(self, skip_words: tuple[str, ...] = ()) -> str:
        """The aliases as one regex with slots as named groups, not yet restricted to whole
        words; `skip_words` may stand wherever the aliases have a space."""
        return combined(self.aliases, numbers_of(self.order.language).pattern, skip_words)

    def to_order(self, spoken: dict[str, str | None]) -> Order:
        """The order this command makes with the slot texts `spoken` (by slot name; None
        for a slot in an optional part that was not said, which then sets nothing).

        Raises SlotValueError when a value is not a number or is out of its bounds.
        """
        filled: dict[str, ParamValue] = {}
        said: dict[str, str] = {}
        read = numbers_of(self.order.language).read
        for name, slot in self.slots.items():
            text = spoken.get(name)
            if text is None:
                continue
            value = slot.value(text, read)
            filled[slot.to] = slot.stored(value)
            said[name] = format_value(value)
        description = PLACEHOLDER.sub(
            lambda m: said.get(m[1], ""), self.order.full_description(self.case)
        )
        description = " ".join(description.split())
        return Order(
            order=self.order.name,
            case=self.case.name if self.case else None,
            label=self.order.label,
            description=description,
            params=self.order.params(self.case, filled),
            target_pose=self.order.target_pose(self.case, filled),
            confirm=self.order.confirms(self.case),
        )
