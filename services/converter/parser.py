"""Text to orders: whole-word alias matching, most specific match wins, ties are errors.

Each segment of an utterance (between separators) becomes exactly one order or one error.
Skip words ("the", "please") may stand between and around a command's words; any other
word outside the matched command makes the segment an error, never a silent drop.
Only the commands whose key word is in the segment are tried: an index built from the
expanded aliases keeps a parse of a 200-order file to a handful of regex searches.

People join commands with "and" as often as with the orders' separator ("turn right and
move forward one meter"): a segment that is not one order is tried split at its "and"s,
and taken only if every piece is an order, so that "one hundred and five" stays a number.
Unit symbols after a number are read as the unit's word ("4.5 m", "90°", "30 s"), unless
an alias itself uses the symbol.

An edit of the queue (an order of label `queue`) may stand next to an order without the
separator ("after that go to base", "go forward two meters no three"); a correction said
right after an order corrects it there and then (amend.py), so that it never adds one.
"""

from __future__ import annotations

import functools
import itertools
import re
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import regex

from voicectl.shared.edits import QUEUE_LABEL, ReplaceEdit, is_edit, read_edit
from voicectl.shared.errors import VoicectlError
from voicectl.shared.messages import Order, ParseProblem, ParseResult

from .amend import Amender, AmendRefused
from .expand import SlotRef
from .grammar import build_grammar
from .language import DEFAULT, language_of
from .model import Command
from .orders import OrderSet
from .patterns import SLOT_GROUP
from .slots import SlotValueError
from .suggest import Suggester
from .text import normalise, whole_words

__all__ = ["MAX_TEXT_CHARS", "Parser", "normalise"]

MAX_TEXT_CHARS = 4096
"""Longer input is refused whole: no spoken command is that long."""
PARSE_BUDGET = 0.25
"""Seconds one parse may spend matching. Aliases are matched with `regex`, whose engine
does not blow up on the usual backtracking traps, and within this time limit for the
rest: an alias that still takes too long makes an error, and the converter answers."""


class _TooSlow(VoicectlError):
    """A command's alias took longer than the parse budget allows."""


def _finditer(matcher: _Matcher, segment: str, deadline: float) -> Iterator[regex.Match[str]]:
    """The command's matches in `segment`, within what is left of the parse's time."""
    left = deadline - time.monotonic()
    try:
        yield from matcher.regex.finditer(segment, timeout=max(left, 0.001))
    except TimeoutError:
        raise _TooSlow(
            f"order '{matcher.command.name}' took over {PARSE_BUDGET * 1000:.0f} ms to "
            "match: its alias backtracks too much; simplify it"
        ) from None


MAX_CONJUNCTIONS = 4
"""A segment with more "and"s is not tried split: 2**4 ways are enough for speech."""
UNIT_SYMBOLS = language_of(DEFAULT).unit_words
"""English unit symbols after a number ("4.5 m"); each language has its own."""


def _symbol_after_number(symbols: dict[str, str]) -> re.Pattern[str]:
    others = "|".join(re.escape(k) for k in symbols if k != "°")
    return re.compile(r"(?<=\d)\s*(?:°|(?:" + others + r")(?!\w))", re.IGNORECASE)


_NUMBER = "\x00number"
"""Index key of commands that start with a slot."""
_NUMERIC = re.compile(r"-?\d")
_DECIMAL_COMMA = re.compile(r"(?<=\d),(?=\d)")


@dataclass(frozen=True)
class _Matcher:
    command: Command
    regex: regex.Pattern[str]


class _Index:
    """Commands by a word they cannot match without; the others are always tried.

    A command is filed under its rarest mandatory word (one in every phrase of its alias,
    such as "box" in "(please )?fetch (the )?box"), or else under every first word of its
    phrases: a segment without that word cannot match it. A segment that lacks any other
    of its mandatory words cannot match it either: it is not tried (most tries failed,
    and each costs a regex search with a time limit).
    """

    def __init__(
        self,
        commands: Sequence[Command],
        skip_words: tuple[str, ...],
        enabled: bool,
        number_starts: frozenset[str],
    ) -> None:
        self._number_starts = number_starts
        """Words a spoken number may begin with, in the orders' language."""
        self.matchers = [
            _Matcher(c, regex.compile(whole_words(c.pattern(skip_words)), regex.IGNORECASE))
            for c in commands
        ]
        self._by_word: dict[str, list[int]] = {}
        self._always: list[int] = []
        keys = [_keys(m) if enabled else ([], False) for m in self.matchers]
        self._needs = [
            frozenset(w.casefold() for w in words) if mandatory else frozenset()
            for words, mandatory in keys
        ]
        """Per matcher, every word a segment must hold for it to match."""
        frequency = Counter(k for words, mandatory in keys if mandatory for k in words)
        for position, (words, mandatory) in enumerate(keys):
            if not words:
                self._always.append(position)
                continue
            if mandatory:
                words = [min(words, key=lambda k: (k == _NUMBER, frequency[k], k))]
            for word in words:
                # Casefolded on both sides, as close as words get to re.IGNORECASE.
                self._by_word.setdefault(word.casefold(), []).append(position)

    def candidates(self, words: list[str]) -> list[_Matcher]:
        """The matchers worth trying on a segment of `words`, in file order."""
        positions = set(self._always)
        present = {word.casefold() for word in words}
        for word in words:
            positions.update(self._by_word.get(word.casefold(), ()))
            if word in self._number_starts or _NUMERIC.match(word):
                positions.update(self._by_word.get(_NUMBER, ()))
                present.add(_NUMBER)
        return [self.matchers[p] for p in sorted(positions) if self._needs[p] <= present]


def _replacement(order: Order) -> ReplaceEdit | None:
    """The correction `order` says, if it is one."""
    if not is_edit(order):
        return None
    try:
        edit = read_edit(order)
    except ValueError:
        return None
    return edit if isinstance(edit, ReplaceEdit) else None


def _names(change: ReplaceEdit, order: Order) -> bool:
    """Whether a correction names `order`: the last one, or its case (or order) by name."""
    return change.which in ("last", order.case or order.order)


def _keys(matcher: _Matcher) -> tuple[list[str], bool]:
    """A command's index keys, and whether each is mandatory (else they are the first
    words). No keys when the alias cannot be expanded, or when a phrase of the expansion
    does not match the regex (a safety net: the expander reads a private module)."""
    templates = matcher.command.expansion.templates
    if not matcher.command.expansion.finite or not templates:
        return [], False
    for template in templates:
        sample = " ".join("1" if isinstance(w, SlotRef) else w for w in template)
        if not matcher.regex.fullmatch(sample):
            return [], False
    sets = [{_NUMBER if isinstance(w, SlotRef) else w for w in t} for t in templates]
    mandatory = set.intersection(*sets)
    if mandatory:
        return sorted(mandatory), True
    firsts = {_NUMBER if isinstance(t[0], SlotRef) else t[0] for t in templates}
    return sorted(firsts), False


class Parser:
    """Turns utterances into orders with one `OrderSet`; build once, parse many.

    `use_index=False` tries every command on every segment: the same results, slower; the
    benchmark and the tests compare the two.
    """

    def __init__(self, orders: OrderSet, use_index: bool = True) -> None:
        self.orders = orders
        spoken = orders.spoken
        self._conjunctions = frozenset(spoken.conjunctions)
        """The language's "and" ("y", "und")."""
        conjunction = "|".join(map(re.escape, spoken.conjunctions)) or "(?!)"
        self._separator = re.compile(
            whole_words(f"(?:(?:{conjunction}) )?(?:{orders.separator})"), re.IGNORECASE
        )
        """The orders' separator, "and then" as well."""
        self._decimal_comma = spoken.decimal_comma
        self._skip_words = frozenset(orders.skip_words)
        starts = orders.numbers.starts
        self._commands = _Index(orders.commands, orders.skip_words, use_index, starts)
        self._prefixes = _Index(orders.prefixes, orders.skip_words, use_index, starts)
        # Edits are short phrases that name the other orders' words ("no kitchen", "cancel
        # left"): offered for a near-miss, they crowd out the orders people meant.
        self._suggester = Suggester(
            [c for c in orders.commands if c.order.label != QUEUE_LABEL],
            self._parse_alone,
            orders.skip_words,
        )
        after_numbers = {
            word.casefold()
            for command in orders.commands
            for template in command.expansion.templates
            for before, word in itertools.pairwise(template)
            if isinstance(word, str) and (isinstance(before, SlotRef) or _NUMERIC.search(before))
        }
        symbols = spoken.unit_words or UNIT_SYMBOLS
        self._symbols = {k: v for k, v in symbols.items() if k not in after_numbers}
        """Unit symbols read as words: those no alias uses itself after a number (the
        queue's "what s next" leaves "10 s" ten seconds)."""
        self._symbol_after_number = _symbol_after_number(symbols)
        self.amender = Amender(orders.commands)
        self.unit_words = frozenset(
            word.casefold()
            for command in orders.commands
            for template in command.expansion.templates
            for before, word in itertools.pairwise(template)
            if isinstance(before, SlotRef) and isinstance(word, str)
        )
        """Words that follow a spoken number in some command ("meters", "degrees")."""

    @functools.cached_property
    def vocabulary(self) -> frozenset[str]:
        """The words the orders are said with, skip words and number words aside: what a
        free transcript's near-miss words are snapped to (snap.py)."""
        grammar = build_grammar(self.orders)
        return frozenset(grammar.words) - set(grammar.skip_words) - set(grammar.number_words)

    def parse(self, text: str) -> ParseResult:
        if len(text) > MAX_TEXT_CHARS:
            reason = f"text too long: {len(text)} characters, at most {MAX_TEXT_CHARS}"
            return ParseResult(errors=[ParseProblem(text=text[:80], reason=reason)])
        clean = normalise(self.spell_units(text))
        if not clean:
            return ParseResult(errors=[ParseProblem(text="", reason="empty text")])
        result = ParseResult()
        deadline = time.monotonic() + PARSE_BUDGET
        for segment in self._separator.split(clean):
            segment = segment.strip()
            if not segment:
                continue
            parsed: Order | ParseProblem | list[Order]
            try:
                parsed = self._parse_segment(segment, suggest=True, deadline=deadline)
                if isinstance(parsed, ParseProblem):
                    parsed = (
                        self._joined(segment, deadline) or self._beside(segment, deadline) or parsed
                    )
            except _TooSlow as exc:
                parsed = ParseProblem(text=segment[:80], reason=str(exc))
            match parsed:
                case Order() as order:
                    result.orders.append(order)
                case ParseProblem() as error:
                    result.errors.append(error)
                case list() as orders:
                    result.orders.extend(orders)
        return self._corrected(result)

    def _corrected(self, result: ParseResult) -> ParseResult:
        """`result` with each correction that follows an order applied to that order (an
        order it cannot fit makes an error instead), never added beside it."""
        orders: list[Order] = []
        errors = list(result.errors)
        for order in result.orders:
            change = _replacement(order)
            before = orders[-1] if orders else None
            if change is None or before is None or is_edit(before) or not _names(change, before):
                orders.append(order)
                continue
            try:
                orders[-1] = self.amender.amend(before, change)
            except AmendRefused as exc:
                orders.pop()
                errors.append(
                    ParseProblem(text=f"{before.description}, {order.description}", reason=str(exc))
                )
        if len(orders) == len(result.orders):
            return result
        return ParseResult(orders=orders, errors=errors)

    def _beside(self, segment: str, deadline: float) -> list[Order] | None:
        """The two orders of a segment that is an edit next to an order, said without the
        separator ("after that go to base"), if exactly one cut makes them."""
        words = segment.split(" ")
        found: list[list[Order]] = []
        for cut in range(1, len(words)):
            left = self._parse_segment(" ".join(words[:cut]), False, deadline)
            if not isinstance(left, Order):
                continue
            right = self._parse_segment(" ".join(words[cut:]), False, deadline)
            if isinstance(right, Order) and (is_edit(left) or is_edit(right)):
                found.append([left, right])
        return found[0] if len(found) == 1 else None

    def spell_units(self, text: str) -> str:
        """Unit symbols right after a number as the unit's word: "4.5 m" -> "4.5 meters";
        a decimal comma as a point, in a language that writes one ("2,5 m")."""
        if self._decimal_comma:
            text = _DECIMAL_COMMA.sub(".", text)

        def word(found: re.Match[str]) -> str:
            symbol = found.group(0).strip()
            spelled = self._symbols.get(symbol.casefold())
            return f" {spelled}" if spelled else found.group(0)

        return self._symbol_after_number.sub(word, text)

    def _joined(self, segment: str, deadline: float) -> list[Order] | None:
        """The orders of a segment that is commands joined by "and", if splitting at some
        of its "and"s makes every piece one order (the fewest pieces first)."""
        words = segment.split(" ")
        while words[:1] and words[0] in self._conjunctions:  # "... then and turn left"; a
            words = words[1:]  # last "and" says that more was to come, and stays an error
        joints = [i for i, word in enumerate(words) if word in self._conjunctions]
        stripped = len(words) < len(segment.split(" "))
        if len(joints) > MAX_CONJUNCTIONS or not (joints or stripped):
            return None
        for count in range(len(joints) + 1):
            for chosen in itertools.combinations(joints, count):
                bounds = [-1, *chosen, len(words)]
                pieces = [" ".join(words[a + 1 : b]) for a, b in itertools.pairwise(bounds)]
                orders = []
                for piece in pieces:
                    parsed = self._parse_segment(piece, False, deadline) if piece else None
                    if not isinstance(parsed, Order):
                        break
                    orders.append(parsed)
                else:
                    return orders
        return None

    def _parse_alone(self, phrase: str) -> Order | None:
        """The order `phrase` makes as one segment, if it makes one."""
        try:
            parsed = self._parse_segment(phrase, False, time.monotonic() + PARSE_BUDGET)
        except _TooSlow:
            return None
        return parsed if isinstance(parsed, Order) else None

    def _parse_segment(self, segment: str, suggest: bool, deadline: float) -> Order | ParseProblem:
        words = segment.split(" ")
        best: list[tuple[_Matcher, regex.Match[str]]] = []
        best_words = 0
        for matcher in self._commands.candidates(words):
            for found in _finditer(matcher, segment, deadline):
                covered = len(found.group(0).split())
                if covered > best_words:
                    best, best_words = [(matcher, found)], covered
                elif covered == best_words and best[-1][0] is not matcher:
                    best.append((matcher, found))
        if len(best) == 1:
            matcher, found = best[0]
            spoken = {name: found.group(f"{SLOT_GROUP}{name}") for name in matcher.command.slots}
            try:
                made = matcher.command.to_order(spoken)
            except SlotValueError as exc:
                return ParseProblem(text=segment, reason=str(exc))
            extra = [
                word
                for word in (segment[: found.start()] + " " + segment[found.end() :]).split()
                if word not in self._skip_words
            ]
            if extra:
                said = found.group(0)
                return ParseProblem(
                    text=segment,
                    reason=f"words not understood: '{' '.join(extra)}'; did you mean: {said}?",
                    candidates=[said],
                )
            return made
        if best:
            names = [m.command.name for m, _ in best]
            return ParseProblem(
                text=segment,
                reason="ambiguous: matches " + ", ".join(names),
                candidates=names,
            )
        suggestions = self._suggester.suggest(segment) if suggest else []
        for matcher in self._prefixes.candidates(words):
            if next(_finditer(matcher, segment, deadline), None) is not None:
                order = matcher.command.order
                cases = ", ".join(order.example(case) for case in order.cases)
                reason = f"'{order.description}' needs one of: {cases}"
                if suggestions:
                    return ParseProblem(
                        text=segment,
                        reason=f"{reason}; did you mean: {' or '.join(suggestions)}?",
                        candidates=suggestions,
                    )
                return ParseProblem(
                    text=segment,
                    reason=reason,
                    candidates=[f"{order.name}/{c.name}" for c in order.cases],
                )
        return ParseProblem(text=segment, reason="no order matches", candidates=suggestions)
