"""Decoding in worker processes, so that several people can speak at once on several cores.

pocketsphinx's Python binding holds the GIL while it decodes: the sessions of one process
share one core however many threads they run on. On the 2-core machine four people
speaking at once took end of speech to final transcript to 1.6 s p95 (bench/e2e.py
--speakers). `ProcessEngine` runs N worker processes, each with an engine of its own (its
models loaded once per process), and lends a new session's recogniser from the one with
the fewest sessions. Every recogniser call is a round trip over that worker's pipe; the
session's thread waits on the pipe without the GIL, so the workers decode in parallel.

The pipe carries this module's own objects between processes it started (pickled, as
`multiprocessing` does); nothing from the bus crosses it undecoded.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import signal
import threading
from dataclasses import replace
from multiprocessing.connection import Connection
from typing import TYPE_CHECKING, Any

from msgspec import Struct

from voicectl.shared.messages import Grammar, PhraseCheck

from .engine import EngineError, EngineOptions, Recogniser, RecognitionEvent, load_here

if TYPE_CHECKING:
    from multiprocessing.context import SpawnProcess

_LOGGER = logging.getLogger(__name__)

START_TIMEOUT = 120.0
"""Seconds a worker may take to load its engine (models from disk, a cold cache)."""


# What the parent asks of a worker, one Struct per engine call; the worker keeps its
# recognisers by number.


class _UseGrammar(Struct, frozen=True, tag=True):
    grammar: Grammar


class _Open(Struct, frozen=True, tag=True):
    """A new recogniser; the reply is its number."""

    max_utterance: float
    segment: bool
    language: str = "en"


class _Accept(Struct, frozen=True, tag=True):
    recogniser: int
    pcm: bytes


class _Finish(Struct, frozen=True, tag=True):
    recogniser: int


class _Close(Struct, frozen=True, tag=True):
    """The recogniser's decoder goes back to the worker's pool."""

    recogniser: int


class _Check(Struct, frozen=True, tag=True):
    pcm: bytes
    phrase: str


_Call = _UseGrammar | _Open | _Accept | _Finish | _Close | _Check


class _Reply(Struct, frozen=True):
    value: Any = None
    error: str = ""
    """An EngineError's text; the caller raises it again."""


class ProcessEngine:
    """An engine whose recognisers run in worker processes; same calls as the others."""

    def __init__(self, options: EngineOptions, workers: int) -> None:
        self.name = options.name
        context = multiprocessing.get_context("spawn")  # never fork Zenoh's threads
        self._workers: list[_Worker] = []
        self.languages: frozenset[str] = frozenset()
        try:
            for number in range(workers):
                self._workers.append(_Worker(context, replace(options, workers=0), number))
            for worker in self._workers:
                self.languages = frozenset(worker.wait_ready())
        except BaseException:
            self.close()
            raise

    def use_grammar(self, grammar: Grammar) -> list[str]:
        unpronounceable: list[str] = []
        for worker in self._workers:
            unpronounceable = worker.call(_UseGrammar(grammar))
        return unpronounceable

    def recogniser(
        self, max_utterance: float, segment: bool = True, language: str = "en"
    ) -> Recogniser:
        worker = min(self._workers, key=lambda w: w.sessions)
        number: int = worker.call(_Open(max_utterance, segment, language))
        worker.sessions += 1
        return _RemoteRecogniser(worker, number)

    def check(self, pcm: bytes, phrase: str) -> PhraseCheck:
        worker = min(self._workers, key=lambda w: w.sessions)
        checked: PhraseCheck = worker.call(_Check(pcm, phrase))
        return checked

    def close(self) -> None:
        for worker in self._workers:
            worker.close()


class _Worker:
    """One worker process and the pipe to it; calls from several threads take turns."""

    def __init__(self, context: Any, options: EngineOptions, number: int) -> None:
        self._connection, theirs = context.Pipe()
        self._process: SpawnProcess = context.Process(
            target=_serve, args=(theirs, options), name=f"stt-worker-{number}", daemon=True
        )
        self._process.start()
        theirs.close()
        self._lock = threading.Lock()
        self.sessions = 0

    def wait_ready(self) -> list[str]:
        """The languages its engine hears, once it has loaded."""
        try:
            if not self._connection.poll(START_TIMEOUT):
                raise EngineError(f"a decoding worker did not start within {START_TIMEOUT:.0f} s")
            languages: list[str] = self._answer(self._connection.recv())
            return languages
        except (EOFError, OSError) as exc:
            code = self._process.exitcode
            raise EngineError(f"a decoding worker exited as it started (exit code {code})") from exc

    def call(self, call: _Call) -> Any:
        with self._lock:
            try:
                self._connection.send(call)
                reply = self._connection.recv()
            except (EOFError, OSError) as exc:
                raise EngineError(f"decoding worker {self._process.name} is gone: {exc}") from exc
        return self._answer(reply)

    @staticmethod
    def _answer(reply: _Reply) -> Any:
        if reply.error:
            raise EngineError(reply.error)
        return reply.value

    def close(self) -> None:
        with self._lock, contextlib.suppress(OSError):
            self._connection.close()  # the worker sees the end of its pipe and returns
        self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(timeout=5.0)


class _RemoteRecogniser:
    def __init__(self, worker: _Worker, number: int) -> None:
        self._worker = worker
        self._number = number
        self._closed = False

    def accept(self, pcm: bytes) -> list[RecognitionEvent]:
        events: list[RecognitionEvent] = self._worker.call(_Accept(self._number, pcm))
        return events

    def finish(self) -> list[RecognitionEvent]:
        events: list[RecognitionEvent] = self._worker.call(_Finish(self._number))
        return events

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._worker.sessions -= 1
        with contextlib.suppress(EngineError):  # a worker that is gone holds nothing
            self._worker.call(_Close(self._number))


def _serve(connection: Connection, options: EngineOptions) -> None:
    """A worker's life: load the engine, then answer calls until the pipe closes."""
    # Ctrl-C reaches the whole process group: the service stops its workers itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        engine = load_here(options)
    except EngineError as exc:
        connection.send(_Reply(error=str(exc)))
        return
    connection.send(_Reply(sorted(engine.languages)))
    recognisers: dict[int, Recogniser] = {}
    count = 0
    while True:
        try:
            call = connection.recv()
        except (EOFError, OSError):
            break
        try:
            match call:
                case _UseGrammar(grammar=grammar):
                    reply = _Reply(engine.use_grammar(grammar))
                case _Open(max_utterance=limit, segment=segment, language=language):
                    count += 1
                    recognisers[count] = engine.recogniser(limit, segment, language)
                    reply = _Reply(count)
                case _Accept(recogniser=number, pcm=pcm):
                    reply = _Reply(recognisers[number].accept(pcm))
                case _Finish(recogniser=number):
                    reply = _Reply(recognisers[number].finish())
                case _Close(recogniser=number):
                    recognisers.pop(number).close()
                    reply = _Reply()
                case _Check(pcm=pcm, phrase=phrase):
                    reply = _Reply(engine.check(pcm, phrase))
        except EngineError as exc:
            reply = _Reply(error=str(exc))
        except Exception as exc:  # the session logs it; the worker serves the others
            _LOGGER.exception("decoding worker: %s failed", type(call).__name__)
            reply = _Reply(error=f"the decoding worker failed: {exc}")
        connection.send(reply)
    for recogniser in recognisers.values():
        recogniser.close()
    engine.close()
