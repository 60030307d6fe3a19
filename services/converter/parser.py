"""Text to orders: whole-word alias matching, most specific match wins, ties are errors."""

from __future__ import annotations

import re
from dataclasses import dataclass

from shared.messages import Order, ParseError, ParseResult

from .orders import CaseSpec, OrderSet, OrderSpec

MAX_TEXT_CHARS = 4096
"""Longer input is refused whole: no spoken command is that long."""

# Punctuation becomes a space; a dot between digits stays ("2.5").
_PUNCTUATION = re.compile(r"(?<!\d)\.|\.(?!\d)|[^\w\s.]")
_SPACES = re.compile(r"\s+")


def normalise(text: str) -> str:
    """Lower-case, punctuation-free, single-spaced text."""
    return _SPACES.sub(" ", _PUNCTUATION.sub(" ", text.lower())).strip()


def _words(pattern: str) -> str:
    """Wrap an alias regex so that it only matches whole words."""
    return rf"(?<!\w)(?:{pattern})(?!\w)"


@dataclass(frozen=True)
class _Candidate:
    order: OrderSpec
    case: CaseSpec | None
    pattern: re.Pattern[str]

    @property
    def name(self) -> str:
        return f"{self.order.name}/{self.case.name}" if self.case else self.order.name

    def to_order(self) -> Order:
        return Order(
            order=self.order.name,
            case=self.case.name if self.case else None,
            label=self.order.label,
            description=self.order.full_description(self.case),
            params=self.order.params(self.case),
            target_pose=self.order.target_pose(self.case),
        )


class Parser:
    """Turns utterances into orders with one `OrderSet`; build once, parse many."""

    def __init__(self, orders: OrderSet) -> None:
        self.orders = orders
        self._separator = re.compile(_words(orders.separator), re.IGNORECASE)
        self._candidates: list[_Candidate] = []
        self._caseless: list[tuple[OrderSpec, re.Pattern[str]]] = []
        for order in orders.orders:
            if not order.cases:
                pattern = re.compile(_words(order.alias), re.IGNORECASE)
                self._candidates.append(_Candidate(order, None, pattern))
                continue
            self._caseless.append((order, re.compile(_words(order.alias), re.IGNORECASE)))
            for case in order.cases:
                pattern = re.compile(
                    _words(rf"(?:{order.alias})\s+(?:{case.alias})"), re.IGNORECASE
                )
                self._candidates.append(_Candidate(order, case, pattern))

    def parse(self, text: str) -> ParseResult:
        if len(text) > MAX_TEXT_CHARS:
            reason = f"text too long: {len(text)} characters, at most {MAX_TEXT_CHARS}"
            return ParseResult(errors=[ParseError(text=text[:80], reason=reason)])
        clean = normalise(text)
        if not clean:
            return ParseResult(errors=[ParseError(text="", reason="empty text")])
        result = ParseResult()
        for segment in self._separator.split(clean):
            segment = segment.strip()
            if not segment:
                continue
            match self._parse_segment(segment):
                case Order() as order:
                    result.orders.append(order)
                case ParseError() as error:
                    result.errors.append(error)
        return result

    def _parse_segment(self, segment: str) -> Order | ParseError:
        best: list[_Candidate] = []
        best_words = 0
        for candidate in self._candidates:
            found = candidate.pattern.search(segment)
            if found is None:
                continue
            words = len(found.group(0).split())
            if words > best_words:
                best, best_words = [candidate], words
            elif words == best_words:
                best.append(candidate)
        if len(best) == 1:
            return best[0].to_order()
        if best:
            names = [c.name for c in best]
            return ParseError(
                text=segment,
                reason="ambiguous: matches " + ", ".join(names),
                candidates=names,
            )
        for order, pattern in self._caseless:
            if pattern.search(segment):
                cases = ", ".join(c.description for c in order.cases)
                return ParseError(
                    text=segment,
                    reason=f"'{order.description}' needs one of: {cases}",
                    candidates=[f"{order.name}/{c.name}" for c in order.cases],
                )
        return ParseError(text=segment, reason="no order matches")
