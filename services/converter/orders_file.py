"""Reading an orders file: YAML with line numbers in, checked orders and commands out.

Checked by hand rather than decoded into a schema: any key of an order or case that is
not one of RESERVED_KEYS is a parameter of the order, so the set of keys is open, and
each problem must name its file, order, case and YAML line in one line a person can
act on. Decoding into msgspec Structs was tried (msgspec 0.22) and not kept: its error
paths drop mapping keys (`$.cases[...].params[...]`), and orders, cases, slots and
parameters are all keyed by name here, so an error could name neither the order nor
the line; it also stops at the first error, where this reports every bad order.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import yaml

from voicectl.shared.edits import QUEUE_LABEL, read_edit
from voicectl.shared.errors import OrdersFileError, VoicectlError
from voicectl.shared.messages import Order, ParamValue

from .expand import SlotRef, expand
from .language import DEFAULT, LANGUAGES, language_of, markers_in, reads_numbers, unreadable
from .model import POSE_KEYS, CaseSpec, Command, OrderSpec
from .patterns import PLACEHOLDER, SLOT_GROUP, SLOT_STUB, check_regex, combined, with_slots
from .slots import OrderSlot, SlotSpec, slot_from_dict
from .text import normalise

RESERVED_KEYS = frozenset({"voice_alias", "label", "description", "cases", "slots", "confirm"})
DEFAULT_SEPARATOR = "then"
DEFAULT_SKIP_WORDS = ("a", "the", "to", "please", "now")
"""Words people add around and inside commands ("please reach the kitchen now"): the
parser ignores them there and the recogniser's grammar makes them optional there."""

_WORDS = re.compile(r"[\w\s'.,{}°-]*")
"""An alias that is words and slots, read as it is; any other regex syntax is not."""

Problem = tuple[str, int | None]
"""One thing wrong, as 'FILE: order NAME: what' and its YAML line when known."""


class OrdersInvalid(OrdersFileError):
    """Orders files that do not validate, with every problem found.

    Its text is the first problem (the one line the CLI prints); `errors` lists them all
    with their YAML lines, for the status a running converter publishes.
    """

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = tuple(problems)
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        super().__init__(problems[0][0] + more)

    @property
    def errors(self) -> tuple[str, ...]:
        return tuple(f"{message}{_at(line)}" for message, line in self.problems)


@dataclass(frozen=True)
class OrdersFile:
    """One file's orders and commands, checked."""

    orders: tuple[OrderSpec, ...]
    commands: list[Command]
    separator: str
    skip_words: tuple[str, ...] | None
    """None when the file does not say."""
    language: str = DEFAULT
    """What its aliases are written in (`language: es`); English when it does not say."""


def read_yaml(text: str, source: str) -> Any:
    """The YAML document, its mappings carrying their lines; one-line error otherwise."""
    try:
        return yaml.load(text, Loader=_LineLoader)  # a SafeLoader that adds line numbers
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{source}:{mark.line + 1}" if mark is not None else source
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise OrdersFileError(f"{where}: invalid YAML: {problem}") from exc


def check_file(data: Any, source: str) -> OrdersFile:
    """The orders of one file's document; OrdersInvalid lists every order that is wrong."""
    if isinstance(data, dict) and "orders_list" in data:
        data = data["orders_list"]
    if not isinstance(data, dict) or not isinstance(data.get("orders"), dict):
        raise OrdersFileError(f"{source}: expected a mapping with an 'orders' mapping")
    unknown = set(data) - {"orders", "separator", "skip_words", "language"}
    if unknown:
        raise OrdersFileError(
            f"{source}: unknown top-level key(s) {', '.join(sorted(map(str, unknown)))}; "
            "allowed: orders, separator, skip_words, language"
        )
    language = _language(data, source)
    if "separator" not in data and not language_of(language).separator:
        where = (
            f"{source}: language {language}: say how its commands are joined "
            "('separator', a regex: \"then\" in English)"
        )
        raise OrdersInvalid([(where, _line(data, "language"))])
    separator = data.get("separator", language_of(language).separator or DEFAULT_SEPARATOR)
    if not isinstance(separator, str) or not separator.strip():
        raise OrdersFileError(f"{source}: 'separator' must be a non-empty string (regex)")
    try:
        check_regex(separator)
    except ValueError as exc:
        where = f"{source}: separator: {exc}"
        raise OrdersInvalid([(where, _line(data, "separator"))]) from exc
    skip_words = _skip_words(data, source)
    orders: list[OrderSpec] = []
    commands: list[Command] = []
    problems: list[Problem] = []
    for name, spec in data["orders"].items():
        try:
            order = _order_from_dict(str(name), spec, source, language)
            commands.extend(_commands(order))
            orders.append(order)
        except _Problem as exc:
            line = exc.line or _line(data["orders"], name)
            problems.append((f"{source}: order '{name}'{exc.where}: {exc}", line))
    if problems:
        raise OrdersInvalid(problems)
    if not orders:
        raise OrdersFileError(f"{source}: 'orders' is empty")
    line = _line(data, "language")
    _check_language(commands, language, source, line)
    _check_numbers(orders, language, source, line)
    return OrdersFile(tuple(orders), commands, separator, skip_words, language)


def _language(data: dict[str, Any], source: str) -> str:
    """The file's `language`: an ISO 639-1 code (two letters), English when absent."""
    language = data.get("language", DEFAULT)
    if not isinstance(language, str) or not re.fullmatch(r"[a-z]{2}", language):
        where = f"{source}: 'language' must be a two-letter code (en, es, de...), got {language!r}"
        raise OrdersInvalid([(where, _line(data, "language"))])
    return language


def _check_language(commands: list[Command], language: str, source: str, line: int | None) -> None:
    """A file whose aliases are plainly in another language than it says is refused: its
    commands would be listened for in the wrong language, and never heard. Told apart by
    the words of the aliases that only one language here uses (`Language.markers`)."""
    words = {
        word for command in commands for alias in command.aliases for word in expand_words(alias)
    }
    found = markers_in(words)
    own = found.get(language, [])
    for other, marks in found.items():
        if other != language and len(marks) >= 2 and len(marks) > len(own):
            said = ", ".join(f"'{w}'" for w in marks[:5])
            ours = LANGUAGES[language].name if language in LANGUAGES else f"'{language}'"
            raise OrdersInvalid(
                [
                    (
                        f"{source}: says language: {language}, but its aliases are "
                        f"{LANGUAGES[other].name} ({said}"
                        + (f"; {ours}: only {', '.join(repr(w) for w in own)}" if own else "")
                        + f"): write language: {other}, or the aliases in {ours}",
                        line,
                    )
                ]
            )


def expand_words(alias: str) -> set[str]:
    """Every word an alias can say (slots aside)."""
    try:
        expansion = expand(with_slots(alias, SLOT_STUB))
    except re.error:
        return set()
    return {word for word in expansion.words if normalise(word) == word}


def _check_numbers(orders: list[OrderSpec], language: str, source: str, line: int | None) -> None:
    """Orders with number slots need their numbers read in the file's language."""
    slots = [
        (order, slot)
        for order in orders
        for slot in [*order.slots.values(), *(s for c in order.cases for s in c.slots.values())]
    ]
    if not slots:
        return
    if not reads_numbers(language):
        order, slot = slots[0]
        raise OrdersInvalid(
            [
                (
                    f"{source}: language {language}: text2num cannot read numbers in it, "
                    f"and order '{order.name}' has the number slot '{slot.name}'",
                    line,
                )
            ]
        )
    for order, slot in slots:
        wrong = unreadable(language, slot.heard())
        if wrong:
            value, said = wrong[0]
            raise OrdersInvalid(
                [
                    (
                        f"{source}: language {language}: text2num does not read '{said}' as "
                        f"{value:g} (order '{order.name}', slot '{slot.name}')",
                        line,
                    )
                ]
            )


class _Problem(VoicectlError):
    """One thing wrong inside an order; the caller adds the file and order names."""

    def __init__(self, message: str, line: int | None = None, where: str = "") -> None:
        super().__init__(message)
        self.line = line
        self.where = where
        """' case NAME' when the problem is inside a case."""


def _at(line: int | None) -> str:
    return f" (line {line})" if line else ""


def _order_from_dict(name: str, spec: Any, source: str, language: str = DEFAULT) -> OrderSpec:
    if not isinstance(spec, dict):
        raise _Problem(f"expected a mapping, got {type(spec).__name__}")
    alias = _required_str(spec, "voice_alias")
    label = _required_str(spec, "label")
    description = spec.get("description", _plain(alias, name))
    if not isinstance(description, str):
        raise _Problem("'description' must be a string", _line(spec, "description"))
    slots, refs = _slots(spec)
    values = _values(spec)
    confirm = _confirm(spec)
    raw_cases = spec.get("cases", {})
    if raw_cases is None:
        raw_cases = {}
    if not isinstance(raw_cases, dict):
        raise _Problem("'cases' must be a mapping of case name to case", _line(spec, "cases"))
    cases = []
    for case_name, case_spec in raw_cases.items():
        try:
            cases.append(_case_from_dict(str(case_name), case_spec))
        except _Problem as exc:
            line = exc.line or _line(raw_cases, case_name)
            raise _Problem(str(exc), line, f" case '{case_name}'") from exc
    order = OrderSpec(
        name=name,
        alias=alias,
        label=label,
        description=description,
        values=values,
        cases=tuple(cases),
        source=source,
        slots=slots,
        line=_line(spec),
        confirm=bool(confirm),
        refs=refs,
        language=language,
    )
    for case in order.cases or (None,):
        at = f" case '{case.name}'" if case else ""
        line = case.line if case else order.line
        merged = order.merged_values(case)
        if "frame" in merged:
            for key in POSE_KEYS:
                value = merged.get(key, 0.0)
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise _Problem(f"'{key}' must be a number, got {value!r}", line, at)
    return order


def _plain(alias: str, name: str) -> str:
    """What a person reads for an order or case without a description: its alias when
    that is words ('reach', 'forward {d} m'), else its name ('pause' for 'wait|pause')."""
    return alias if _WORDS.fullmatch(alias) else name.replace("_", " ")


def _case_from_dict(name: str, spec: Any) -> CaseSpec:
    if not isinstance(spec, dict):
        raise _Problem(f"expected a mapping, got {type(spec).__name__}")
    if "cases" in spec:
        raise _Problem("cases cannot have cases of their own", _line(spec, "cases"))
    if "label" in spec:
        raise _Problem("'label' belongs to the order, not to a case", _line(spec, "label"))
    alias = _required_str(spec, "voice_alias")
    description = spec.get("description", _plain(alias, name))
    if not isinstance(description, str):
        raise _Problem("'description' must be a string", _line(spec, "description"))
    slots, refs = _slots(spec)
    return CaseSpec(
        name=name,
        alias=alias,
        description=description,
        values=_values(spec),
        slots=slots,
        line=_line(spec),
        confirm=_confirm(spec),
        refs=refs,
    )


def _confirm(spec: dict[str, Any]) -> bool | None:
    """`confirm: true`: hands-free, the order is read back and runs only on a spoken yes."""
    confirm = spec.get("confirm")
    if confirm is not None and not isinstance(confirm, bool):
        raise _Problem("'confirm' must be true or false", _line(spec, "confirm"))
    return confirm


def _required_str(spec: dict[str, Any], key: str) -> str:
    if key not in spec:
        raise _Problem(f"missing mandatory key '{key}'", _line(spec))
    value = spec[key]
    if not isinstance(value, str) or not value.strip():
        raise _Problem(f"'{key}' must be a non-empty string, got {value!r}", _line(spec, key))
    if key == "voice_alias":
        names = PLACEHOLDER.findall(value)
        for name in names:
            if names.count(name) > 1:
                raise _Problem(f"slot '{{{name}}}' appears twice in one command", _line(spec, key))
        try:
            check_regex(with_slots(value, SLOT_STUB))
        except ValueError as exc:
            raise _Problem(f"'voice_alias': {exc}", _line(spec, key)) from exc
    return value.strip()


def _slots(spec: dict[str, Any]) -> tuple[dict[str, SlotSpec], dict[str, OrderSlot]]:
    """The number slots and the order slots declared under `slots`."""
    raw = spec.get("slots") or {}
    if not isinstance(raw, dict):
        raise _Problem("'slots' must be a mapping of slot name to slot", _line(spec, "slots"))
    slots: dict[str, SlotSpec] = {}
    refs: dict[str, OrderSlot] = {}
    for name, slot in raw.items():
        try:
            made = slot_from_dict(str(name), slot)
        except ValueError as exc:
            raise _Problem(str(exc), _line(raw, name)) from exc
        if isinstance(made, OrderSlot):
            refs[made.name] = made
        else:
            slots[made.name] = made
    return slots, refs


def _values(spec: dict[str, Any]) -> dict[str, ParamValue]:
    values: dict[str, ParamValue] = {}
    for key, value in spec.items():
        if key in RESERVED_KEYS:
            continue
        if not isinstance(key, str):
            raise _Problem(f"parameter names must be strings, got {key!r}", _line(spec, key))
        if not isinstance(value, str | int | float | bool):
            raise _Problem(
                f"parameter '{key}' must be a string, number or boolean, "
                f"got {type(value).__name__}",
                _line(spec, key),
            )
        if isinstance(value, float) and not math.isfinite(value):
            raise _Problem(
                f"parameter '{key}' must be a finite number, got {value!r}", _line(spec, key)
            )
        values[key] = value
    return values


def _skip_words(data: dict[str, Any], source: str) -> tuple[str, ...] | None:
    """The file's `skip_words`: a list of single words in normal form, or None if absent."""
    if "skip_words" not in data:
        return None
    words = data["skip_words"]
    line = _line(data, "skip_words")
    if words is None:
        words = []
    if not isinstance(words, list):
        raise OrdersInvalid([(f"{source}: 'skip_words' must be a list of words", line)])
    for word in words:
        if not isinstance(word, str) or not word or normalise(word) != word or " " in word:
            raise OrdersInvalid(
                [
                    (
                        f"{source}: skip_words: {word!r} must be one lower-case word "
                        "without punctuation",
                        line,
                    )
                ]
            )
    return tuple(dict.fromkeys(words))


def _commands(order: OrderSpec) -> list[Command]:
    """The order's commands: itself, or its alias alone and with each case."""
    order_used = set(PLACEHOLDER.findall(order.alias))
    case_used: set[str] = set()
    commands = [_command(order, None)]
    for case in order.cases:
        commands.append(_command(order, case))
        case_used.update(PLACEHOLDER.findall(case.alias))
        declared = {*case.slots, *case.refs}
        unused = declared - order_used - set(PLACEHOLDER.findall(case.alias))
        if unused:
            raise _Problem(
                f"slot(s) {', '.join(sorted(unused))} declared but not in any alias",
                case.line,
                f" case '{case.name}'",
            )
    unused = {*order.slots, *order.refs} - order_used - case_used
    if unused:
        raise _Problem(
            f"slot(s) {', '.join(sorted(unused))} declared but not in any alias", order.line
        )
    return commands


def command(order: OrderSpec, case: CaseSpec | None) -> Command:
    """The command `order` makes with `case` (or alone): its aliases joined, its slots
    checked, its phrases expanded. Raises ValueError saying what is wrong."""
    try:
        return _command(order, case)
    except _Problem as exc:
        raise ValueError(f"order '{order.name}'{exc.where}: {exc}") from None


MAX_ORDER_SLOTS = 2


def _command(order: OrderSpec, case: CaseSpec | None) -> Command:
    at = f" case '{case.name}'" if case else ""
    line = case.line if case else order.line
    numbers = {**order.slots, **(case.slots if case else {})}
    names = {**order.refs, **(case.refs if case else {})}
    available: dict[str, SlotSpec | OrderSlot] = {**numbers, **names}
    aliases = [order.alias, *([case.alias] if case else [])]
    used = [name for alias in aliases for name in PLACEHOLDER.findall(alias)]
    for name in used:
        if used.count(name) > 1:
            raise _Problem(f"slot '{{{name}}}' appears twice in one command", line, at)
        if name not in available:
            declared = ", ".join(sorted(available)) or "none"
            raise _Problem(f"slot '{{{name}}}' is not declared; declared: {declared}", line, at)
    slots = {name: numbers[name] for name in used if name in numbers}
    refs = {name: names[name] for name in used if name in names}
    targets = [slot.to for slot in slots.values()] + [ref.to for ref in refs.values()]
    for target in targets:
        if targets.count(target) > 1:
            raise _Problem(f"two slots write to '{target}'", line, at)
    _check_refs(order, refs, line, at)

    try:
        expansion = expand(
            combined(tuple(aliases), SLOT_STUB, ()),
            {f"{SLOT_GROUP}{n}": n for n in (*slots, *refs)},
        )
    except re.error as exc:  # each alias compiled alone: e.g. a group name in both
        raise _Problem(f"the aliases do not combine into one regex: {exc}", line, at) from exc
    for template in expansion.templates:
        for word in template:
            if isinstance(word, SlotRef) or normalise(word) == word:
                continue
            raise _Problem(
                f"alias can never match '{word}': text is matched without punctuation "
                f"(write '{normalise(word)}')",
                line,
                at,
            )
    if order.label == QUEUE_LABEL and (case is not None or not order.cases):
        _check_edit(order, case, slots, refs, line, at)
    return Command(order, case, tuple(aliases), slots, expansion, refs)


def _check_refs(order: OrderSpec, refs: dict[str, OrderSlot], line: int | None, at: str) -> None:
    if refs and order.label != QUEUE_LABEL:
        raise _Problem(
            f"a slot of type order names an order in the queue: only orders of label "
            f"'{QUEUE_LABEL}' have one (slot {', '.join(sorted(refs))})",
            line,
            at,
        )
    if len(refs) > MAX_ORDER_SLOTS:
        raise _Problem(f"at most {MAX_ORDER_SLOTS} slots of type order in one command", line, at)
    for ref in refs.values():
        if ref.like and (ref.like == ref.name or ref.like not in refs):
            raise _Problem(
                f"slot '{ref.name}': 'like' must name another slot of type order of the same "
                f"command, not {ref.like!r}",
                line,
                at,
            )
    if len(refs) == MAX_ORDER_SLOTS and not any(ref.like for ref in refs.values()):
        raise _Problem(
            "two slots of type order in one command: the second says which order it is of "
            "with 'like: <the first>'",
            line,
            at,
        )


def _check_edit(
    order: OrderSpec,
    case: CaseSpec | None,
    slots: dict[str, SlotSpec],
    refs: dict[str, OrderSlot],
    line: int | None,
    at: str,
) -> None:
    """An order of label `queue` must say an edit the supervisor knows, with sample values
    where its slots go."""
    params: dict[str, ParamValue] = dict(order.merged_values(case))
    params.update({slot.to: 1.0 for slot in slots.values()})
    params.update({ref.to: ref.name for ref in refs.values()})
    made = Order(order=order.name, label=QUEUE_LABEL, description="", params=params)
    try:
        read_edit(made)
    except ValueError as exc:
        raise _Problem(f"not an edit of the queue: {exc}", line, at) from None


def _line(mapping: Any, key: Any = None) -> int | None:
    """The YAML line of `mapping` or of its `key`, when it was read from YAML."""
    if not isinstance(mapping, _LineMapping):
        return None
    if key is None:
        return mapping.line
    return mapping.key_lines.get(key, mapping.line)


class _LineMapping(dict[Any, Any]):
    """A YAML mapping that remembers the line it starts on and the lines of its keys."""

    line: int | None = None
    key_lines: dict[Any, int]


class _LineLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """yaml's safe loader (libyaml's when installed), with line numbers on mappings."""


def _construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> Iterator[_LineMapping]:
    mapping = _LineMapping()
    mapping.line = node.start_mark.line + 1
    mapping.key_lines = {}
    yield mapping
    mapping.update(loader.construct_mapping(node))
    for key_node, _ in node.value:
        key = loader.construct_object(key_node)
        line = key_node.start_mark.line + 1
        try:
            first = mapping.key_lines.setdefault(key, line)
        except TypeError:  # an unhashable key; construct_mapping has refused it already
            continue
        if first != line:
            # YAML would keep the last silently: an order defined twice is a mistake.
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"'{key}' is defined twice, at lines {first} and {line}",
                key_node.start_mark,
            )


_LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
