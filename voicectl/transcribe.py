"""Offline transcription: recordings through an engine with a grammar made from orders files.

Integrators use it to check their YAML against real recordings before they run anything:
each file is one utterance, and the result says what the engine heard, whether it would be
rejected, what each ear heard, and the orders and errors the converter makes of it.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import msgspec

from voicectl.services.converter.decide import decide, problem, readings
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import read_wav
from voicectl.services.stt.engine import Engine, finals
from voicectl.services.stt.service import transcript_of
from voicectl.shared.errors import AudioError
from voicectl.shared.messages import Doubt, Hearing, Order, ParseProblem

MAX_FILE_SECONDS = 600.0


class FileTranscript(msgspec.Struct):
    """One file's line of `voicectl transcribe` output."""

    file: str
    transcript: str
    """The words the decision rests on (one ear's, or both's when they agree)."""
    rejected: bool
    reason: str
    """Why it is rejected; empty when it is not."""
    confidence: float | None
    """The grammar's confidence, 0..1."""
    orders: list[Order]
    """The orders the speech becomes (never dispatched if rejected)."""
    errors: list[ParseProblem]
    heard: str = ""
    """What pocketsphinx's unconstrained decode heard."""
    word_confidences: list[float] = msgspec.field(default_factory=list)
    """Per word of the grammar's result, 0..1."""
    doubts: list[Doubt] = msgspec.field(default_factory=list)
    """Values to ask about: a transcript with doubts is never sent by itself."""
    hearings: list[Hearing] = msgspec.field(default_factory=list)
    """What each ear heard and made of it."""
    decision: str = ""
    """Why the speech became these orders, or nothing."""


class Unreadable(msgspec.Struct):
    """The line for a file that could not be read."""

    file: str
    error: str


def transcribe(
    engine: Engine, parser: Parser, files: list[Path]
) -> Iterator[FileTranscript | Unreadable]:
    """Each file's transcription, in order, decided as the converter decides (decide.py)."""
    for path in files:
        try:
            pcm = read_wav(path)
        except AudioError as exc:
            yield Unreadable(file=str(path), error=str(exc))
            continue
        heard = finals(engine, pcm, MAX_FILE_SECONDS, segment=False)
        decisions = [decide(*readings(transcript_of(final), parser)) for final in heard]
        rejected = [d for d in decisions if d.rejected]
        reason = rejected[0].reason if rejected else ""
        if not heard:
            reason = "no command heard"
        yield FileTranscript(
            file=str(path),
            transcript=" ".join(d.text for d in decisions if d.text),
            rejected=bool(reason),
            reason=reason,
            confidence=min((f.confidence for f in heard), default=None),
            orders=[] if reason else [o for d in decisions for o in d.orders],
            errors=[problem(d) for d in rejected],
            heard=" ".join(f.heard for f in heard if f.heard),
            word_confidences=[c for f in heard for c in f.confidences],
            doubts=[] if reason or len(decisions) != 1 else decisions[0].doubts,
            hearings=[h for d in decisions for h in d.hearings],
            decision="; ".join(d.reason for d in decisions if d.reason),
        )
