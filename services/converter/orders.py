"""Orders files: YAML in, a validated `OrderSet` out, or errors that each fit on a line.

The shape (the ``orders_list`` wrapper is optional)::

    orders_list:
      separator: "then"            # regex between the orders of one utterance
      skip_words: [the, please]    # small words people add; default DEFAULT_SKIP_WORDS
      orders:
        rotation:                  # order name
          voice_alias: "turn"      # regex, mandatory
          label: "mbgoal"          # executor label, mandatory
          frame: "base_link"       # frame/x/y/yaw make the target pose
          cases:
            left: {voice_alias: "left", yaw: 1.57}
            by:                    # a typed slot: "turn by 45 degrees"
              voice_alias: "by {angle} degrees?"
              slots: {angle: {type: number, unit: deg, min: 1, max: 180, to: yaw}}

Any other key of an order or case is a parameter of the order: unknown keys are
meaningful here, so they are kept rather than refused.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from shared.errors import OrdersFileError
from shared.messages import Order, ParamValue, TargetPose

from .expand import Expansion, SlotRef, expand, nested_repeat
from .slots import NUMBER_PATTERN, SlotSpec, format_value
from .text import normalise

RESERVED_KEYS = frozenset({"voice_alias", "label", "description", "cases", "slots"})
POSE_KEYS = ("x", "y", "yaw")
DEFAULT_SEPARATOR = "then"
DEFAULT_SKIP_WORDS = ("a", "the", "to", "please", "now")
"""Words people add around and inside commands ("please reach the kitchen now"): the
parser ignores them there and the recogniser's grammar makes them optional there."""

PLACEHOLDER = re.compile(r"(?<!\\)\{([A-Za-z_]\w*)\}")
"""A slot inside an alias or description: ``{distance}`` (a quantifier has digits only)."""
_QUANTIFIER = re.compile(r"[*+?]|\{\d*(?:,\d*)?\}")
SLOT_GROUP = "slot_"
"""Prefix of the named regex group a slot becomes."""
_SLOT_STUB = "#"
"""Stands for a number when an alias is only checked or expanded."""


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


def orders_files(path: Path) -> list[Path]:
    """The files an orders path stands for: itself, or the *.yaml/*.yml in a directory."""
    if path.is_dir():
        return sorted([*path.glob("*.yaml"), *path.glob("*.yml")])
    return [path]


@dataclass(frozen=True)
class CaseSpec:
    """One variant of an order ('left' of 'rotation') and what it changes."""

    name: str
    alias: str
    description: str
    values: dict[str, ParamValue]
    slots: dict[str, SlotSpec] = field(default_factory=dict)
    line: int | None = None


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

        def number(found: re.Match[str]) -> str:
            slot = slots.get(found[1])
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
    """The slots of the pattern, by name."""
    expansion: Expansion

    @property
    def name(self) -> str:
        return f"{self.order.name}/{self.case.name}" if self.case else self.order.name

    def pattern(self, skip_words: tuple[str, ...] = ()) -> str:
        """The aliases as one regex with slots as named groups, not yet restricted to whole
        words; `skip_words` may stand wherever the aliases have a space."""
        return _combined(self.aliases, NUMBER_PATTERN, skip_words)

    def to_order(self, spoken: dict[str, str | None]) -> Order:
        """The order this command makes with the slot texts `spoken` (by slot name; None
        for a slot in an optional part that was not said, which then sets nothing).

        Raises SlotValueError when a value is not a number or is out of its bounds.
        """
        filled: dict[str, ParamValue] = {}
        said: dict[str, str] = {}
        for name, slot in self.slots.items():
            text = spoken.get(name)
            if text is None:
                continue
            value = slot.value(text)
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
        )


@dataclass(frozen=True)
class OrderSet:
    """Every order the converter knows, and how utterances are split."""

    orders: tuple[OrderSpec, ...]
    separator: str = DEFAULT_SEPARATOR
    declared_skip_words: tuple[str, ...] | None = None
    """The files' `skip_words`; None when no file says, and `DEFAULT_SKIP_WORDS` apply."""
    sources: tuple[str, ...] = field(default=())
    commands: tuple[Command, ...] = ()
    """Every whole command, in file order."""
    prefixes: tuple[Command, ...] = ()
    """The aliases of orders with cases, alone."""
    separator_expansion: Expansion = field(default_factory=Expansion)

    @property
    def skip_words(self) -> tuple[str, ...]:
        """The small words the parser ignores between and around a command's words."""
        if self.declared_skip_words is None:
            return DEFAULT_SKIP_WORDS
        return self.declared_skip_words

    @staticmethod
    def load(path: Path) -> OrderSet:
        """Load one YAML file, or every ``*.yaml``/``*.yml`` in a directory."""
        if path.is_dir():
            files = orders_files(path)
            if not files:
                raise OrdersFileError(f"{path}: no *.yaml orders files in this directory")
            sets: list[OrderSet] = []
            problems: list[Problem] = []
            for file in files:
                try:
                    sets.append(OrderSet.load(file))
                except OrdersInvalid as exc:
                    problems.extend(exc.problems)
                except OrdersFileError as exc:
                    problems.append((str(exc), None))
            if problems:
                raise OrdersInvalid(problems)
            return OrderSet.merge(sets)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise OrdersFileError(f"{path}: cannot read orders file: {exc}") from exc
        return OrderSet.from_yaml(text, str(path))

    @staticmethod
    def from_yaml(text: str, source: str = "<text>") -> OrderSet:
        try:
            data = yaml.load(text, Loader=_LineLoader)  # a SafeLoader that adds line numbers
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f"{source}:{mark.line + 1}" if mark is not None else source
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
            raise OrdersFileError(f"{where}: invalid YAML: {problem}") from exc
        return OrderSet.from_dict(data, source)

    @staticmethod
    def from_dict(data: Any, source: str = "<dict>") -> OrderSet:
        if isinstance(data, dict) and "orders_list" in data:
            data = data["orders_list"]
        if not isinstance(data, dict) or not isinstance(data.get("orders"), dict):
            raise OrdersFileError(f"{source}: expected a mapping with an 'orders' mapping")
        unknown = set(data) - {"orders", "separator", "skip_words"}
        if unknown:
            raise OrdersFileError(
                f"{source}: unknown top-level key(s) {', '.join(sorted(map(str, unknown)))}; "
                "allowed: orders, separator, skip_words"
            )
        separator = data.get("separator", DEFAULT_SEPARATOR)
        if not isinstance(separator, str) or not separator.strip():
            raise OrdersFileError(f"{source}: 'separator' must be a non-empty string (regex)")
        try:
            _check_regex(separator)
        except _Problem as exc:
            where = f"{source}: separator: {exc}"
            raise OrdersInvalid([(where, _line(data, "separator"))]) from exc
        skip_words = _skip_words(data, source)
        orders: list[OrderSpec] = []
        commands: list[Command] = []
        problems: list[Problem] = []
        for name, spec in data["orders"].items():
            try:
                order = _order_from_dict(str(name), spec, source)
                commands.extend(_commands(order))
                orders.append(order)
            except _Problem as exc:
                line = exc.line or _line(data["orders"], name)
                problems.append((f"{source}: order '{name}'{exc.where}: {exc}", line))
        if problems:
            raise OrdersInvalid(problems)
        if not orders:
            raise OrdersFileError(f"{source}: 'orders' is empty")
        return OrderSet.build(tuple(orders), commands, separator, skip_words, (source,))

    @staticmethod
    def build(
        orders: tuple[OrderSpec, ...],
        commands: list[Command],
        separator: str,
        skip_words: tuple[str, ...] | None,
        sources: tuple[str, ...],
    ) -> OrderSet:
        return OrderSet(
            orders=orders,
            separator=separator,
            declared_skip_words=skip_words,
            sources=sources,
            commands=tuple(c for c in commands if c.case or not c.order.cases),
            prefixes=tuple(c for c in commands if c.order.cases and not c.case),
            separator_expansion=expand(separator),
        )

    @staticmethod
    def merge(sets: list[OrderSet]) -> OrderSet:
        """Join several files; the same order name twice is an error naming both files."""
        seen: dict[str, str] = {}
        problems: list[Problem] = []
        for order_set in sets:
            for order in order_set.orders:
                if order.name in seen:
                    problems.append(
                        (
                            f"{order.source}: order '{order.name}' is already defined in "
                            f"{seen[order.name]}",
                            order.line,
                        )
                    )
                else:
                    seen[order.name] = order.source
        if problems:
            raise OrdersInvalid(problems)
        separators = {s.separator for s in sets}
        if len(separators) > 1:
            raise OrdersFileError(
                "orders files disagree on the separator: " + ", ".join(sorted(separators))
            )
        declared = {s.declared_skip_words for s in sets} - {None}
        if len(declared) > 1:
            raise OrdersFileError(
                "orders files disagree on skip_words: "
                + "; ".join(
                    f"{', '.join(s.sources)}: {list(s.declared_skip_words)}"
                    for s in sets
                    if s.declared_skip_words is not None
                )
            )
        return OrderSet.build(
            tuple(o for s in sets for o in s.orders),
            [c for s in sets for c in (*s.prefixes, *s.commands)],
            separators.pop(),
            declared.pop() if declared else None,
            tuple(src for s in sets for src in s.sources),
        )


# --- validation ---------------------------------------------------------------------------


class _Problem(Exception):
    """One thing wrong inside an order; the caller adds the file and order names."""

    def __init__(self, message: str, line: int | None = None, where: str = "") -> None:
        super().__init__(message)
        self.line = line
        self.where = where
        """' case NAME' when the problem is inside a case."""


def _at(line: int | None) -> str:
    return f" (line {line})" if line else ""


def _order_from_dict(name: str, spec: Any, source: str) -> OrderSpec:
    if not isinstance(spec, dict):
        raise _Problem(f"expected a mapping, got {type(spec).__name__}")
    alias = _required_str(spec, "voice_alias")
    label = _required_str(spec, "label")
    description = spec.get("description", alias)
    if not isinstance(description, str):
        raise _Problem("'description' must be a string", _line(spec, "description"))
    slots = _slots(spec)
    values = _values(spec)
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


def _case_from_dict(name: str, spec: Any) -> CaseSpec:
    if not isinstance(spec, dict):
        raise _Problem(f"expected a mapping, got {type(spec).__name__}")
    if "cases" in spec:
        raise _Problem("cases cannot have cases of their own", _line(spec, "cases"))
    if "label" in spec:
        raise _Problem("'label' belongs to the order, not to a case", _line(spec, "label"))
    alias = _required_str(spec, "voice_alias")
    description = spec.get("description", alias)
    if not isinstance(description, str):
        raise _Problem("'description' must be a string", _line(spec, "description"))
    return CaseSpec(
        name=name,
        alias=alias,
        description=description,
        values=_values(spec),
        slots=_slots(spec),
        line=_line(spec),
    )


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
            _check_regex(_with_slots(value, _SLOT_STUB))
        except _Problem as exc:
            raise _Problem(f"'voice_alias': {exc}", _line(spec, key)) from exc
    return value.strip()


def _slots(spec: dict[str, Any]) -> dict[str, SlotSpec]:
    raw = spec.get("slots") or {}
    if not isinstance(raw, dict):
        raise _Problem("'slots' must be a mapping of slot name to slot", _line(spec, "slots"))
    slots: dict[str, SlotSpec] = {}
    for name, slot in raw.items():
        try:
            slots[str(name)] = SlotSpec.from_dict(str(name), slot)
        except ValueError as exc:
            raise _Problem(str(exc), _line(raw, name)) from exc
    return slots


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


def _check_regex(pattern: str) -> None:
    try:
        compiled = re.compile(pattern)
    except re.error as exc:
        raise _Problem(f"invalid regex {_plain(pattern)!r}: {exc}") from exc
    if compiled.match(""):
        raise _Problem(f"regex {_plain(pattern)!r} matches empty text")
    nested = nested_repeat(pattern)
    if nested:
        raise _Problem(
            f"regex {_plain(pattern)!r} repeats a repetition ({nested}): it can take "
            "exponential time on text that almost matches; write it with one repetition"
        )


def _plain(pattern: str) -> str:
    """The pattern as the user wrote it, slots back in braces."""
    return re.sub(rf"\(\?P<{SLOT_GROUP}(\w+)>{re.escape(_SLOT_STUB)}\)", r"{\1}", pattern)


def _with_slots(alias: str, body: str = NUMBER_PATTERN) -> str:
    """The alias with each ``{name}`` replaced by a named group matching one number.

    Checks and expansion use a one-character `body`: the number pattern is long, and
    parsing it for every alias made loading a 200-order file take a second.
    """
    return PLACEHOLDER.sub(lambda m: f"(?P<{SLOT_GROUP}{m[1]}>{body})", alias)


def _commands(order: OrderSpec) -> list[Command]:
    """The order's commands: itself, or its alias alone and with each case."""
    order_used = set(PLACEHOLDER.findall(order.alias))
    case_used: set[str] = set()
    commands = [_command(order, None)]
    for case in order.cases:
        commands.append(_command(order, case))
        case_used.update(PLACEHOLDER.findall(case.alias))
        unused = set(case.slots) - order_used - set(PLACEHOLDER.findall(case.alias))
        if unused:
            raise _Problem(
                f"slot(s) {', '.join(sorted(unused))} declared but not in any alias",
                case.line,
                f" case '{case.name}'",
            )
    unused = set(order.slots) - order_used - case_used
    if unused:
        raise _Problem(
            f"slot(s) {', '.join(sorted(unused))} declared but not in any alias", order.line
        )
    return commands


def _command(order: OrderSpec, case: CaseSpec | None) -> Command:
    at = f" case '{case.name}'" if case else ""
    line = case.line if case else order.line
    available = {**order.slots, **(case.slots if case else {})}
    aliases = [order.alias, *([case.alias] if case else [])]
    used = [name for alias in aliases for name in PLACEHOLDER.findall(alias)]
    for name in used:
        if used.count(name) > 1:
            raise _Problem(f"slot '{{{name}}}' appears twice in one command", line, at)
        if name not in available:
            declared = ", ".join(sorted(available)) or "none"
            raise _Problem(f"slot '{{{name}}}' is not declared; declared: {declared}", line, at)
    slots = {name: available[name] for name in used}
    targets = [slot.to for slot in slots.values()]
    for target in targets:
        if targets.count(target) > 1:
            raise _Problem(f"two slots write to '{target}'", line, at)

    try:
        expansion = expand(
            _combined(tuple(aliases), _SLOT_STUB, ()), {f"{SLOT_GROUP}{n}": n for n in slots}
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
    return Command(order, case, tuple(aliases), slots, expansion)


def _combined(aliases: tuple[str, ...], slot_body: str, skip_words: tuple[str, ...]) -> str:
    """Aliases said one after the other, as one regex; `skip_words` may stand wherever
    there is a space between words (none for the recogniser's expansion)."""
    gap = r"\s+"
    if skip_words:
        gap += r"(?:(?:" + "|".join(map(re.escape, skip_words)) + r")\s+)*"
    return gap.join(f"(?:{_with_slots(_spaced(alias, gap), slot_body)})" for alias in aliases)


def _spaced(alias: str, gap: str) -> str:
    """`alias` with each run of plain spaces between words replaced by the regex `gap`.

    Spaces inside a character class, escaped, or under a quantifier (" ?") stay as written.
    """
    if gap == r"\s+":
        return alias
    out: list[str] = []
    position = 0
    in_class = False
    while position < len(alias):
        char = alias[position]
        if char == "\\":
            out.append(alias[position : position + 2])
            position += 2
            continue
        if in_class:
            in_class = char != "]"
        elif char == "[":
            in_class = True
        elif char == " ":
            end = position
            while end < len(alias) and alias[end] == " ":
                end += 1
            if not _QUANTIFIER.match(alias, end):
                out.append(gap)
                position = end
                continue
        out.append(char)
        position += 1
    return "".join(out)


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
