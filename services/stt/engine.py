"""The speech engine seam: an engine compiles grammars and hands out recognisers.

A recogniser belongs to one audio stream (one session). It is fed 16 kHz PCM and answers
with events: speech started, what it hears so far, and one final result per utterance.
It finds the end of an utterance in the audio itself, or ends it at `finish()` (the
session stopped) or at the maximum utterance length. Every call blocks: the service runs
each session's recogniser on a thread of its own.

Engines are imported lazily, so that a machine without a heavy engine still runs the
others; `load_engine` names the extra to install.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from shared.errors import VoicectlError
from shared.messages import Doubt, Grammar

ENGINES = ("pocketsphinx", "vosk")


class EngineError(VoicectlError):
    """An engine that cannot start or cannot use a grammar; the text says how to fix it."""


@dataclass(frozen=True)
class SpeechStarted:
    utterance: int
    at: float
    """Seconds from the start of the stream."""


@dataclass(frozen=True)
class Heard:
    """A partial transcript of the utterance in progress."""

    utterance: int
    text: str


@dataclass(frozen=True)
class Final:
    """The result of one utterance."""

    utterance: int
    text: str
    confidence: float
    rejection: str
    """Why the engine rejects it ('' when it does not): no words, low confidence..."""
    speech_start: float
    speech_end: float
    heard: str = ""
    """What an unconstrained decode heard: the person's words, command or not."""
    confidences: list[float] = field(default_factory=list)
    """Per word of `text`, 0..1: how surely the engine heard it (judge.py's Verdict)."""
    doubts: list[Doubt] = field(default_factory=list)


RecognitionEvent = SpeechStarted | Heard | Final


class Recogniser(Protocol):
    def accept(self, pcm: bytes) -> list[RecognitionEvent]:
        """Feed whole 16-bit samples; returns what happened in them."""

    def finish(self) -> list[RecognitionEvent]:
        """End of the stream: the utterance in progress, if any, ends now."""

    def close(self) -> None:
        """Give back what the recogniser holds (its decoder goes back to a pool)."""


class Engine(Protocol):
    name: str

    def use_grammar(self, grammar: Grammar) -> list[str]:
        """Compile `grammar` for recognisers made from now on; returns the words it
        cannot pronounce. Raises EngineError when the grammar cannot be used."""

    def recogniser(self, max_utterance: float, segment: bool = True) -> Recogniser:
        """A recogniser for one stream, with the grammar in use now. Utterances longer
        than `max_utterance` seconds are cut; with `segment` False the whole stream is one
        utterance (offline transcription). Raises EngineError before any grammar."""

    def close(self) -> None:
        """Give back what the engine holds beyond this process's memory (its workers)."""


@dataclass(frozen=True)
class EngineOptions:
    name: str = "pocketsphinx"
    vosk_model: Path | None = None
    min_confidence: float = 0.5
    """Utterances whose confidence is lower are rejected."""
    workers: int = 0
    """Decode in this many worker processes (workers.py); 0: in the calling process."""


def load_engine(options: EngineOptions) -> Engine:
    """The engine `options` names, imported now; EngineError with an install hint."""
    if options.workers > 0:
        from .workers import ProcessEngine

        return ProcessEngine(options, options.workers)
    match options.name:
        case "pocketsphinx":
            _require("pocketsphinx", "stt")
            from .sphinx import PocketsphinxEngine

            return PocketsphinxEngine(min_confidence=options.min_confidence)
        case "vosk":
            _require("vosk", "vosk")
            from .vosk_engine import VoskEngine

            if options.vosk_model is None:
                raise EngineError(
                    "--engine vosk needs --vosk-model DIR: "
                    + "an unpacked model from https://alphacephei.com/vosk/models"
                )
            return VoskEngine(options.vosk_model, min_confidence=options.min_confidence)
    raise EngineError(f"unknown engine {options.name!r}; engines: {', '.join(ENGINES)}")


def _require(module: str, extra: str) -> None:
    try:
        importlib.import_module(module)
    except ImportError as exc:
        raise EngineError(
            f"the {module} engine is not installed: pip install 'voicectl[{extra}]' ({exc})"
        ) from exc


def logistic(value: float, midpoint: float, width: float) -> float:
    """A score mapped to 0..1, 0.5 at `midpoint`."""
    exponent = -(value - midpoint) / width
    if exponent > 700:
        return 0.0
    return 1.0 / (1.0 + math.exp(exponent))


def rejection(text: str, confidence: float, minimum: float) -> str:
    """Why an engine rejects what it heard, or '' when it does not."""
    if not text:
        return "no command heard"
    if confidence < minimum:
        return f"sounds unlike any command (confidence {confidence:.2f}, below {minimum:.2f})"
    return ""
