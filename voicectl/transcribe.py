"""Offline transcription: recordings through an engine with a grammar made from orders files.

Integrators use it to check their YAML against real recordings before they run anything:
each file is one utterance, and the result says what the engine heard, whether it would be
rejected, and the orders and errors the converter makes of it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import msgspec

from services.stt.audio import AudioError, read_wav
from services.stt.engine import Engine, finals
from shared.messages import Doubt, Order, ParseProblem, ParseResult

MAX_FILE_SECONDS = 600.0


class Transcription(msgspec.Struct):
    """One file's line of `voicectl transcribe` output."""

    file: str
    transcript: str
    rejected: bool
    reason: str
    """Why it is rejected; empty when it is not."""
    confidence: float | None
    orders: list[Order]
    """What `voicectl parse` makes of the transcript (never dispatched if rejected)."""
    errors: list[ParseProblem]
    heard: str = ""
    """What an unconstrained decode heard: the person's words, command or not."""
    word_confidences: list[float] = msgspec.field(default_factory=list)
    """Per word of the transcript, 0..1."""
    doubts: list[Doubt] = msgspec.field(default_factory=list)
    """Values to ask about: a transcript with doubts is never sent by itself."""


class Unreadable(msgspec.Struct):
    """The line for a file that could not be read."""

    file: str
    error: str


def transcribe(
    engine: Engine, parse: Callable[[str], ParseResult], files: list[Path]
) -> Iterator[Transcription | Unreadable]:
    """Each file's transcription, in order, with what `parse` makes of the transcript."""
    for path in files:
        try:
            pcm = read_wav(path)
        except AudioError as exc:
            yield Unreadable(file=str(path), error=str(exc))
            continue
        heard = finals(engine, pcm, MAX_FILE_SECONDS, segment=False)
        text = " ".join(f.text for f in heard if f.text)
        engine_reason = next((f.rejection for f in heard if f.rejection), "")
        result = parse(text) if text else None
        reason = engine_reason
        if not reason and result is not None and (result.errors or not result.orders):
            reason = "not a command" + (f": {result.errors[0].reason}" if result.errors else "")
        if not text:
            reason = reason or "no command heard"
        yield Transcription(
            file=str(path),
            transcript=text,
            rejected=bool(reason),
            reason=reason,
            confidence=min((f.confidence for f in heard), default=None),
            orders=result.orders if result is not None else [],
            errors=result.errors if result is not None else [],
            heard=" ".join(f.heard for f in heard if f.heard),
            word_confidences=[c for f in heard for c in f.confidences],
            doubts=[] if reason or len(heard) != 1 else heard[0].doubts,
        )
