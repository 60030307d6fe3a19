"""A second opinion on what the grammar heard: accept it, doubt one value, or reject it.

A grammar forces a best match out of any speech: "could you pass the salt" comes out as
some command, and a number said outside the grammar as a nearby one. Two signals catch
that, one from outside the grammar and one from inside it:

- **Foreign words.** An unconstrained decode of the same audio (pocketsphinx's general
  English language model) transcribes ordinary speech nearly word for word; the posterior
  mass of the words it hears that no command contains says "this was not a command". A
  foreign word weighs only as much as it sounds unlike the grammar's words at the same
  time: "reach the dumps there" is the open decode's spelling of "reach the dumpster",
  "turn on the lights" is not "turn a left". Synthetic voices it cannot transcribe give it
  junk with low posteriors, which weighs little.
- **The grammar's own doubt.** Each word of the grammar's result carries its posterior in
  the grammar search's lattice: how much of the probability of every path the grammar
  allows went through that word at that time. "drive ahead one meter" said as "drive back
  one meter" in a reverberant room came out with "ahead" at 0.58, where words that were
  said reach 0.9 and more. A command word below `min_word_posterior` rejects the utterance
  unless the open decode heard that word too; a value below `min_value_posterior` is a
  doubt.
- **Values.** A spoken number is also compared with the open decode: when it heard another
  number there ("two" where the grammar says "ten"), or none that matches, the value is a
  doubt, to be asked, never guessed.
- **Words squeezed in.** A phone lasts at least three 10 ms frames in pocketsphinx's
  models (three emitting states, none skipped). A word of the grammar's path no longer
  than that was not said: the search pressed it into the gap between words that were,
  because the grammar needs it there (in babble, "move forward" became "turn a left then
  move forward", its "turn" 90 ms long). The utterance is rejected.

Requiring the open decode to hear the command words as well (its "support") rejected most
commands in noise and in voices it cannot transcribe, for no fewer wrong orders than the
lattice posteriors. The thresholds are tuned on the development split of
harness/speech_set.py and reported on its test split (docs/benchmarks.md).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from rapidfuzz.distance import Levenshtein

from voicectl.shared.messages import Doubt

ALIKE = 0.75
"""Words at least this alike sound like each other to the judge ("crimes"/"primes")."""
SUPPORTS = 0.6
"""An open word at least this alike to a command word at the same time supports it."""
FRAMES_PER_PHONE = 3
"""The fewest frames a phone can last in pocketsphinx's models: three emitting states."""


def filler(text: str) -> bool:
    """Not a word: a decoder's marker of silence, noise or unknown speech ("<sil>",
    "[NOISE]", "[SPEECH]", Vosk's "[unk]")."""
    return text[:1] in ("[", "<")


@dataclass(frozen=True)
class Word:
    """A word of a decode, in 10 ms frames from the start of the utterance's audio."""

    text: str
    start: int
    end: int
    posterior: float = 1.0


@dataclass(frozen=True)
class Thresholds:
    max_foreign: float = 1.6
    """Posterior mass of non-command words, each weighed by how unlike the grammar's words
    at its time it sounds, above which the utterance is not a command."""
    min_word_posterior: float = 0.75
    """A command word less sure than this in the grammar's lattice, and not heard by the open
    decode too, makes the utterance a rejection."""
    min_value_posterior: float = 0.75
    """A value less sure than this in the grammar's lattice is a doubt."""
    squeezed: float = 1.0
    """A grammar word lasting at most this many times its shortest possible length
    (`FRAMES_PER_PHONE` a phone) was squeezed in, not said; 0 turns the rule off."""


OFF = Thresholds(
    max_foreign=math.inf,
    min_word_posterior=0.0,
    min_value_posterior=0.0,
    squeezed=0.0,
)
"""The grammar alone: what the benchmark compares the judge with."""


@dataclass(frozen=True)
class Vocabulary:
    """The words of the grammar in use, and how to tell two words that sound alike."""

    words: frozenset[str]
    skip_words: frozenset[str]
    number_words: frozenset[str]
    sounds: Callable[[str], frozenset[str]]
    """A word's pronunciations (phone strings); words sharing one sound the same."""

    def same(self, a: str, b: str) -> bool:
        return a == b or bool(self.sounds(a) & self.sounds(b))

    def alike(self, a: str, b: str) -> float:
        """How alike two words or runs of words sound, 0..1: one minus the phone edit
        distance over the longer pronunciation ("crimes" and "primes" are 0.8)."""
        if a == b:
            return 1.0
        best = 0.0
        for one in self._spoken(a):
            for other in self._spoken(b):
                best = max(best, Levenshtein.normalized_similarity(one, other))
        return best

    def _spoken(self, words: str) -> list[list[str]]:
        """Every pronunciation of a run of words, as lists of phones."""
        runs: list[list[str]] = [[]]
        for word in words.split():
            variants = self.sounds(word) or frozenset({word})
            runs = [run + v.split() for run in runs for v in sorted(variants)][:8]
        return runs

    def known(self, word: str) -> bool:
        return word in self.words or any(self.alike(word, w) >= ALIKE for w in self.words)


@dataclass(frozen=True)
class Verdict:
    rejection: str
    """Why it is not a command, in plain words; '' when it is (possibly with doubts)."""
    heard: str
    """The open decode's transcript: what the person seems to have said."""
    confidences: list[float] = field(default_factory=list)
    """Per word of the transcript, 0..1: its posterior in the grammar's lattice, or the open
    decode's for a command word it heard too, whichever is higher; a value's is the lower of
    the two, and 0 when the open decode heard another number."""
    doubts: list[Doubt] = field(default_factory=list)
    foreign: float = 0.0
    """The posterior mass of words the open decode heard that no command has, each weighed
    by how unlike the grammar's words at the same time it sounds."""
    support: float = 0.0
    """The share of command words the open decode heard too (reported, not required)."""


@dataclass(frozen=True)
class _Token:
    """A command word, or a run of number words (one value)."""

    first: int
    words: list[Word]
    value: bool

    @property
    def start(self) -> int:
        return self.words[0].start

    @property
    def end(self) -> int:
        return self.words[-1].end

    @property
    def text(self) -> str:
        return " ".join(w.text for w in self.words)


def judge(
    grammar: list[Word], heard: list[Word], vocabulary: Vocabulary, thresholds: Thresholds
) -> Verdict:
    """Accept, doubt or reject what the grammar heard (its words carry their lattice
    posteriors), given what the open decode heard."""
    heard = [w for w in heard if not filler(w.text)]
    said = " ".join(w.text for w in heard)
    confidences = [round(w.posterior, 3) for w in grammar]
    foreign = round(_unexplained(grammar, heard, vocabulary), 3)
    tokens = list(_tokens(grammar, vocabulary))
    commands = [t for t in tokens if not t.value]
    supported = 0
    unsure: list[_Token] = []
    for token in commands:
        match = _support(token, heard, vocabulary)
        supported += match > 0
        posterior = token.words[0].posterior
        confidences[token.first] = round(max(posterior, match), 3)
        if posterior < thresholds.min_word_posterior and match == 0:
            unsure.append(token)
    support = round(supported / len(commands), 3) if commands else 0.0
    if foreign > thresholds.max_foreign or any(
        _squeezed(w, vocabulary, thresholds.squeezed) for w in grammar
    ):
        return Verdict(_not_a_command(said), said, confidences, [], foreign, support)
    if unsure:
        doubtful = ", ".join(f"'{t.text}'" for t in unsure)
        reason = f"not sure I heard {doubtful}: say it again"
        return Verdict(reason, said, confidences, [], foreign, support)
    doubts = []
    for token in (t for t in tokens if t.value):
        posterior = min(w.posterior for w in token.words)
        others = _overlapping(token, heard)
        numbers = [
            w for w in others if w.text in vocabulary.number_words or _numeric(w, vocabulary)
        ]
        spoken = [_as_number(w.text, vocabulary) for w in numbers]
        surely = min((w.posterior for w in numbers), default=0.0)
        agree = len(spoken) == len(token.words) and all(
            vocabulary.same(a, b.text) for a, b in zip(spoken, token.words, strict=True)
        )
        confidence = round(min(posterior, surely) if agree else 0.0, 3)
        for offset in range(len(token.words)):
            confidences[token.first + offset] = confidence
        if agree and posterior >= thresholds.min_value_posterior:
            continue
        alternative = " ".join(spoken)
        alternatives = [alternative] if alternative and not agree else []
        doubts.append(
            Doubt(
                position=token.first,
                words=token.text,
                alternatives=alternatives,
                confidence=confidence,
            )
        )
    return Verdict("", said, confidences, doubts, foreign, support)


def _not_a_command(said: str) -> str:
    return f"I heard '{said}': not a command" if said else "not a command"


def _squeezed(word: Word, vocabulary: Vocabulary, limit: float) -> bool:
    """The word lasts no longer than `limit` times the shortest it could (its shortest
    pronunciation at `FRAMES_PER_PHONE` a phone)."""
    phones = min((len(p.split()) for p in vocabulary.sounds(word.text)), default=0)
    return phones > 0 and word.end - word.start + 1 <= limit * FRAMES_PER_PHONE * phones


def _unexplained(grammar: list[Word], heard: list[Word], vocabulary: Vocabulary) -> float:
    """The posterior mass of the open decode's foreign words, each stretch of it weighed by
    how unlike the grammar's words of the same stretch of audio it sounds (all of it where
    the grammar heard nothing)."""
    mass = 0.0
    for said, heard_there in _stretches(grammar, heard):
        foreign = sum(w.posterior for w in heard_there if not vocabulary.known(w.text))
        if foreign:
            run = " ".join(w.text for w in heard_there)
            alike = vocabulary.alike(" ".join(w.text for w in said), run) if said else 0.0
            mass += foreign * (1.0 - alike)
    return mass


def _stretches(grammar: list[Word], heard: list[Word]) -> list[tuple[list[Word], list[Word]]]:
    """The two decodes cut where neither has a word across the cut: (grammar's words,
    open decode's words) of each stretch, in time order. A word belongs with another of
    the other decode that it overlaps by at least half of the shorter one."""
    words = sorted(
        [(w, True) for w in grammar] + [(w, False) for w in heard], key=lambda item: item[0].start
    )
    stretches: list[tuple[list[Word], list[Word]]] = []
    for word, from_grammar in words:
        joined = stretches and any(
            _together(word, other) for other in [*stretches[-1][0], *stretches[-1][1]]
        )
        if not joined:
            stretches.append(([], []))
        stretches[-1][0 if from_grammar else 1].append(word)
    return stretches


def _together(a: Word, b: Word) -> bool:
    overlap = min(a.end, b.end) - max(a.start, b.start) + 1
    return overlap > 0 and 2 * overlap >= min(a.end - a.start, b.end - b.start) + 1


def _tokens(grammar: list[Word], vocabulary: Vocabulary) -> Iterable[_Token]:
    run: list[Word] = []
    first = 0
    for index, word in enumerate(grammar):
        if word.text in vocabulary.number_words:
            if not run:
                first = index
            run.append(word)
            continue
        if run:
            yield _Token(first, run, value=True)
            run = []
        if word.text not in vocabulary.skip_words:
            yield _Token(index, [word], value=False)
    if run:
        yield _Token(first, run, value=True)


def _overlapping(token: _Token, heard: list[Word]) -> list[Word]:
    """Open words at least half inside the token's stretch of audio."""
    found = []
    for word in heard:
        inside = min(word.end, token.end) - max(word.start, token.start) + 1
        if inside * 2 >= word.end - word.start + 1:
            found.append(word)
    return found


def _support(token: _Token, heard: list[Word], vocabulary: Vocabulary) -> float:
    """How surely the open decode heard a command word: the posterior of the nearby open
    word (or two) that sounds most like it, 0 when none sounds enough like it."""
    word = token.words[0]
    near = [w for w in heard if w.end >= word.start - 10 and w.start <= word.end + 10]
    candidates = [[w] for w in near] + [list(pair) for pair in itertools.pairwise(near)]
    best = 0.0
    for run in candidates:
        alike = vocabulary.alike(" ".join(w.text for w in run), word.text)
        if alike >= SUPPORTS:
            best = max(best, alike * min(w.posterior for w in run))
    return best


def _numeric(word: Word, vocabulary: Vocabulary) -> bool:
    return any(vocabulary.same(word.text, n) for n in vocabulary.number_words)


def _as_number(text: str, vocabulary: Vocabulary) -> str:
    """The number word `text` sounds like ("for" is "four")."""
    if text in vocabulary.number_words:
        return text
    return next((n for n in sorted(vocabulary.number_words) if vocabulary.same(text, n)), text)
