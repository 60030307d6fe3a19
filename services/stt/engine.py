"""The speech engine seam: an engine compiles grammars and hands out recognisers.

A recogniser belongs to one audio stream (one session). It is fed 16 kHz PCM and answers
with events: speech started, what it hears so far, and one final result per utterance.
It finds the end of an utterance in the audio itself, or ends it at `finish()` (the
session stopped) or at the maximum utterance length. Every call blocks: the service runs
each session's recogniser on a thread of its own.

`ENGINES` is the one registry of engines: each entry names its module (imported only
when that engine is loaded, so that a machine without a heavy engine still runs the
others), the library and extra it needs, and its own options, which become command-line
flags of every command that loads engines and are forwarded by `voicectl up`. A new engine
is a module with a `load(options)` function and one entry here.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from msgspec import Struct

from voicectl.shared.errors import VoicectlError
from voicectl.shared.hints import pip_install
from voicectl.shared.messages import Doubt, Grammar, PhraseCheck, Transcription

from .audio import frames


class EngineError(VoicectlError):
    """An engine that cannot start or cannot use a grammar; the text says how to fix it."""


class SpeechStarted(Struct, frozen=True, tag=True):
    utterance: int
    at: float
    """Seconds from the start of the stream."""


class Heard(Struct, frozen=True, tag=True):
    """A partial transcript of the utterance in progress."""

    utterance: int
    text: str


class Final(Struct, frozen=True, tag=True):
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
    confidences: list[float] = []
    """Per word of `text`, 0..1: how surely the engine heard it (judge.py's Verdict)."""
    doubts: list[Doubt] = []
    transcription: Transcription | None = None
    """What a second ear heard of the same utterance (Moonshine)."""
    third: Transcription | None = None
    """What the third ear heard, when it was asked (Whisper)."""
    noisy: bool = False
    """The room was noisy when the utterance ended."""
    alone: bool = False
    """Heard by the language's one ear (`transcription`), no grammar's ear beside it."""


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
    languages: frozenset[str]
    """What its recognisers can hear (ISO 639-1)."""

    def use_grammar(self, grammar: Grammar) -> list[str]:
        """Compile `grammar` for recognisers made from now on; returns the words it
        cannot pronounce. Raises EngineError when the grammar cannot be used."""

    def recogniser(
        self, max_utterance: float, segment: bool = True, language: str = "en"
    ) -> Recogniser:
        """A recogniser for one stream in `language`, with that language's grammar in use
        now. Utterances longer than `max_utterance` seconds are cut; with `segment` False
        the whole stream is one utterance (offline transcription). Raises EngineError
        before any grammar, or for a language it does not hear."""

    def check(self, pcm: bytes, phrase: str) -> PhraseCheck:
        """Whether `pcm` says `phrase`, by an ear bound to no grammar; `checked` False
        for an engine that has none."""

    def close(self) -> None:
        """Give back what the engine holds beyond this process's memory (its workers)."""


@dataclass(frozen=True)
class EngineFlag:
    """One option of one engine, given as `--<name>` on the command line."""

    name: str
    metavar: str
    help: str
    type: Callable[[str], Any] = str

    @property
    def dest(self) -> str:
        """Its key in `EngineOptions.settings` (and argparse's attribute)."""
        return self.name.replace("-", "_")


@dataclass(frozen=True)
class EngineKind:
    """An engine voicectl can load."""

    name: str
    module: str
    """Where its `load(options) -> Engine` is; imported when the engine is loaded."""
    requires: str
    """The library it runs on, and the pip extra that installs it."""
    extra: str
    flags: tuple[EngineFlag, ...] = ()
    entry: str = "load"
    """The function of `module` that loads it."""


ENGINES: dict[str, EngineKind] = {
    kind.name: kind
    for kind in (
        EngineKind(
            "whisper",
            "voicectl.services.stt.ears",
            requires="ctranslate2",
            extra="stt",
            entry="load_three",
            flags=(
                EngineFlag(
                    "whisper-when",
                    "WHEN",
                    "when the third ear hears an utterance: 'doubt' (when the other two leave "
                    "one) or 'always'",
                ),
            ),
        ),
        EngineKind(
            "moonshine",
            "voicectl.services.stt.ears",
            requires="onnxruntime",
            extra="stt",
        ),
        EngineKind(
            "pocketsphinx", "voicectl.services.stt.sphinx", requires="pocketsphinx", extra="stt"
        ),
        EngineKind(
            "vosk",
            "voicectl.services.stt.vosk_engine",
            requires="vosk",
            extra="vosk",
            flags=(
                EngineFlag(
                    "vosk-model",
                    "DIR",
                    "an unpacked Vosk model (https://alphacephei.com/vosk/models)",
                    Path,
                ),
            ),
        ),
    )
}


@dataclass(frozen=True)
class EngineOptions:
    name: str = "whisper"
    min_confidence: float = 0.5
    """Utterances whose confidence is lower are rejected."""
    workers: int = 0
    """Decode in this many worker processes (workers.py); 0: in the calling process."""
    settings: Mapping[str, Any] = field(default_factory=dict)
    """The engine's own options by `EngineFlag.dest`; None or absent when not given."""

    def argv(self) -> list[str]:
        """The same options as flags, for a `voicectl stt` this process starts."""
        flags = ["--engine", self.name, "--min-confidence", str(self.min_confidence)]
        flags += ["--workers", str(self.workers)]
        for flag in ENGINES[self.name].flags if self.name in ENGINES else ():
            value = self.settings.get(flag.dest)
            if value is not None:
                flags += [f"--{flag.name}", str(value)]
        return flags


def load_here(options: EngineOptions) -> Engine:
    """The engine `options` names, imported now into this process (a worker process calls
    this; everything else `load.load_engine`); EngineError with an install hint."""
    kind = ENGINES.get(options.name)
    if kind is None:
        raise EngineError(f"unknown engine {options.name!r}; engines: {', '.join(ENGINES)}")
    # Found, not imported: the engine's module imports its library as it must be imported
    # (onnxruntime with its telemetry off, moonshine.py).
    if importlib.util.find_spec(kind.requires) is None:
        raise EngineError(
            f"the {kind.name} engine is not installed: {pip_install(kind.extra)} "
            f"(no module named {kind.requires!r})"
        )
    try:
        load: Callable[[EngineOptions], Engine] = getattr(
            importlib.import_module(kind.module), kind.entry
        )
    except ImportError as exc:
        raise EngineError(
            f"the {kind.name} engine is not installed: {pip_install(kind.extra)} ({exc})"
        ) from exc
    return load(options)


def finals(
    engine: Engine,
    pcm: bytes,
    max_utterance: float = 15.0,
    segment: bool = True,
    language: str = "en",
) -> list[Final]:
    """What one stream of `pcm` comes to, sent in 20 ms frames as a microphone sends it:
    its final results, in order (`voicectl transcribe`, the tests, the speech benchmark)."""
    recogniser = engine.recogniser(max_utterance, segment, language)
    try:
        events = [e for frame in frames(pcm) for e in recogniser.accept(frame)]
        events += recogniser.finish()
    finally:
        recogniser.close()
    return [e for e in events if isinstance(e, Final)]


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
