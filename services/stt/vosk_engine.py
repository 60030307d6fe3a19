"""Vosk (Kaldi) as an engine: a model directory, the orders' phrases as its grammar.

Vosk takes a grammar as a list of phrases and builds a small language model from them, so
phrases can recombine ("left then forward" pieces): the service's parse check catches what
does not make whole orders. Vosk finds the end of an utterance itself. A recogniser is
created once per stream and reset between utterances: its first chunk costs about 0.7 s.

No English model comes from a package registry; users download one (see `HOW_TO_GET`).
"""

from __future__ import annotations

import json
import logging
import math
import threading
from pathlib import Path
from typing import Any

import vosk

from voicectl.shared.messages import Doubt, Grammar, PhraseCheck

from .audio import seconds, whole
from .engine import (
    EngineError,
    EngineOptions,
    Final,
    Heard,
    RecognitionEvent,
    SpeechStarted,
    rejection,
)

_LOGGER = logging.getLogger(__name__)

HOW_TO_GET = (
    "download and unpack a model from https://alphacephei.com/vosk/models "
    "(for English: vosk-model-small-en-us-0.15) and pass its directory with --vosk-model"
)
UNKNOWN_WORDS = ("[unk]", "<UNK>")
"""How models name speech outside the grammar (English models, and some others)."""
CHUNK_BYTES = 3200
"""100 ms per call: partial results grow at that pace."""
MIN_VALUE_CONFIDENCE = 0.9
"""A number word Kaldi heard less surely than this is a doubt (not tuned: no English model
is installable here to tune it on)."""
MAX_ALTERNATIVES = 5
"""Kaldi's best paths per result. A word's confidence is the share of their probability
that has the same word at the same time, and a doubtful number offers the numbers the
others heard there: Vosk gives either per-word confidences (`SetWords`) or alternatives
(`SetMaxAlternatives`), not both, and only the alternatives can say "ten or two"."""


def load(options: EngineOptions) -> VoskEngine:
    """The engine registry's entry point (engine.py's ENGINES)."""
    model: Path | None = options.settings.get("vosk_model")
    if model is None:
        raise EngineError(f"--engine vosk needs --vosk-model DIR: {HOW_TO_GET}")
    return VoskEngine(model, min_confidence=options.min_confidence)


class VoskEngine:
    name = "vosk"
    languages = frozenset({"en"})
    """The model's language is not known to voicectl: its grammars are the English orders'."""

    def __init__(self, model_dir: Path, min_confidence: float = 0.5) -> None:
        self.min_confidence = min_confidence
        if not model_dir.is_dir():
            raise EngineError(f"Vosk model directory {model_dir} does not exist: {HOW_TO_GET}")
        vosk.SetLogLevel(-1)
        try:
            self._model = vosk.Model(str(model_dir))
        except Exception as exc:  # vosk raises a bare Exception for a broken model
            raise EngineError(
                f"{model_dir} is not a usable Vosk model ({exc}): {HOW_TO_GET}"
            ) from exc
        self._unknown = next(
            (w for w in UNKNOWN_WORDS if self._model.vosk_model_find_word(w) != -1), None
        )
        self._grammar: str | None = None
        self._version = ""
        self._numbers: frozenset[str] = frozenset()
        self._pool: list[tuple[str, Any]] = []
        """Idle recognisers, each with the version of the grammar it was built with."""
        self._lock = threading.Lock()

    def check(self, pcm: bytes, phrase: str) -> PhraseCheck:
        return PhraseCheck(checked=False)  # bound to the grammar, like pocketsphinx

    def close(self) -> None:
        """Nothing beyond this process's memory."""

    def use_grammar(self, grammar: Grammar) -> list[str]:
        words = set(grammar.words)
        missing = sorted(w for w in words if self._model.vosk_model_find_word(w) == -1)
        unheard = set(missing)
        phrases = [p for p in grammar.phrases if not unheard & set(p.split())]
        # Commands too many to list give their words; skip words and the separator stand
        # alone: Vosk's grammar is a language model over these, not an exact grammar.
        singles = sorted(words - unheard - {w for p in phrases for w in p.split()})
        singles += [w for w in grammar.skip_words if w not in unheard]
        singles += [w for p in grammar.separator_phrases for w in p.split() if w not in unheard]
        listed = list(dict.fromkeys([*phrases, *singles]))
        if not listed:
            raise EngineError(f"grammar {grammar.version}: no phrase this model can hear")
        if self._unknown:
            listed.append(self._unknown)
        with self._lock:  # a recogniser is lent with the grammar and version of one moment
            self._grammar = json.dumps(listed, ensure_ascii=False)
            self._version = grammar.version
            self._numbers = frozenset(grammar.number_words)
        return missing

    def recogniser(
        self, max_utterance: float, segment: bool = True, language: str = "en"
    ) -> VoskRecogniser:
        if language not in self.languages:
            raise EngineError(f"the vosk engine hears its model's language, not {language!r}")
        if self._grammar is None:
            raise EngineError("no grammar yet")
        return VoskRecogniser(self, max_utterance, segment)

    def borrow(self) -> tuple[str, Any]:
        """A Kaldi recogniser with the grammar in use now, and that grammar's version."""
        with self._lock:
            grammar, version = self._grammar, self._version
            while self._pool:
                built_for, recogniser = self._pool.pop()
                if built_for == version:
                    return version, recogniser
        assert grammar is not None
        recogniser = vosk.KaldiRecognizer(self._model, 16000, grammar)
        recogniser.SetWords(True)
        recogniser.SetMaxAlternatives(MAX_ALTERNATIVES)
        return version, recogniser

    def give_back(self, version: str, recogniser: Any) -> None:
        """Keep `recogniser` for later only if it still has the grammar in use."""
        recogniser.Reset()
        with self._lock:
            if version == self._version and len(self._pool) < 2:
                self._pool.append((version, recogniser))

    def doubts(self, words: list[dict[str, Any]]) -> list[Doubt]:
        """Number words Kaldi was not sure of, with the numbers its other paths heard there:
        asked, never guessed."""
        return [
            Doubt(
                position=i,
                words=str(w["word"]),
                alternatives=[a for a in w.get("others", []) if a in self._numbers],
                confidence=round(float(w["conf"]), 3),
            )
            for i, w in enumerate(words)
            if w.get("word") in self._numbers and float(w.get("conf", 0.0)) < MIN_VALUE_CONFIDENCE
        ]

    def judge(self, words: list[dict[str, Any]]) -> tuple[float, str]:
        """Confidence (mean word confidence) and why the utterance is rejected, if it is."""
        if not words:
            return 0.0, rejection("", 0.0, self.min_confidence)
        confidence = sum(float(w.get("conf", 0.0)) for w in words) / len(words)
        if any(w.get("word") in UNKNOWN_WORDS for w in words):
            return confidence, "words outside the orders' grammar"
        text = " ".join(str(w.get("word", "")) for w in words)
        return confidence, rejection(text, confidence, self.min_confidence)


class VoskRecogniser:
    """One stream: Vosk's own endpointing, a result per utterance."""

    def __init__(self, engine: VoskEngine, max_utterance: float, segment: bool) -> None:
        self._engine = engine
        version, recogniser = engine.borrow()
        self._version = version
        self._recogniser: Any = recogniser
        self._max_utterance = max_utterance
        self._segment = segment
        self._pending = bytearray()
        self._clock = 0.0
        self._offset = 0.0
        """Where the Kaldi recogniser's own clock started (it restarts on a forced cut)."""
        self._started: float | None = None
        self._partial = ""
        self._count = 0
        self._words: list[dict[str, Any]] = []
        """Whole-stream mode: the words of every result so far."""

    def accept(self, pcm: bytes) -> list[RecognitionEvent]:
        events: list[RecognitionEvent] = []
        self._pending += pcm
        for chunk in whole(self._pending, CHUNK_BYTES):
            self._chunk(chunk, events)
        return events

    def finish(self) -> list[RecognitionEvent]:
        events: list[RecognitionEvent] = []
        if self._pending:
            self._chunk(bytes(self._pending), events)
            self._pending.clear()
        self._result(json.loads(self._recogniser.FinalResult()), events, force=True)
        return events

    def close(self) -> None:
        if self._recogniser is not None:
            self._engine.give_back(self._version, self._recogniser)
            self._recogniser = None

    def _chunk(self, chunk: bytes, events: list[RecognitionEvent]) -> None:
        self._clock += seconds(len(chunk))
        if self._recogniser.AcceptWaveform(chunk):
            self._result(json.loads(self._recogniser.Result()), events)
            return
        text = json.loads(self._recogniser.PartialResult()).get("partial", "")
        if text and self._started is None:
            self._started = max(self._clock - seconds(len(chunk)), 0.0)
            events.append(SpeechStarted(self._count, self._started))
        if text and text != self._partial:
            self._partial = text
            events.append(Heard(self._count, text))
        if self._started is not None and self._clock - self._started > self._max_utterance:
            _LOGGER.info("utterance %d cut at its maximum length", self._count)
            self._result(json.loads(self._recogniser.FinalResult()), events, force=True)
            self._recogniser.Reset()
            self._offset = self._clock

    def _result(
        self, result: dict[str, Any], events: list[RecognitionEvent], force: bool = False
    ) -> None:
        words = best_words(result)
        if not self._segment:
            self._words.extend(words)
            if not force:
                return
            words = self._words
        elif not words and self._started is None:
            return  # silence ended: there was no utterance
        text = " ".join(str(w.get("word", "")) for w in words)
        confidence, rejection = self._engine.judge(words)
        start = self._offset + float(words[0]["start"]) if words else self._started or 0.0
        end = self._offset + float(words[-1]["end"]) if words else self._clock
        events.append(
            Final(
                self._count,
                text,
                round(confidence, 3),
                rejection,
                start,
                end,
                confidences=[round(float(w.get("conf", 0.0)), 3) for w in words],
                doubts=[] if rejection else self._engine.doubts(words),
            )
        )
        self._count += 1
        self._started = None
        self._partial = ""


def best_words(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The words of Kaldi's best path (`word`, `start`, `end`), each with its `conf`: the
    share of the alternatives' probability that heard the same word at the same time, and
    `others`: what the other alternatives heard there instead. A result without
    alternatives keeps the confidences it has."""
    alternatives = [a for a in result.get("alternatives", []) if isinstance(a, dict)]
    if not alternatives:
        return [w for w in result.get("result", []) if isinstance(w, dict)]
    scores = [float(a.get("confidence", 0.0)) for a in alternatives]
    top = max(scores)
    weights = [math.exp(score - top) for score in scores]
    total = sum(weights)
    paths = [[w for w in a.get("result", []) if isinstance(w, dict)] for a in alternatives]
    best = []
    for word in paths[0]:
        share, others = 0.0, []
        for weight, path in zip(weights, paths, strict=True):
            there = [w for w in path if _overlap(word, w)]
            if any(w.get("word") == word.get("word") for w in there):
                share += weight
            others += [str(w["word"]) for w in there if w.get("word") != word.get("word")]
        best.append({**word, "conf": share / total, "others": list(dict.fromkeys(others))})
    return best


def _overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two timed words share at least half of the shorter one."""
    start, end = max(float(a["start"]), float(b["start"])), min(float(a["end"]), float(b["end"]))
    shorter = min(float(a["end"]) - float(a["start"]), float(b["end"]) - float(b["start"]))
    return end > start and 2 * (end - start) >= shorter
