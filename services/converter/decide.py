"""Two ears, one decision: whether and which orders an utterance becomes.

The recogniser hears every utterance twice (services/stt/moonshine_engine.py): pocketsphinx
bound to the orders' grammar, with its own verdict (its judge's), and Moonshine, a neural
model bound to nothing, whose words this module parses. Moonshine also says how likely it
finds the grammar's words beside its own (`Transcription.support`). Each ear gives a
`Reading`; `decide` weighs them by `Rule`, chosen on the dev split of harness/speech_set.py
and reported on its test split (docs/benchmarks.md, docs/speech.md):

- Both make the same orders: taken, and a value the grammar doubted is no longer doubted.
- They make different orders: nothing, never a guess between them.
- Only Moonshine's words make orders: taken. It heard the person's words, free of the
  grammar; on the dev split its orders were never wrong. A number in them that has a
  -teen or -ty twin ("fifty", "fifteen") is asked, offering the twin.
- Only the grammar's: taken when Moonshine finds them nearly as likely as its own words
  ("breach the kitchen" heard for "reach the kitchen"), and Moonshine heard no other
  numbers. A person saying "front left" is heard as "front left" by Moonshine and as "turn
  to left" by the grammar, which Moonshine finds far less likely: nothing. The same holds
  for grammar words its own judge rejected (`Rule.overrule`).

No order stands on a value that neither ear heard, and a doubt only offers what an ear
heard. Moonshine writing "to" or "too" where a number stands before its unit ("drive back
to meters") is read as "two", and asked unless the grammar heard "two" there too.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace

from voicectl.shared.messages import Doubt, Hearing, Order, ParseProblem, Transcript, Transcription

from .parser import Parser
from .slots import NUMBER_PATTERN, read_number, say_number
from .text import normalise

GRAMMAR = "grammar"
SOUNDS_LIKE_TWO = ("to", "too")
_NUMBERS = re.compile(rf"(?<!\S){NUMBER_PATTERN}(?!\S)")
_DIGITS = re.compile(r"(?<!\S)-?\d+(?:\.\d+)?(?!\S)")
_LIST_NUMBER = re.compile(r"^\s*\d+[.)]\s+")
_TEENS = ["thirteen", "fourteen", "fifteen", "sixteen", "seventeen", "eighteen", "nineteen"]
_TENS = ["thirty", "forty", "fifty", "sixty", "seventy", "eighty", "ninety"]
_PARTNERS = {
    **dict(zip(_TEENS, _TENS, strict=True)),
    **dict(zip(_TENS, _TEENS, strict=True)),
    **{str(n): str((n - 10) * 10) for n in range(13, 20)},
    **{str((n - 10) * 10): str(n) for n in range(13, 20)},
}
"""Numbers that people and models confuse with another: "fifteen" and "fifty"."""


@dataclass(frozen=True)
class Rule:
    """The decision's settings (bench/stt.py sweeps them on the dev split)."""

    support: float = -1.0
    """How much less likely than its own words, in nats a token, Moonshine may find the
    grammar's words and still back orders that its own words do not make. On the dev split
    the grammar's non-commands were all under -2.6; -1.5 let half a command through ("turn
    left" for "turn left then reach the kitchen" at -1.49, in pink noise at 5 dB)."""
    overrule: bool = True
    """Whether that support also stands for grammar words the judge rejected."""


SHIPPED = Rule()


@dataclass(frozen=True)
class Reading:
    """What one ear's words make."""

    ear: str
    text: str
    """The words as the proposal shows them (a doubt's position counts these words)."""
    orders: list[Order] = field(default_factory=list)
    """The whole orders its words make, if they make some (even when not `accepted`)."""
    accepted: bool = False
    """Its words make whole orders and the ear vouches for them."""
    reason: str = ""
    """Why not, in plain words, when not accepted."""
    candidates: list[str] = field(default_factory=list)
    """What the words may have meant, when they did not parse."""
    doubts: list[Doubt] = field(default_factory=list)
    support: float | None = None
    """A second ear's likelihood of the grammar's words (`Transcription.support`)."""

    @property
    def heard(self) -> bool:
        """Whether the ear heard words at all."""
        return bool(self.text)

    def hearing(self) -> Hearing:
        if self.accepted:
            made = "; ".join(order.description for order in self.orders)
            verdict = f"{made} (asks about '{self.doubts[0].words}')" if self.doubts else made
        else:
            verdict = self.reason or "nothing heard"
        return Hearing(ear=self.ear, text=self.text, accepted=self.accepted, verdict=verdict)


@dataclass(frozen=True)
class Decision:
    """What the utterance becomes: orders (perhaps asked about) or nothing, and why."""

    text: str
    orders: list[Order]
    doubts: list[Doubt]
    rejected: bool
    reason: str
    """One line for a person: why these orders, or why none."""
    candidates: list[str]
    hearings: list[Hearing]


def readings(transcript: Transcript, parser: Parser) -> tuple[Reading, Reading | None]:
    """What each ear of a final transcript heard, read by `parser`."""
    heard = transcript.transcription
    second = None if heard is None else free_reading(heard, parser)
    return grammar_reading(transcript, parser), second


def grammar_reading(transcript: Transcript, parser: Parser) -> Reading:
    """The grammar's result, its own verdict, and what the converter makes of its words."""
    text = transcript.text
    result = parser.parse(text) if text else None
    made = result.orders if result is not None and not result.errors else []
    if transcript.rejected:
        reason = transcript.reason or "not a command"
        if "not a command" not in reason:
            reason = f"not a command: {reason}"
        return Reading(GRAMMAR, text, made, reason=reason)
    if result is None or result.errors or not result.orders:
        return not_a_command(GRAMMAR, text, result.errors if result is not None else [])
    return Reading(GRAMMAR, text, result.orders, accepted=True, doubts=transcript.doubts)


def free_reading(heard: Transcription, parser: Parser) -> Reading:
    """A free transcript's words, parsed whole; "to" before a unit is tried as "two"."""
    ear, support = heard.engine, heard.support
    text = " ".join(once(normalise(parser.spell_units(spoken(heard.text))).split()))
    if not text:
        return Reading(ear, "", reason="heard nothing", support=support)
    result = parser.parse(text)
    if result.orders and not result.errors:
        return Reading(ear, text, result.orders, accepted=True, support=support)
    words = text.split(" ")
    for position, word in enumerate(words[:-1]):
        if word in SOUNDS_LIKE_TWO and words[position + 1] in parser.unit_words:
            guess = [*words[:position], "two", *words[position + 1 :]]
            second = parser.parse(" ".join(guess))
            if second.orders and not second.errors:
                doubt = Doubt(position=position, words="two", confidence=0.5)
                return Reading(
                    ear,
                    " ".join(guess),
                    second.orders,
                    accepted=True,
                    doubts=[doubt],
                    support=support,
                )
    return not_a_command(ear, text, result.errors, support)


def not_a_command(
    ear: str, text: str, errors: list[ParseProblem], support: float | None = None
) -> Reading:
    """Words that make no whole order: the first problem, and what it may have meant."""
    problem = errors[0] if errors else None
    why = f" ('{problem.text}': {problem.reason})" if problem else ""
    return Reading(
        ear,
        text,
        reason=f"I heard '{text}': not a command{why}",
        candidates=problem.candidates if problem else [],
        support=support,
    )


def once(words: list[str]) -> list[str]:
    """`words` without the repeat a sequence model falls into when audio goes on after the
    speech: "turn right turn right", "go to the bathroom please go to the bath", "move
    ahead six meters and move ahead six" become the phrase once. Only a tail that says the
    beginning again goes (its last word perhaps cut short), after an "and" or not."""
    for period in range(1, len(words)):
        rest = words[period:]
        if rest[:1] == ["and"] and len(rest) > 1:
            rest = rest[1:]
        *whole, last = rest
        again = [words[i % period] for i in range(len(rest))]
        if whole == again[:-1] and again[-1].startswith(last):
            return words[:period]
    return words


def spoken(text: str) -> str:
    """A free transcript without what a model adds that nobody says: a list number
    ("1. Rotate left 90 degrees.")."""
    return _LIST_NUMBER.sub("", text)


def decide(grammar: Reading, second: Reading | None, rule: Rule = SHIPPED) -> Decision:
    """The one decision for an utterance heard by the grammar and perhaps a second ear."""
    if second is None:
        return _take(grammar, [grammar.hearing()], "")
    hearings = [grammar.hearing(), second.hearing()]
    both = f"'{grammar.text}' or '{second.text}'"
    if second.accepted:
        if grammar.accepted and grammar.orders != second.orders:
            return _refuse(second, hearings, f"the two ears disagree ({both}): say it again")
        if grammar.orders == second.orders:
            return _take(replace(second, doubts=[]), hearings, f"both heard {_said(second)}")
        asked = replace(second, doubts=second.doubts or _teens_or_tens(second.text))
        return _take(asked, hearings, f"{second.ear} heard {_said(second)}")
    if not grammar.orders or not (grammar.accepted or rule.overrule):
        rejected = second if second.heard else grammar
        return _refuse(rejected, hearings, rejected.reason)
    if second.support is None or second.support < rule.support:
        why = second.reason if second.heard else f"{second.ear} heard nothing"
        return _refuse(second, hearings, f"{why} (the grammar heard '{grammar.text}')")
    if numbers(second.text) and numbers(grammar.text) != numbers(second.text):
        return _refuse(second, hearings, f"the two ears heard other numbers ({both}): say it again")
    backed = replace(grammar, accepted=True, doubts=[])
    return _take(backed, hearings, f"both heard {_said(grammar)}")


def _teens_or_tens(text: str) -> list[Doubt]:
    """A number only Moonshine heard that sounds like its -teen or -ty ("fifty" and
    "fifteen": in babble it wrote 50 for a person's 15) is asked, offering the other."""
    for position, word in enumerate(text.split(" ")):
        other = _PARTNERS.get(word)
        if other is not None:
            return [Doubt(position=position, words=word, alternatives=[other], confidence=0.5)]
    return []


def numbers(text: str) -> list[float]:
    """The numbers a transcript says, in order, digits or words."""
    found = (read_number(match.group(0)) for match in _NUMBERS.finditer(_spelled(text)))
    return [value for value in found if value is not None]


def _spelled(text: str) -> str:
    def words(match: re.Match[str]) -> str:
        try:
            return say_number(float(match.group(0)))
        except ValueError:
            return match.group(0)

    return _DIGITS.sub(words, text)


def _take(reading: Reading, hearings: list[Hearing], why: str) -> Decision:
    if not reading.accepted:
        return _refuse(reading, hearings, reading.reason)
    return Decision(
        text=reading.text,
        orders=reading.orders,
        doubts=reading.doubts,
        rejected=False,
        reason=why,
        candidates=[],
        hearings=hearings,
    )


def _refuse(reading: Reading, hearings: list[Hearing], why: str) -> Decision:
    return Decision(
        text=reading.text,
        orders=[],
        doubts=[],
        rejected=True,
        reason=why or "not a command",
        candidates=reading.candidates,
        hearings=hearings,
    )


def _said(reading: Reading) -> str:
    return "'" + "; ".join(order.description for order in reading.orders) + "'"


def problem(decision: Decision) -> ParseProblem:
    """A rejected decision as the proposal's one error."""
    return ParseProblem(text=decision.text, reason=decision.reason, candidates=decision.candidates)
