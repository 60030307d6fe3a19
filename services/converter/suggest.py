"""Near-misses: the phrases closest to a segment that matched nothing, as suggestions.

A suggestion is only ever offered, never dispatched: the parser returns it in the
`candidates` of an error, and each one is a phrase that parses to exactly one order, so a
panel can send it back in one click. Numbers the person said are kept: "move forwad 2
meters" suggests "move forward 2 meters", never a number they did not say.

Scoring every phrase of a 200-order file costs milliseconds, so only phrases that share a
word with the segment are scored, where a word one letter off counts as shared ("kitchn",
"lift" for "left"): each word is indexed under itself and its one-letter deletions, and two
words one edit apart have one of those in common.

A segment is also scored without its skip words ("the", "please", which the parser
ignores), and the better score counts: each one a person adds would otherwise cost a
sentence with two misspelt words its suggestion ("raech the kichen" scored 76 against
"reach kitchen", "raech kichen" 88). The phrases keep theirs: a phrase shortened to its
distinctive words ("go kitchen") would be close to anything that names a place.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import msgspec
from rapidfuzz import fuzz, process

from voicectl.shared.messages import Order

from .expand import SlotRef
from .model import Command
from .slots import NUMBER_PATTERN, SlotValueError
from .text import whole_words

THRESHOLD = 78.0
"""Lowest score (0-100, `rapidfuzz.fuzz.token_set_ratio`) of a suggestion.

Measured on the shipped orders (tests/test_converter_suggest.py): misheard commands ("turn
lift", "teach kitchen", "reach the kitchen", "weight 10 seconds") score 80-100, everyday
speech ("what is the weather today", "move on", "take it easy") at most 73. Plain `ratio`
and `token_sort_ratio` fell below 75 on dropped or extra words; `WRatio` gave unrelated
sentences 85.
"""
MAX_SUGGESTIONS = 3
MARGIN = 10.0
"""Suggestions scoring this much below the best are left out ("move back 2 meters" for
"move forwad 2 meters", where "move forward 2 meters" scores 97)."""
MAX_QUERY_CHARS = 200
"""Longer segments are not commands anyone mistyped; they get no suggestions."""
MAX_SCORED = 12
"""At most this many phrases are scored, those sharing the most words with the segment."""
COMMON_SHARE = 0.1
"""A word in more than this share of the phrases ('the') does not select phrases."""

_SLOT = "#"
_MAX_CACHED = 4096
_ENCODE = msgspec.json.Encoder().encode
_NUMBERS = re.compile(whole_words(NUMBER_PATTERN))


@dataclass(frozen=True)
class _Phrase:
    text: str
    """The phrase with '#' where a number goes."""
    words: frozenset[str]
    command: Command
    slots: tuple[str, ...]
    """The slot names in the order their '#' appear."""
    order: Order | None
    """What the phrase parses to, for a phrase without slots; None if not one order."""
    unique: bool
    """Whether the phrase parses to its own command alone (checked with sample numbers)."""


class Suggester:
    """Scores a segment against the phrases that share a word with it; keeps the close ones
    that parse to one order."""

    def __init__(
        self,
        commands: Iterable[Command],
        parse: Callable[[str], Order | None],
        skip_words: Iterable[str] = (),
    ) -> None:
        """`parse` turns a phrase into its order, or None; it is called here only.
        `skip_words` are the words the parser ignores."""
        self._skip = frozenset(skip_words)
        self._phrases: list[_Phrase] = []
        seen: set[str] = set()
        for command in commands:
            for template in command.expansion.templates:
                text = " ".join(_SLOT if isinstance(t, SlotRef) else t for t in template)
                if text in seen:
                    continue
                seen.add(text)
                slots = tuple(t.name for t in template if isinstance(t, SlotRef))
                sample = " ".join(
                    _sample(command, t.name) if isinstance(t, SlotRef) else t for t in template
                )
                order = parse(sample)
                unique = order is not None and (order.order, order.case) == (
                    command.order.name,
                    command.case.name if command.case else None,
                )
                self._phrases.append(
                    _Phrase(text, frozenset(text.split()), command, slots, order, unique)
                )
        self._lengths = [len(phrase.text) for phrase in self._phrases]
        by_word: dict[str, list[int]] = {}
        for position, phrase in enumerate(self._phrases):
            for word in phrase.words:
                by_word.setdefault(word, []).append(position)
        common = max(20, COMMON_SHARE * len(self._phrases))
        self._by_variant: dict[str, set[int]] = {}
        """Phrase positions by each distinctive word and its one-letter deletions."""
        for word, positions in by_word.items():
            if word == _SLOT or len(positions) > common:
                continue
            for variant in _deletions(word):
                self._by_variant.setdefault(variant, set()).update(positions)
        self._word_hits: dict[str, set[int]] = {}
        """A cache of `_hits`, emptied when it reaches _MAX_CACHED words."""

    def suggest(self, segment: str) -> list[str]:
        """Up to MAX_SUGGESTIONS phrases for `segment` (normalised), best first, each making
        a different order."""
        if len(segment) > MAX_QUERY_CHARS:
            return []
        numbers = [m.group(0) for m in _NUMBERS.finditer(segment)]
        query = _NUMBERS.sub(_SLOT, segment) if numbers else segment
        closest = self._closest(query)
        if not closest:
            return []
        best = closest[0][1]
        suggestions: dict[bytes, str] = {}
        for phrase, score in closest:
            if score < best - MARGIN or len(suggestions) == MAX_SUGGESTIONS:
                break
            made = _made(phrase, numbers)
            if made is not None:
                text, order = made
                suggestions.setdefault(_ENCODE(order), text)
        return list(suggestions.values())

    def _hits(self, word: str) -> set[int]:
        """The phrases containing `word` or a word one letter off."""
        found = self._word_hits.get(word)
        if found is None:
            if len(self._word_hits) >= _MAX_CACHED:
                self._word_hits.clear()
            variants = _deletions(word)
            found = set().union(*(self._by_variant.get(v, ()) for v in variants))
            self._word_hits[word] = found
        return found

    def _closest(self, query: str) -> list[tuple[_Phrase, float]]:
        """Phrases scoring at least THRESHOLD against `query`, best first."""
        words = query.split()
        hits = [self._hits(word) for word in set(words)]
        several: set[int] = set()
        for first, second in itertools.combinations(hits, 2):
            several |= first & second
        # Phrases sharing two words or more if there are any, else those sharing one; the
        # ones closest in length to the query first (finer ranking cost more than it won).
        size = len(query)
        lengths = self._lengths

        def closer(position: int) -> int:
            return abs(lengths[position] - size)

        pool = several or set().union(*hits)
        if not pool:
            return []
        positions = sorted(pool, key=closer)[:MAX_SCORED]
        texts = [self._phrases[p].text for p in positions]
        core = " ".join(word for word in words if word not in self._skip)
        best: dict[int, float] = {}
        for said in dict.fromkeys((query, core)):
            if not said:
                continue
            heard = frozenset(said.split())
            found = process.extract(
                said, texts, scorer=fuzz.token_set_ratio, score_cutoff=THRESHOLD, limit=None
            )
            for text, score, index in found:
                if heard < self._phrases[positions[index]].words:
                    # token_set_ratio gives 100 to any part of a phrase ("turn" for "turn
                    # left"); a fragment must be close as a whole instead.
                    score = fuzz.ratio(said, text, score_cutoff=THRESHOLD)
                if score:
                    best[index] = max(score, best.get(index, 0.0))
        closest = [(self._phrases[positions[index]], score) for index, score in best.items()]
        closest.sort(key=lambda item: -item[1])
        return closest


def _made(phrase: _Phrase, numbers: list[str]) -> tuple[str, Order] | None:
    """The phrase with the person's numbers in its slots and the order it makes, or None
    if the numbers do not fit or it would not make exactly that order."""
    if not phrase.slots:
        return (phrase.text, phrase.order) if phrase.order is not None else None
    if not phrase.unique or len(phrase.slots) != len(numbers):
        return None
    spoken: dict[str, str | None] = dict(zip(phrase.slots, numbers, strict=True))
    try:
        order = phrase.command.to_order(spoken)
    except SlotValueError:
        return None
    in_turn = iter(numbers)
    return " ".join(next(in_turn) if w == _SLOT else w for w in phrase.text.split()), order


def _sample(command: Command, slot: str) -> str:
    """A number the slot accepts, to check what a phrase with it parses to."""
    return f"{command.slots[slot].grid(limit=1)[0]:g}"


def _deletions(word: str) -> set[str]:
    """The word and the word with any one letter left out."""
    if len(word) < 3:
        return {word}
    return {word, *(word[:i] + word[i + 1 :] for i in range(len(word)))}
