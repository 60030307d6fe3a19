"""Offline transcription: recordings through an engine with a grammar made from orders files.

Integrators use it to check their YAML against real recordings before they run anything.
A file is heard as a microphone's stream is: read a second at a time (so that a file of
any length takes bounded memory), cut into utterances where the speech pauses, each
utterance decided as the converter decides. The result says what each ear heard, whether
it became orders, and why.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import msgspec

from voicectl.services.converter.decide import Decision, decide, problem, readings
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import read_blocks
from voicectl.services.stt.engine import Engine, Final
from voicectl.services.stt.service import transcript_of
from voicectl.shared.errors import AudioError
from voicectl.shared.messages import Doubt, Hearing, Order, ParseProblem

MAX_UTTERANCE = 15.0
"""Seconds an utterance may last before it is cut, as `voicectl stt`'s default."""
LEAD_SILENCE = 0.5
"""Silence heard before each file, as a microphone opened before the person speaks: the
endpointer learns the room from it, and speech at the file's very start is heard whole."""


class Utterance(msgspec.Struct):
    """One utterance of a file, and what it became."""

    start: float
    """Seconds from the start of the file to where the speech began..."""
    end: float
    """...and ended."""
    transcript: str
    """The words the decision rests on."""
    rejected: bool
    """True when it became no orders; `reason` says why."""
    reason: str
    orders: list[Order]
    doubts: list[Doubt]
    """Values to ask about: orders with doubts are never sent by themselves."""
    hearings: list[Hearing]
    """What each ear heard, and what it made of it."""
    decision: str
    """Why these orders, or none, in one line."""


class Diagnostics(msgspec.Struct):
    """What the grammar's ear measured, for an engineer tuning it; no decision reads these
    but its own judge."""

    grammar_confidence: float | None
    """The lowest acoustic confidence of the grammar's results, 0..1."""
    grammar_word_confidences: list[float]
    """Per word of the grammar's results, 0..1."""
    open_decode: str
    """pocketsphinx's unconstrained decode with its general English model, the grammar
    judge's second opinion: often not the person's words (it cannot hear synthetic voices
    well), and never made into orders."""


class FileTranscript(msgspec.Struct):
    """One file's line of `voicectl transcribe` output."""

    file: str
    transcript: str
    """The words of every utterance that became orders, in order; else of every utterance."""
    rejected: bool
    """True when no utterance of the file became orders."""
    reason: str
    """Why, when rejected; empty otherwise."""
    orders: list[Order]
    """The orders of every utterance that became orders, in order (never dispatched)."""
    errors: list[ParseProblem]
    """One per utterance that became no orders."""
    doubts: list[Doubt]
    """The doubts of a file of one utterance (positions count its transcript's words)."""
    hearings: list[Hearing]
    """What each ear heard of each utterance."""
    decision: str
    """Why each utterance became these orders or none, joined."""
    utterances: list[Utterance]
    """Each utterance heard, in order."""
    diagnostics: Diagnostics


class Unreadable(msgspec.Struct):
    """The line for a file that could not be read."""

    file: str
    error: str


def transcribe(
    engine: Engine, parser: Parser, files: list[Path]
) -> Iterator[FileTranscript | Unreadable]:
    """Each file's transcription, in order, decided as the converter decides (decide.py),
    heard in the language of `parser`'s orders."""
    for path in files:
        try:
            heard = list(stream_finals(engine, path, parser.orders.language))
        except AudioError as exc:
            yield Unreadable(file=str(path), error=str(exc))
            continue
        yield _file_line(path, heard, parser)


def stream_finals(engine: Engine, path: Path, language: str = "en") -> Iterator[Final]:
    """The final results of a file streamed through a recogniser as a microphone's audio,
    a second at a time, times counted from the file's start."""
    recogniser = engine.recogniser(MAX_UTTERANCE, language=language)
    try:
        lead = recogniser.accept(bytes(int(LEAD_SILENCE * 32000)))
        events = [e for e in lead if isinstance(e, Final)]
        for block in read_blocks(path):
            yield from _shifted(events)
            events = [e for e in recogniser.accept(block) if isinstance(e, Final)]
        events += [e for e in recogniser.finish() if isinstance(e, Final)]
        yield from _shifted(events)
    finally:
        recogniser.close()


def _shifted(finals: list[Final]) -> Iterator[Final]:
    for final in finals:
        yield msgspec.structs.replace(
            final,
            speech_start=max(0.0, final.speech_start - LEAD_SILENCE),
            speech_end=max(0.0, final.speech_end - LEAD_SILENCE),
        )


def _file_line(path: Path, heard: list[Final], parser: Parser) -> FileTranscript:
    language = parser.orders.language
    decisions = [
        decide(*readings(transcript_of(final, language=language), parser)) for final in heard
    ]
    utterances = [_utterance(f, d) for f, d in zip(heard, decisions, strict=True)]
    taken = [u for u in utterances if not u.rejected]
    refused = [d for d in decisions if d.rejected]
    if not heard:
        reason = "no speech heard"
    elif not taken:
        reason = refused[0].reason
    else:
        reason = ""
    return FileTranscript(
        file=str(path),
        transcript=" ".join(u.transcript for u in (taken or utterances) if u.transcript),
        rejected=not taken,
        reason=reason,
        orders=[order for u in taken for order in u.orders],
        errors=[problem(d) for d in refused],
        doubts=utterances[0].doubts if len(utterances) == 1 else [],
        hearings=[h for u in utterances for h in u.hearings],
        decision="; ".join(u.decision for u in utterances if u.decision),
        utterances=utterances,
        diagnostics=Diagnostics(
            grammar_confidence=min((f.confidence for f in heard), default=None),
            grammar_word_confidences=[c for f in heard for c in f.confidences],
            open_decode=" ".join(f.heard for f in heard if f.heard),
        ),
    )


def _utterance(final: Final, decision: Decision) -> Utterance:
    return Utterance(
        start=round(final.speech_start, 2),
        end=round(final.speech_end, 2),
        transcript=decision.text,
        rejected=decision.rejected,
        reason=decision.reason if decision.rejected else "",
        orders=decision.orders,
        doubts=decision.doubts,
        hearings=decision.hearings,
        decision=decision.reason,
    )
