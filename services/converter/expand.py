"""Expand an alias regex into the finite set of phrases it matches, for the recogniser.

The regex is read by Python's own parser (``re._parser``), so the expansion agrees with
what `re` matches. That module is private: only the node types listed here are expanded,
anything else makes the alias unexpandable (never a wrong phrase), and every phrase is
checked against the compiled regex before it is used.

PyPI alternatives were considered: exrex is AGPL-licensed, sre_yield has had no release
since 2019 and imports the deprecated ``sre_parse`` (a warning, which the tests treat as an
error), and greenery has its own regex dialect (it rejects ``\\b``), so its phrases could
disagree with what `re` matches.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from voicectl.shared.errors import VoicectlError

_sre: Any = importlib.import_module("re._parser")

MAX_PHRASES = 1000
"""An alias with more phrases than this (before slot values) is treated as unexpandable."""
MAX_CLASS = 8
"""A character class with more members than this ([a-z], \\w) is not expanded."""
MAX_REPEAT = 4
"""A bounded repeat above this ({0,9}) is not expanded."""


@dataclass(frozen=True)
class SlotRef:
    """Where a slot's number goes in a phrase."""

    name: str


class _Gap:
    """Stands for text the regex matches that cannot be listed (.*, \\w+)."""

    def __repr__(self) -> str:
        return "GAP"


GAP = _Gap()
Piece = str | SlotRef | _Gap
Template = tuple[str | SlotRef, ...]
"""A phrase as words, with the slots still open: ('move', 'forward', SlotRef('d'), 'meters')."""


@dataclass(frozen=True)
class Expansion:
    """What an alias can be heard as: phrases, or why not plus the words it contains."""

    templates: tuple[Template, ...] = ()
    problem: str = ""
    """Empty when `templates` is the whole, finite set; else why it is not."""
    words: tuple[str, ...] = field(default=())
    """Every whole word the regex contains, expandable or not."""

    @property
    def finite(self) -> bool:
        return not self.problem


class _TooMany(VoicectlError):
    """A pattern with more spellings than an alias may have."""


def expand(pattern: str, slot_groups: dict[str, str] | None = None) -> Expansion:
    """Expand `pattern`; `slot_groups` maps a named group of it to the slot it stands for.

    Raises re.error for a pattern that does not parse.
    """
    slot_groups = slot_groups or {}
    parsed = _sre.parse(pattern, 0)
    names = {index: name for name, index in parsed.state.groupdict.items()}
    walker = _Walker({index: slot_groups[n] for index, n in names.items() if n in slot_groups})
    try:
        alternatives = walker.sequence(list(parsed))
    except _TooMany:
        return Expansion(problem=f"more than {MAX_PHRASES} phrases")
    templates: list[Template] = []
    words: set[str] = set()
    for pieces in alternatives:
        template, gaps = _tokens(pieces)
        words.update(t for t in template if isinstance(t, str))
        if not gaps:
            templates.append(template)
    if walker.problems:
        return Expansion(problem="; ".join(sorted(walker.problems)), words=tuple(sorted(words)))
    return Expansion(templates=tuple(dict.fromkeys(templates)), words=tuple(sorted(words)))


def _tokens(pieces: Sequence[Piece]) -> tuple[Template, bool]:
    """Join pieces into words; a gap cuts the word it touches (that fragment is dropped)."""
    tokens: list[str | SlotRef] = []
    current = ""
    partial = False
    gaps = False

    def flush() -> None:
        nonlocal current, partial
        if current and not partial:
            tokens.append(current)
        current, partial = "", False

    for piece in pieces:
        if isinstance(piece, SlotRef):
            flush()
            tokens.append(piece)
        elif isinstance(piece, _Gap):
            gaps = True
            partial = True
        else:
            for char in piece:
                if char.isspace():
                    flush()
                else:
                    current += char
    flush()
    return tuple(tokens), gaps


Alternatives = list[tuple[Piece, ...]]


class _Walker:
    """Turns parser nodes into lists of alternatives, each a tuple of pieces."""

    def __init__(self, slots: dict[int, str]) -> None:
        self._slots = slots
        self.problems: set[str] = set()

    def sequence(self, nodes: Iterable[tuple[Any, Any]]) -> Alternatives:
        result: Alternatives = [()]
        for op, arg in nodes:
            options = self.node(str(op), arg)
            if len(result) * len(options) > MAX_PHRASES:
                raise _TooMany
            result = [left + right for left in result for right in options]
        return result

    def _gap(self, problem: str) -> Alternatives:
        self.problems.add(problem)
        return [(GAP,)]

    def node(self, op: str, arg: Any) -> Alternatives:
        match op:
            case "LITERAL":
                return [(chr(arg).lower(),)]
            case "IN":
                return self._charset(arg)
            case "BRANCH":
                _, branches = arg
                merged: Alternatives = []
                for branch in branches:
                    merged.extend(self.sequence(branch))
                    if len(merged) > MAX_PHRASES:
                        raise _TooMany
                return merged
            case "SUBPATTERN":
                group, _add_flags, _del_flags, body = arg
                if group in self._slots:
                    return [(SlotRef(self._slots[group]),)]
                return self.sequence(body)
            case "MAX_REPEAT" | "MIN_REPEAT" | "POSSESSIVE_REPEAT":
                return self._repeat(*arg)
            case "AT":
                return [()]  # \b, ^, $: zero-width, and every phrase is whole words anyway
            case "ANY" | "NOT_LITERAL":
                return self._gap("matches any character (. or [^...])")
            case "CATEGORY":
                return self._charset([(op, arg)])
            case "ASSERT" | "ASSERT_NOT":
                # Consumes no text, but may forbid some phrases: not listable for sure.
                self.problems.add("contains a lookahead or lookbehind")
                return [()]
            case "GROUPREF" | "GROUPREF_EXISTS":
                return self._gap("refers back to a group")
            case _:
                return self._gap(f"uses {op}, which is not expanded")

    def _charset(self, items: list[tuple[Any, Any]]) -> Alternatives:
        chars: list[str] = []
        for op, arg in items:
            match str(op):
                case "LITERAL":
                    chars.append(chr(arg))
                case "RANGE" if arg[1] - arg[0] < MAX_CLASS:
                    chars.extend(chr(c) for c in range(arg[0], arg[1] + 1))
                case "CATEGORY" if str(arg) == "CATEGORY_SPACE":
                    chars.append(" ")
                case _:
                    return self._gap(f"has a character class with more than {MAX_CLASS} members")
        unique = dict.fromkeys(c.lower() for c in chars)
        if len(unique) > MAX_CLASS:
            return self._gap(f"has a character class with more than {MAX_CLASS} members")
        return [(c,) for c in unique]

    def _repeat(self, low: int, high: int, body: list[tuple[Any, Any]]) -> Alternatives:
        if _is_space(body):
            # Text is whitespace-normalised: any run of spaces is one space (or none).
            return [(" ",)] if low > 0 else [(" ",), ()]
        once = self.sequence(body)
        if high > MAX_REPEAT:
            self.problems.add(
                f"repeats without a small bound (*, +, {{n,}} or more than {MAX_REPEAT} times)"
            )
            # One copy, an unknown number more, one last copy: enough to keep the words.
            return [(*alt, GAP, *alt) for alt in once]
        result: Alternatives = []
        for count in range(low, high + 1):
            current: Alternatives = [()]
            for _ in range(count):
                if len(current) * len(once) > MAX_PHRASES:
                    raise _TooMany
                current = [left + right for left in current for right in once]
            result.extend(current)
            if len(result) > MAX_PHRASES:
                raise _TooMany
        return result


def _is_space(body: list[tuple[Any, Any]]) -> bool:
    """True for the body of ``\\s+``, `` +``, ``[ \\t]*``: nothing but whitespace."""
    if len(body) != 1:
        return False
    op, arg = body[0]
    if str(op) == "LITERAL":
        return chr(arg).isspace()
    if str(op) == "IN":
        return all(
            (str(o) == "LITERAL" and chr(a).isspace())
            or (str(o) == "CATEGORY" and str(a) == "CATEGORY_SPACE")
            for o, a in arg
        )
    return False


def nested_repeat(pattern: str) -> str:
    """The first repetition inside a repetition that can backtrack catastrophically
    ('(a+)+', '(a|b*)*'), shown as regex; '' when there is none.

    Python's regex engine backtracks: a repeated group whose body can itself match in
    many ways takes exponential time on text that almost matches ('(a+)+b' on forty a's
    froze the converter). Refused at load: an unbounded repeat around any repeat, or any
    repeat around an unbounded one.
    """

    def walk(nodes: Iterable[tuple[Any, Any]], outer: tuple[int, int] | None) -> str:
        for op, arg in nodes:
            name = str(op)
            if name in ("MAX_REPEAT", "MIN_REPEAT", "POSSESSIVE_REPEAT"):
                low, high, body = arg
                if _is_space(body):
                    continue  # whitespace is normalised: one space, one way to match it
                unbounded = high == _sre.MAXREPEAT
                varies = high > 1 and low != high  # 'a{2}' matches one way only
                if outer is not None and varies and (unbounded or outer[1] == _sre.MAXREPEAT):
                    return f"{'unbounded ' if unbounded else ''}repeat inside a repeat"
                found = walk(body, (low, high) if high > 1 else outer)
            elif name == "SUBPATTERN":
                found = walk(arg[3], outer)
            elif name == "BRANCH":
                found = next((f for f in (walk(b, outer) for b in arg[1]) if f), "")
            elif name in ("ASSERT", "ASSERT_NOT"):
                found = walk(arg[1], outer)
            else:
                found = ""
            if found:
                return found
        return ""

    return walk(_sre.parse(pattern, 0), None)
