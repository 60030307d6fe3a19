"""Three ears, one decision: whether and which orders an utterance becomes.

The recogniser hears every utterance with two ears (services/stt/ears.py): pocketsphinx
bound to the orders' grammar, with its own verdict (its judge's), and Moonshine, a neural
model bound to nothing. When those two leave a doubt, a third, Whisper, hears it too. Each
ear gives a `Reading`; `decide` weighs them by `Rule`, chosen on the dev split of
harness/speech_set.py and reported on its test split (docs/benchmarks.md). The rules,
written down in docs/speech.md ("How the ears decide") and walked by a property test
(tests/test_decide.py):

- An ear *claims* the orders its words make: a free ear (Moonshine, Whisper) when its
  words make whole orders, the grammar whenever its words do, vouched for by its judge or
  not. Only claimed orders are ever taken, exactly as an ear made them.
- Two or more ears claiming the same orders, and no other claim: taken. Two free ears
  claiming the same orders outweigh the grammar's other orders only when its own judge
  rejected them (`Rule.majority`). Any other claims that differ are a question offering
  each of them (`Rule.ask`), never a pick between them.
- The grammar alone: taken when every free ear that heard words finds them nearly as
  likely as its own (`Rule.support`) and heard no other numbers, and at least one did.
  An ear that heard nothing backs nothing.
- One free ear alone: taken when no other ear claims orders (`Rule.lone`); its words are
  the person's, free of the grammar.
- Absence of evidence never clears a doubt: a value an ear doubted stays asked unless
  another ear that claims the same orders heard it without doubt. Every number of the
  -teen/-ty pairs ("fifteen", "fifty") that the grammar did not hear too is asked.
- One ear is not two. In a language only one ear hears (`Transcript.alone`: Whisper, for
  Spanish or German), nothing can agree with it: its orders are sent by themselves only
  when its own evidence passes (`Rule.alone`); else they are a confirmation, read back
  and sent only on a yes (`Decision.confirm`), never sent by themselves.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import msgspec

from voicectl.shared.messages import Doubt, Hearing, Order, ParseProblem, Transcript, Transcription

from .parser import MAX_TEXT_CHARS, Parser
from .slots import NUMBER_PATTERN, read_number, say_number
from .snap import snapped
from .text import normalise

GRAMMAR = "grammar"
HYPOTHESIS = "another of its hypotheses"
SNAPPED = "its words snapped to the orders'"
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
    """How much less likely than its own words, in nats a token, a free ear may find the
    grammar's words and still back orders that its own words do not make. On the dev split
    the grammar's non-commands were all under -2.6 for Moonshine; -1.5 let half a command
    through ("turn left" for "turn left then reach the kitchen" at -1.49, in pink noise at
    5 dB)."""
    overrule: bool = True
    """Whether that support also stands for grammar words the judge rejected."""
    majority: bool = True
    """Whether two free ears claiming the same orders outweigh the grammar's other orders
    that its own judge rejected."""
    ask: bool = True
    """Whether ears claiming different orders are asked which ("'turn left fifteen
    degrees' or 'turn right 15 degrees'?"), rather than refused; never sent either way."""
    lone: str = "unclaimed"
    """When one free ear's orders are taken alone: 'unclaimed' (no other ear claims orders),
    'unheard' (and no other free ear heard words at all) or 'never'."""
    alone: str = "confirm"
    """In a language one ear alone hears, when its orders are sent without a confirmation:
    'confirm' (never: every one is read back and waits for a yes) or 'evidence' (when its
    own evidence passes `alone_confidence`, `alone_no_speech` and its second decode made
    the same orders). Chosen on the dev split of harness/speech_languages.py
    (docs/benchmarks.md, "Other languages")."""
    alone_confidence: float = 0.8
    """The lowest geometric mean of its tokens' probabilities that may send alone."""
    alone_no_speech: float = 0.1
    """The highest probability it gave to the audio holding no speech."""


SHIPPED = Rule()


@dataclass(frozen=True)
class Evidence:
    """What an ear that hears alone says of its own words (services/stt/ears.py, `_Alone`)."""

    confidence: float
    """The geometric mean of its tokens' probabilities."""
    no_speech: float | None
    """Its probability that the audio held no speech."""
    second: bool | None
    """Whether its second decode (prompted with the orders' words) made the same orders;
    None when it made none (its first decode heard no words)."""
    prompted: bool = False
    """The orders are the prompted decode's, the first having made none: the prompt may
    have put them there, so they are never sent without a yes."""
    guess: str = ""
    """How the orders were guessed when neither decode's best words made any (`HYPOTHESIS`,
    `SNAPPED`): a guess is never sent without a yes."""

    def passes(self, rule: Rule) -> bool:
        return (
            not self.prompted
            and not self.guess
            and self.second is True
            and self.confidence >= rule.alone_confidence
            and self.no_speech is not None
            and self.no_speech <= rule.alone_no_speech
        )


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
    """This ear's likelihood of the grammar's words (`Transcription.support`)."""
    evidence: Evidence | None = None
    """For an ear that hears its language alone: what it says of its own words."""

    @property
    def heard(self) -> bool:
        """Whether the ear heard words at all."""
        return bool(self.text)

    @property
    def claims(self) -> bool:
        """Whether this reading puts orders forward: a free ear's accepted words, or the
        grammar's words whatever its judge said."""
        return bool(self.orders) and (self.accepted or self.ear == GRAMMAR)

    def hearing(self) -> Hearing:
        if self.accepted:
            made = "; ".join(order.description for order in self.orders)
            asked = ", ".join(f"'{doubt.words}'" for doubt in self.doubts)
            verdict = f"{made} (asks about {asked})" if asked else made
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
    confirm: bool = False
    """Sent only on a yes: heard by one ear without the evidence to send it alone."""


def readings(transcript: Transcript, parser: Parser) -> tuple[Reading, list[Reading]]:
    """What each ear of a final transcript heard, read by `parser`: the grammar's, and the
    free ears' that heard the utterance; in a language one ear hears alone, that ear's,
    with its evidence, beside a grammar that heard nothing."""
    if transcript.alone:
        nobody = Reading(GRAMMAR, "", reason="no grammar's ear in this language")
        heard = transcript.transcription
        if heard is None:
            return nobody, []
        return nobody, [alone_reading(heard, parser)]
    free = [
        free_reading(heard, parser)
        for heard in (transcript.transcription, transcript.third)
        if heard is not None
    ]
    return grammar_reading(transcript, parser), free


def grammar_reading(transcript: Transcript, parser: Parser) -> Reading:
    """The grammar's result, its own verdict, and what the converter makes of its words."""
    text = transcript.text
    result = parser.parse(text) if text else None
    made = result.orders if result is not None and not result.errors else []
    if transcript.rejected:
        reason = transcript.reason or "not a command"
        if "not a command" not in reason:
            reason = f"not a command: {reason}"
        return Reading(GRAMMAR, text, made, reason=reason, doubts=transcript.doubts)
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


def alone_reading(heard: Transcription, parser: Parser) -> Reading:
    """The words of an ear that hears its language alone, with its own evidence: the
    model's confidence and no-speech probability, and whether a second decode of it made
    the same orders. When neither decode's best words make orders, their other hypotheses
    are read, then every hypothesis's words snapped to the orders' (snap.py): the first
    that makes whole orders is a guess, only ever read back for a yes."""
    reading = free_reading(heard, parser)
    if heard.second is None and reading.claims:
        return replace(reading, evidence=Evidence(heard.confidence, heard.no_speech, None))
    again = free_reading(msgspec.structs.replace(heard, text=heard.second or ""), parser)
    if not reading.claims and again.claims:  # heard as orders only with the prompt
        evidence = Evidence(heard.confidence, heard.no_speech, None, prompted=True)
        return replace(again, evidence=evidence)
    if not reading.claims:
        return _guessed(heard, parser) or replace(
            reading, evidence=Evidence(heard.confidence, heard.no_speech, None)
        )
    second = again.claims and again.orders == reading.orders
    return replace(reading, evidence=Evidence(heard.confidence, heard.no_speech, second))


def _guessed(heard: Transcription, parser: Parser) -> Reading | None:
    """Orders from the decodes' other hypotheses, else from the words of any hypothesis
    snapped to the orders' words; None when none makes whole orders."""
    # The parser reads no more than MAX_TEXT_CHARS (longer text makes no orders): never
    # snap more. Snapped only when no hypothesis as heard makes orders.
    texts = [heard.text, heard.second or "", *heard.alternatives]
    tries = itertools.chain(
        ((text, HYPOTHESIS) for text in heard.alternatives),
        (
            (snapped(text, parser.vocabulary), SNAPPED)
            for text in texts
            if len(text) <= MAX_TEXT_CHARS
        ),
    )
    for text, how in tries:
        if not text:  # nothing snapped
            continue
        guess = free_reading(msgspec.structs.replace(heard, text=text), parser)
        if guess.claims:
            evidence = Evidence(heard.confidence, heard.no_speech, None, guess=how)
            return replace(guess, evidence=evidence)
    return None


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


def decide(grammar: Reading, free: Sequence[Reading] = (), rule: Rule = SHIPPED) -> Decision:
    """The one decision for an utterance heard by the grammar and the free ears."""
    ears = [grammar, *free]
    hearings = [reading.hearing() for reading in ears]
    if not free:  # an engine with the grammar's ear alone: its judge decides
        return (
            _take(grammar, hearings, "")
            if grammar.accepted
            else _refuse(grammar, hearings, grammar.reason)
        )
    if len(free) == 1 and free[0].evidence is not None and not grammar.text:
        return _lone(free[0], hearings, rule)
    claims = [reading for reading in ears if reading.claims]
    if not claims:
        said = [reading for reading in free if reading.text]
        refused = said[0] if said else grammar
        return _refuse(refused, hearings, refused.reason or "nothing heard")
    kinds = _distinct(claims)
    if len(kinds) > 1:
        return _majority(grammar, claims, kinds, hearings, rule)
    if len(claims) >= 2:
        return _agreed(grammar, claims, hearings)
    (claim,) = claims
    if claim is grammar:
        return _backed(grammar, free, hearings, rule)
    return _alone(claim, grammar, free, hearings, rule)


def _distinct(claims: Sequence[Reading]) -> list[list[Order]]:
    found: list[list[Order]] = []
    for reading in claims:
        if reading.orders not in found:
            found.append(reading.orders)
    return found


def _majority(
    grammar: Reading,
    claims: list[Reading],
    kinds: list[list[Order]],
    hearings: list[Hearing],
    rule: Rule,
) -> Decision:
    """Ears that claim different orders: nothing, unless two free ears agree against the
    grammar's rejected words (`Rule.majority`)."""
    shown = " or ".join(f"'{reading.text}'" for reading in claims)
    free = [reading for reading in claims if reading is not grammar]
    agreeing = [r for r in free if r.orders == free[0].orders] if free else []
    against = [reading for reading in claims if reading not in agreeing]
    if (
        rule.majority
        and len(kinds) == 2
        and len(agreeing) >= 2
        and against == [grammar]
        and not grammar.accepted
    ):
        return _agreed(grammar, agreeing, hearings, outvoted=True)
    if not rule.ask:
        return _refuse(claims[-1], hearings, f"the ears disagree ({shown}): say it again")
    return _asked(grammar, claims, hearings)


def _asked(grammar: Reading, claims: list[Reading], hearings: list[Hearing]) -> Decision:
    """Ears that claim different orders: a question offering each claim, the free ears'
    words first (the person's), never orders sent by themselves."""
    ordered = sorted(claims, key=lambda reading: reading is grammar)
    first, texts = ordered[0], []
    for reading in ordered[1:]:
        if reading.orders != first.orders and reading.text not in texts:
            texts.append(reading.text)
    question = Doubt(position=0, words=first.text, alternatives=texts, confidence=0.0)
    said = " or ".join(f"'{text}'" for text in [first.text, *texts])
    why = f"the ears heard different things ({said}): which?"
    return _take(replace(first, accepted=True, doubts=[question]), hearings, why)


def _agreed(
    grammar: Reading, claims: list[Reading], hearings: list[Hearing], outvoted: bool = False
) -> Decision:
    """Two or more ears claim the same orders: shown in a free ear's words (the person's),
    each doubt settled only by another claimer that heard that value without doubt."""
    free = [reading for reading in claims if reading is not grammar]
    shown = free[0] if free else claims[0]
    others = [reading for reading in claims if reading is not shown]
    doubts = [d for d in shown.doubts if not any(_heard_surely(o, d) for o in others)]
    if grammar not in claims or outvoted:
        doubts = _merged(doubts, _teens_or_tens(shown.text))
    why = f"{_named(claims)} heard {_said(shown)}"
    if outvoted:
        why += f" (the grammar's '{grammar.text}' was rejected)"
    return _take(replace(shown, accepted=True, doubts=doubts), hearings, why)


def _backed(
    grammar: Reading, free: Sequence[Reading], hearings: list[Hearing], rule: Rule
) -> Decision:
    """Only the grammar claims orders: taken if every free ear that heard words finds them
    nearly as likely as its own words and heard no other numbers, and one did."""
    if not grammar.accepted and not rule.overrule:
        refused = next((reading for reading in free if reading.text), grammar)
        return _refuse(refused, hearings, refused.reason)
    heard = [reading for reading in free if reading.text]
    if not heard:
        ears = _named(free) if free else "no other ear"
        return _refuse(
            grammar, hearings, f"{ears} heard nothing (the grammar heard '{grammar.text}')"
        )
    for reading in heard:
        if reading.support is None or reading.support < rule.support:
            return _refuse(
                reading, hearings, f"{reading.reason} (the grammar heard '{grammar.text}')"
            )
        if numbers(reading.text) and numbers(reading.text) != numbers(grammar.text):
            both = f"'{grammar.text}' or '{reading.text}'"
            return _refuse(
                reading, hearings, f"the ears heard other numbers ({both}): say it again"
            )
    settled = numbers(grammar.text) and any(
        numbers(reading.text) == numbers(grammar.text) for reading in heard
    )
    doubts = [] if settled else grammar.doubts
    ears = _named([grammar, *heard])
    return _take(
        replace(grammar, accepted=True, doubts=doubts), hearings, f"{ears} heard {_said(grammar)}"
    )


def _alone(
    claim: Reading, grammar: Reading, free: Sequence[Reading], hearings: list[Hearing], rule: Rule
) -> Decision:
    """One free ear claims orders, and no other ear claims any."""
    others = [reading for reading in free if reading is not claim and reading.heard]
    if rule.lone == "never" or (others and rule.lone == "unheard"):
        shown = others[0] if others else claim
        why = f"{claim.ear} heard {_said(claim)}, {shown.ear} heard '{shown.text}': say it again"
        return _refuse(claim, hearings, why)
    doubts = _merged(claim.doubts, _teens_or_tens(claim.text))
    return _take(replace(claim, doubts=doubts), hearings, f"{claim.ear} heard {_said(claim)}")


def _lone(reading: Reading, hearings: list[Hearing], rule: Rule) -> Decision:
    """The one ear of a language claims orders: sent alone only if its own evidence
    passes the rule; else read back, and sent only on a yes. Its number doubts are asked
    either way."""
    if not reading.claims:
        return _refuse(reading, hearings, reading.reason or "nothing heard")
    doubts = _merged(reading.doubts, _teens_or_tens(reading.text))
    evidence = reading.evidence
    said = f"{reading.ear} alone heard {_said(reading)}"
    if evidence is not None and evidence.guess:
        said += f" ({evidence.guess})"
    elif evidence is not None and evidence.prompted:
        said += " (prompted with the orders' words)"
    if rule.alone == "evidence" and evidence is not None and evidence.passes(rule):
        return _take(replace(reading, doubts=doubts), hearings, f"{said}, and again")
    if not doubts:
        confidence = evidence.confidence if evidence is not None else 0.0
        doubts = [Doubt(position=0, words=reading.text, confidence=confidence)]
    decision = _take(replace(reading, doubts=doubts), hearings, f"{said}: confirm it")
    return replace(decision, confirm=True)


def _heard_surely(reading: Reading, doubt: Doubt) -> bool:
    """Whether `reading`, which claims the same orders, heard the doubted value without
    doubting it itself."""
    return not any(own.words == doubt.words for own in reading.doubts)


def _merged(doubts: list[Doubt], more: list[Doubt]) -> list[Doubt]:
    taken = {doubt.position for doubt in doubts}
    return sorted(
        [*doubts, *(d for d in more if d.position not in taken)], key=lambda d: d.position
    )


def _teens_or_tens(text: str) -> list[Doubt]:
    """Every number that sounds like its -teen or -ty ("fifty" and "fifteen": in babble
    Moonshine wrote 50 for a person's 15) is asked, offering the other."""
    return [
        Doubt(position=position, words=word, alternatives=[_PARTNERS[word]], confidence=0.5)
        for position, word in enumerate(text.split(" "))
        if word in _PARTNERS
    ]


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


def _named(readings: Sequence[Reading]) -> str:
    """The ears of `readings` for a person: "grammar, moonshine and whisper"."""
    names = [reading.ear for reading in readings]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _said(reading: Reading) -> str:
    return "'" + "; ".join(order.description for order in reading.orders) + "'"


def problem(decision: Decision) -> ParseProblem:
    """A rejected decision as the proposal's one error."""
    return ParseProblem(text=decision.text, reason=decision.reason, candidates=decision.candidates)
