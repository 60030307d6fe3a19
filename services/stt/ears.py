"""Three ears: pocketsphinx bound to the orders' grammar, Moonshine's free transcript of
every utterance, and Whisper's, asked when the first two leave a doubt.

pocketsphinx does what it is good at, as the pocketsphinx engine alone does: it finds the
utterances in the stream, gives partial transcripts while the person speaks, and the
grammar's result with its own verdict. Moonshine transcribes every utterance beside it,
started on a thread of its own when the speech pauses (`LISTENER_FRAMES` in sphinx.py), so
that its result is ready when the end is confirmed; if the speech goes on, that run is
dropped. Whisper, stronger and slower, hears an utterance only when the first two leave a
doubt (`why_ask`), so that clean speech the two agree on pays nothing for it. The
results travel together in one `Final`; the converter, which parses, decides from all of
them (services/converter/decide.py).

Two engines of the registry are made here: `moonshine` (the first two ears) and `whisper`
(all three). Whisper also hears the languages the other two do not: there it is the one
ear (`_Alone`), told the language, and pocketsphinx only finds where utterances begin and
end; a second decode of Whisper's, prompted with the orders' words, is its own evidence
for the converter (docs/speech.md, "One ear is not two").
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import re
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Generic, TypeVar

from voicectl.shared.config import cache_dir
from voicectl.shared.errors import Cancelled
from voicectl.shared.languages import WHISPER_LANGUAGES
from voicectl.shared.messages import Grammar, PhraseCheck, Transcription

from .engine import EngineError, EngineOptions, Recogniser
from .moonshine import Moonshine, Transcript, prepare, weights_dir
from .sphinx import GrammarHeard, PocketsphinxEngine
from .whisper import Heard as WhisperHeard
from .whisper import Whisper
from .whisper import weights_dir as whisper_weights

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")

RUNS_AT_ONCE = 2
"""Transcriptions a process runs at once, one onnxruntime thread each (two cores)."""
PHRASE_SUPPORT = -1.5
"""A wake phrase is heard when Moonshine finds it at most this many nats a token less
likely than its own words. On the dev split's spotted wake phrases (bench/wake.py), true
ones scored -0.02 to -2.2, mostly above -1.3; the spotter's false wakes in Asterisk's
prompts and the chatter, -1.9 to -5.3 ("Hello, robot." -3.4)."""
AGREED = -0.5
"""Moonshine finding the grammar's words at least this likely beside its own (nats a
token) is the two ears agreeing; below it, the third ear is asked."""
PROMPT_WORDS = 60
"""At most this many of the orders' words (numbers aside) prompt the second decode of a
lone ear. Prompted, Whisper base wrote "gira la izquierda" for Kokoro's Spanish voice that
it heard unprompted as "kira la izquierda"; it also wrote a German "warte zehn Sekunden"
from the prompt that nobody said: a prompted decode is never sent without a yes."""
HYPOTHESES = 5
"""Both decodes of the lone ear are beam searches that keep this many hypotheses, and the
second, prompted, runs after any words, not only after a word of the orders. On the whole
dev split of harness/speech_languages.py (bench/languages.py, 2026-11-28), commands that
became the said orders, read back: Spanish 52 of 84 with only the second decode a beam,
56 with both (whole files decoded once each, main's decodes made at most 28); German 9,
then 12 of 56. No other orders, no non-command's (docs/benchmarks.md, "Other languages")."""
WHEN = ("doubt", "always")
"""When the third ear hears an utterance: when the first two leave a doubt (`why_ask`), or
always (bench/stt.py records every ear's reading, to choose the rule on the dev split)."""


@dataclass
class Runs:
    """What the second ears of an engine have done: each utterance is transcribed once,
    at its pause or at its end, plus the runs started at pauses the speech went on from."""

    at_pause: int = 0
    dropped: int = 0
    """Started at a pause, then dropped: the speech went on."""
    at_end: int = 0
    """Started only when the utterance ended (it ended without a pause: cut, or stopped)."""
    third: int = 0
    """Utterances the third ear heard."""


def load(options: EngineOptions) -> Ears:
    """The registry's `moonshine` engine: the grammar's ear and Moonshine's."""
    source = weights_dir()
    model = Moonshine.prepared(source, prepare(source, cache_dir()))
    return Ears("moonshine", PocketsphinxEngine(min_confidence=options.min_confidence), model)


def load_three(options: EngineOptions) -> Ears:
    """The registry's `whisper` engine: the grammar's ear, Moonshine's and Whisper's."""
    when = options.settings.get("whisper_when") or WHEN[0]
    if when not in WHEN:
        raise EngineError(f"--whisper-when {when!r}: one of {', '.join(WHEN)}")
    third = Whisper(whisper_weights(cache_dir()))
    source = weights_dir()
    model = Moonshine.prepared(source, prepare(source, cache_dir()))
    grammar = PocketsphinxEngine(min_confidence=options.min_confidence)
    return Ears("whisper", grammar, model, third, always=when == "always")


class Ears:
    """pocketsphinx's engine with Moonshine, and perhaps Whisper, beside every recogniser."""

    def __init__(
        self,
        name: str,
        grammar: PocketsphinxEngine,
        model: Moonshine,
        third: Whisper | None = None,
        always: bool = False,
    ) -> None:
        self.name = name
        self.languages = frozenset({"en"}) | (WHISPER_LANGUAGES if third is not None else set())
        """English with all ears; with Whisper, every language it knows, heard by it alone."""
        self._grammar = grammar
        self._model = model
        self._third = third
        self._always = always
        self._pool = ThreadPoolExecutor(RUNS_AT_ONCE, thread_name_prefix="moonshine")
        self.runs = Runs()

    def use_grammar(self, grammar: Grammar) -> list[str]:
        return self._grammar.use_grammar(grammar)

    def recogniser(
        self, max_utterance: float, segment: bool = True, language: str = "en"
    ) -> Recogniser:
        if language not in self.languages:
            raise EngineError(
                f"the {self.name} engine does not hear {language!r}"
                + (" (--engine whisper hears it)" if language in WHISPER_LANGUAGES else "")
            )
        if language in self._grammar.languages:
            ear: _Ear | _Alone = _Ear(self._model, self._pool, self.runs, self._third, self._always)
        else:
            assert self._third is not None
            ear = _Alone(self._third, self._pool, self.runs, language)
        return self._grammar.recogniser(max_utterance, segment, ear, language)

    def check(self, pcm: bytes, phrase: str) -> PhraseCheck:
        """Moonshine's reading of a wake phrase's audio: heard when the phrase is about as
        likely as its own words (`PHRASE_SUPPORT`), or when its words are the phrase's."""
        heard = self._model.transcribe(pcm)
        if heard.audio is None or not heard.text.strip():
            # No words at all: noise, or a breath. Measured on the test split, where
            # 9 of 10 false wakes the support alone let through were empty transcripts.
            return PhraseCheck(checked=True, text=heard.text)
        own = math.log(heard.confidence) if heard.text else self._model.likelihood(heard.audio, "")
        support = self._model.likelihood(heard.audio, written(phrase)) - own
        said = " ".join(re.findall(r"[a-z']+", heard.text.lower()))
        return PhraseCheck(
            checked=True,
            heard=support >= PHRASE_SUPPORT or phrase in said,
            text=heard.text,
            support=round(support, 3),
        )

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


def why_ask(grammar: GrammarHeard, second: Transcription) -> str:
    """Why the third ear should hear an utterance, or '' when the first two settle it.

    Asked in a noisy room, when Moonshine heard nothing of what the grammar heard, when the
    grammar doubted a value, or when Moonshine finds the grammar's words unlikely beside
    its own (`AGREED`). Not asked when both heard nothing, nor in a quiet room when
    Moonshine's words hold no word of any command (a conversation nearby): on the dev
    split that kept it from 154 of 244 clean utterances, at the cost of 3 commands of 405
    it would have heard (docs/benchmarks.md). The grammar's judge rejecting its own words
    is no reason by itself: Moonshine's support already says whether they were said."""
    if not grammar.text and not second.text:
        return ""
    if grammar.noisy:
        return "a noisy room"
    if not second.text:
        return "Moonshine heard nothing"
    words = set(re.findall(r"[a-z']+", second.text.lower()))
    if not words & grammar.vocabulary and not re.search(r"\d", second.text):
        return ""
    if grammar.doubted:
        return "the grammar doubted a value"
    if second.support is None or second.support < AGREED:
        return "the two ears heard different words"
    return ""


class _AtPause(Generic[T]):
    """The one transcription of a stream started when its speech pauses: a newer pause, or
    speech going on, drops the one in flight (its cancel is set)."""

    def __init__(self, pool: ThreadPoolExecutor, runs: Runs) -> None:
        self._pool = pool
        self._runs = runs
        self._run: Future[T] | None = None
        self._cancel = threading.Event()

    def start(self, transcribe: Callable[[threading.Event], T]) -> None:
        self.drop()
        self._cancel = threading.Event()
        self._run = self._pool.submit(transcribe, self._cancel)
        self._runs.at_pause += 1

    def done(self) -> T | None:
        """Its result, once it finished well; None while it runs, or when it failed."""
        run = self._run
        if run is None or not run.done() or run.cancelled() or run.exception() is not None:
            return None
        return run.result()

    def take(self) -> Future[T] | None:
        """The run in flight, no longer this stream's to drop."""
        run, self._run = self._run, None
        return run

    def drop(self) -> None:
        if self._run is not None:
            self._cancel.set()
            self._run = None
            self._runs.dropped += 1


class _Ear:
    """One stream's free ears (sphinx.py's `Listener`): at most one Moonshine run in
    flight, and Whisper at the end when asked."""

    def __init__(
        self,
        model: Moonshine,
        pool: ThreadPoolExecutor,
        runs: Runs,
        third: Whisper | None,
        always: bool,
    ) -> None:
        self._model = model
        self._runs = runs
        self._third = third
        self._always = always
        self._paused: _AtPause[Transcript] = _AtPause(pool, runs)

    def pause(self, audio: bytes) -> None:
        self._paused.start(functools.partial(self._model.transcribe, audio))

    def paused_text(self) -> str:
        heard = self._paused.done()
        return "" if heard is None else heard.text

    def drop(self) -> None:
        self._paused.drop()

    def result(
        self, audio: bytes, grammar: GrammarHeard
    ) -> tuple[Transcription, Transcription | None]:
        second = self._second(audio, grammar.text)
        if self._third is None:
            return second, None
        why = why_ask(grammar, second)
        if not why and not self._always:
            return second, None
        self._runs.third += 1
        return second, self._heard_by_third(audio, grammar.text, why)

    def _second(self, audio: bytes, grammar: str) -> Transcription:
        heard = None
        run = self._paused.take()
        if run is not None:
            with contextlib.suppress(Cancelled):  # never set for a run still wanted
                heard = run.result()
        if heard is None:
            self._runs.at_end += 1
            heard = self._model.transcribe(audio)
        support = None
        if grammar and heard.audio is not None:
            # Its own words' mean log-probability is what `confidence` is the exponential of.
            own = (
                math.log(heard.confidence)
                if heard.text
                else self._model.likelihood(heard.audio, "")
            )
            support = self._model.likelihood(heard.audio, written(grammar)) - own
        _LOGGER.debug(
            "moonshine heard %r in %.3f s; the grammar's words %s",
            heard.text,
            heard.seconds,
            "none" if support is None else f"{support:+.2f} nats a token",
        )
        return Transcription(
            engine="moonshine",
            text=heard.text,
            confidence=round(heard.confidence, 3),
            support=None if support is None else round(support, 3),
        )

    def _heard_by_third(self, audio: bytes, grammar: str, why: str) -> Transcription:
        assert self._third is not None
        heard = self._third.transcribe(audio)
        support = None
        if grammar and heard.text:
            own = math.log(max(heard.confidence, 1e-12))
            support = self._third.likelihood(heard, written(grammar)) - own
        _LOGGER.debug("whisper heard %r in %.3f s (asked: %s)", heard.text, heard.seconds, why)
        return Transcription(
            engine="whisper",
            text=heard.text,
            confidence=round(heard.confidence, 3),
            support=None if support is None else round(support, 3),
            asked=f"always ({why})" if self._always and why else why or "always",
        )


class _Alone:
    """A stream's one ear in a language only Whisper hears (sphinx.py's `Listener`):
    Whisper, told the language, started when the speech pauses as Moonshine is; at the
    end, when it heard any words, a second decode prompted with the orders' words, both
    beam searches that keep their other hypotheses (`HYPOTHESES`): Whisper mishears the
    orders' words so often that "no word of the orders" is no sign of no command. Both,
    with the model's own no-speech probability and confidence, are the evidence the
    converter weighs (decide.py's `Rule.alone`). The run at the pause only tells the
    endpointer whether a number may follow (`paused_text`)."""

    def __init__(self, model: Whisper, pool: ThreadPoolExecutor, runs: Runs, language: str) -> None:
        self._model = model
        self._runs = runs
        self._language = language
        self._paused: _AtPause[WhisperHeard] = _AtPause(pool, runs)

    def pause(self, audio: bytes) -> None:
        transcribe = functools.partial(self._model.transcribe, audio, self._language, "")
        self._paused.start(transcribe)

    def paused_text(self) -> str:
        heard = self._paused.done()
        return "" if heard is None else heard.text

    def drop(self) -> None:
        self._paused.drop()

    def result(
        self, audio: bytes, grammar: GrammarHeard
    ) -> tuple[Transcription, Transcription | None]:
        # The run started at the pause is not taken: its audio ends where the voice
        # activity detector stopped flagging speech, 80 to 120 ms before the voice did,
        # which cut the last syllable ("cocina" heard as "coc"); with no other ear to make
        # up for it, the one ear hears the whole utterance again.
        self.drop()
        self._runs.at_end += 1
        heard = self._model.transcribe(audio, self._language, hypotheses=HYPOTHESES)
        self._runs.third += 1
        second, alternatives = None, list(heard.alternatives)
        if heard.text:
            prompt = ", ".join(sorted(grammar.vocabulary - grammar.numbers)[:PROMPT_WORDS])
            again = self._model.again(heard, self._language, prompt, hypotheses=HYPOTHESES)
            second, alternatives = again.text, [*alternatives, *again.alternatives]
        _LOGGER.debug(
            "whisper alone (%s) heard %r in %.3f s, then %r",
            self._language,
            heard.text,
            heard.seconds,
            second,
        )
        return (
            Transcription(
                engine="whisper",
                text=heard.text,
                confidence=round(heard.confidence, 3),
                asked=f"the one ear that hears {self._language}",
                no_speech=round(heard.no_speech, 3),
                second=second,
                alternatives=alternatives,
            ),
            None,
        )


def written(words: str) -> str:
    """The grammar's words as the model writes a sentence: "Turn left." for "turn left"."""
    return words[:1].upper() + words[1:] + "."
