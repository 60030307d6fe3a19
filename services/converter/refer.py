"""Names of queued orders, spelled out in the aliases that say `{order}`.

An order of label `queue` names a queued order with a slot of type order: "cancel
{order}". A name is the words of a case ("kitchen", "left") or of an order without cases
("take a picture"), as the loaded orders say them, without numbers; its key is that case's
or order's name, which the supervisor matches against the queue, whatever language the
words are in. Once every file is loaded, each alias with such a slot becomes one command
per name (per pair of names, for a second slot `like` the first), so that the parser, the
recogniser's grammar and the suggestions see ordinary phrases: a name is heard and
judged exactly as a command's words are.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

from voicectl.shared.edits import QUEUE_LABEL

from .expand import SlotRef, expand
from .model import Command
from .orders_file import command
from .patterns import PLACEHOLDER
from .slots import OrderSlot


@dataclass(frozen=True)
class Name:
    """What people call queued orders of one case (or one order without cases)."""

    key: str
    """The case's name ('kitchen'), or the order's: what the supervisor matches."""
    phrases: tuple[str, ...]
    """The words, as the aliases say them ('kitchen'; 'take a picture', 'take photo')."""
    description: str
    """How an edit's description shows it ('kitchen', 'take picture')."""
    orders: frozenset[str]
    """The orders of which it is a case: two names of one of them make a correction."""


def names_of(commands: Iterable[Command]) -> dict[str, Name]:
    """Every name of the loaded orders (not of the queue's own), by key, in file order."""
    found: dict[str, Name] = {}
    for made in commands:
        order, case = made.order, made.case
        if order.label == QUEUE_LABEL or made.refs:
            continue
        key = case.name if case is not None else order.name
        known = found.get(key)
        orders = frozenset([order.name]) if case is not None else frozenset()
        phrases = _phrases(case.alias, made) if case is not None else _whole(made)
        if known is None:
            described = case.description if case is not None else order.description
            found[key] = Name(key, phrases, _plain(described), orders)
        else:
            joined = tuple(dict.fromkeys([*known.phrases, *phrases]))
            found[key] = replace(known, phrases=joined, orders=known.orders | orders)
    return {key: name for key, name in found.items() if name.phrases or name.orders}


def _whole(made: Command) -> tuple[str, ...]:
    """An order without cases, by all its words: only if none is a number."""
    if not made.expansion.finite or made.slots:
        return ()
    return tuple(" ".join(str(word) for word in template) for template in made.expansion.templates)


def _phrases(alias: str, made: Command) -> tuple[str, ...]:
    """A case by its own words: the command's phrases less the order's words before them,
    when the case's alias says no number."""
    if not made.expansion.finite or PLACEHOLDER.search(alias):
        return ()
    try:
        expansion = expand(alias)
    except re.error:
        return ()
    if not expansion.finite:
        return ()
    return tuple(
        " ".join(str(word) for word in template)
        for template in expansion.templates
        if template and not any(isinstance(word, SlotRef) for word in template)
    )


def _plain(description: str) -> str:
    """A description without its slots' placeholders ('forward {distance} m' never
    reaches here: names have no numbers)."""
    return " ".join(PLACEHOLDER.sub("", description).split())


def spelled(templates: Sequence[Command], names: dict[str, Name]) -> list[Command]:
    """Every command the templates make, one per name (or pair of names) in each of
    their order slots."""
    made: list[Command] = []
    for template in templates:
        for chosen in _choices(list(template.refs.values()), names):
            made.append(_spell(template, chosen))
    return made


def _choices(refs: list[OrderSlot], names: dict[str, Name]) -> Iterable[dict[str, Name]]:
    if len(refs) == 1:
        (ref,) = refs
        return ({ref.name: name} for name in names.values() if name.phrases)
    first, second = sorted(refs, key=lambda ref: bool(ref.like))
    return (
        {first.name: one, second.name: other}
        for one, other in itertools.permutations(names.values(), 2)
        if one.phrases and other.phrases and one.orders & other.orders
    )


def _spell(template: Command, chosen: dict[str, Name]) -> Command:
    """`template` with each order slot replaced by the words of its name, and the name's
    key written where the slot says (`to`)."""

    def words(alias: str) -> str:
        def name(found: re.Match[str]) -> str:
            picked = chosen.get(found[1])
            if picked is None:
                return found[0]
            # Plain spaces between words: skip words may stand there, as in any alias.
            return "(?:" + "|".join(_regex(phrase) for phrase in picked.phrases) + ")"

        return PLACEHOLDER.sub(name, alias)

    def described(text: str) -> str:
        return PLACEHOLDER.sub(
            lambda found: chosen[found[1]].description if found[1] in chosen else found[0], text
        )

    refs = template.refs
    order, case = template.order, template.case
    keys = {slot: (refs[slot].to, name.key) for slot, name in chosen.items()}
    spelt_order = replace(
        order,
        alias=words(order.alias),
        description=described(order.description),
        refs={},
        values={**order.values, **dict(v for s, v in keys.items() if s in order.refs)},
    )
    spelt_case = None
    if case is not None:
        spelt_case = replace(
            case,
            alias=words(case.alias),
            description=described(case.description),
            refs={},
            values={**case.values, **dict(v for s, v in keys.items() if s not in order.refs)},
        )
    return command(spelt_order, spelt_case)


def _regex(phrase: str) -> str:
    return " ".join(re.escape(word) for word in phrase.split())
