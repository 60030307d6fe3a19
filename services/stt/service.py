"""The recogniser on the bus: audio sessions in, partial and final transcripts out.

Each session (``voice/<robot>/stt/audio/<session>``) gets its own recogniser, run on a
thread of its own, so a slow session never delays another and decoding never blocks the
event loop. A final transcript is rejected (never to become orders) when the engine finds
no command in the speech or too little confidence, or when the converter cannot make
whole orders of it: at least two signals, as a grammar-bound recogniser forces some
command out of any speech.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from types import TracebackType

from shared.bus import Bus, Latest, json_decoder
from shared.errors import BusError
from shared.keys import ConverterKeys, RobotKeys, last_chunk
from shared.messages import (
    AudioChunk,
    AudioMessage,
    AudioStart,
    AudioStop,
    Failed,
    GetGrammar,
    Grammar,
    ParseReply,
    ParseRequest,
    PartialTranscript,
    SttStatus,
    Transcript,
)

from .audio import BYTES_PER_SECOND
from .engine import Engine, EngineError, Event, Final, Heard, Recogniser, SpeechStarted

_LOGGER = logging.getLogger(__name__)


@dataclass(frozen=True)
class Limits:
    """What keeps one client from taking the service down."""

    max_utterance: float = 15.0
    """Seconds; an utterance that goes on longer is cut and recognised as it is."""
    max_sessions: int = 8
    """Open sessions per robot; each holds a decoder (about 30 MB for pocketsphinx)."""
    idle_seconds: float = 30.0
    """A session that sends nothing for this long is stopped."""
    max_backlog: float = 5.0
    """Seconds of audio waiting to be decoded before a session's new audio is dropped."""


class Session:
    """One audio stream: its recogniser on its own thread, events back on the loop."""

    def __init__(self, name: str, service: SttService) -> None:
        self.name = name
        self._service = service
        self._loop = asyncio.get_running_loop()
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"stt-{name}")
        self._recogniser: Recogniser | None = None
        self._events: asyncio.Queue[Event | None] = asyncio.Queue()
        self._publisher = asyncio.create_task(self._publish_events())
        self._next_seq = 0
        self._backlog = 0
        """Bytes handed to the worker and not yet decoded."""
        self.last_heard = self._loop.time()
        self.stopping = False
        self._refused = ""
        """Why no recogniser could be made (no grammar yet); said once, at the end."""

    def feed(self, chunk: AudioChunk) -> None:
        self.last_heard = self._loop.time()
        if chunk.seq != self._next_seq:
            _LOGGER.warning(
                "session %s: chunk %d arrived, %d expected; audio was lost or reordered",
                self.name,
                chunk.seq,
                self._next_seq,
            )
        self._next_seq = chunk.seq + 1
        limit = self._service.limits.max_backlog * BYTES_PER_SECOND
        if self._backlog + len(chunk.pcm) > limit:
            _LOGGER.warning(
                "session %s falls behind: %d ms dropped", self.name, len(chunk.pcm) // 32
            )
            return
        self._backlog += len(chunk.pcm)
        self._run(self._accept, chunk.pcm)

    def stop(self) -> None:
        """Finish the utterance in progress, then release the recogniser."""
        if not self.stopping:
            self.stopping = True
            self._run(self._finish)

    async def closed(self) -> None:
        """Wait until the last event is published, then free the thread."""
        await self._publisher
        self._worker.shutdown(wait=False)

    def abort(self) -> None:
        """Stop at once (the service is stopping): drop queued audio and events."""
        self._worker.shutdown(wait=True, cancel_futures=True)
        if self._recogniser is not None:
            self._recogniser.close()
        self._publisher.cancel()

    # --- on the worker thread ------------------------------------------------------------

    def _accept(self, pcm: bytes) -> list[Event | None]:
        try:
            if self._recogniser is None and not self._refused:
                try:
                    self._recogniser = self._service.engine.recogniser(
                        self._service.limits.max_utterance
                    )
                except EngineError as exc:
                    self._refused = str(exc)
                    _LOGGER.warning("session %s cannot be recognised: %s", self.name, exc)
            return [] if self._recogniser is None else list(self._recogniser.accept(pcm))
        finally:
            self._loop.call_soon_threadsafe(self._decoded, len(pcm))

    def _finish(self) -> list[Event | None]:
        events: list[Event | None] = []
        try:
            if self._recogniser is not None:
                events.extend(self._recogniser.finish())
                self._recogniser.close()
                self._recogniser = None
            elif self._refused:
                events.append(Final(0, "", 0.0, f"cannot recognise: {self._refused}", 0.0, 0.0))
        except Exception:
            _LOGGER.exception("session %s: recogniser failed at the end", self.name)
        events.append(None)  # the end of the session for the publisher
        return events

    # --- on the loop ----------------------------------------------------------------------

    def _decoded(self, size: int) -> None:
        self._backlog -= size

    def _run(self, job: Callable[..., list[Event | None]], *args: object) -> None:
        future = self._loop.run_in_executor(self._worker, job, *args)
        future.add_done_callback(self._delivered)

    def _delivered(self, future: asyncio.Future[list[Event | None]]) -> None:
        if future.cancelled():
            return
        error = future.exception()
        if error is not None:
            if isinstance(error, EngineError):
                _LOGGER.warning("session %s: %s", self.name, error)
            else:
                _LOGGER.error("session %s: recogniser failed: %r", self.name, error)
            return
        for event in future.result():
            self._events.put_nowait(event)

    async def _publish_events(self) -> None:
        while (event := await self._events.get()) is not None:
            await self._service.publish(self.name, event)


class SttService:
    """Serves one robot's audio sessions with one engine, following the converter's grammar.

    Use it as a context manager: entering subscribes and announces the service.
    """

    def __init__(self, bus: Bus, robot: str, engine: Engine, limits: Limits) -> None:
        self.bus = bus
        self.engine = engine
        self.limits = limits
        self._keys = RobotKeys(robot)
        self._converter = ConverterKeys()
        self._sessions: dict[str, Session] = {}
        self._grammar = ""
        """Version of the grammar in use; empty before the first."""
        self._wanted: Grammar | None = None
        self._compiling: asyncio.Task[None] | None = None
        self._status: Latest | None = None
        self._unpronounceable: list[str] = []
        self._parse_decode = json_decoder(ParseReply | Failed)
        self._endings: set[asyncio.Task[None]] = set()
        """Sessions finishing their last utterance (the loop keeps only weak references)."""

    def __enter__(self) -> SttService:
        self._status = self.bus.latest(self._keys.stt_status)
        self._publish_status("waiting for the converter's grammar")
        self.bus.subscribe(self._converter.grammar, json_decoder(Grammar), self._on_grammar)
        self.bus.subscribe(self._keys.stt_audio_any, json_decoder(AudioMessage), self._on_audio)
        self.bus.announce(self._keys.alive("stt"))
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        for session in self._sessions.values():
            session.abort()
        self._sessions.clear()

    async def run(self) -> None:
        """Ask for the grammar once (it is also published), then stop idle sessions."""
        with contextlib.suppress(BusError):
            reply = await self.bus.request(
                self._converter.grammar, GetGrammar(), json_decoder(Grammar | Failed)
            )
            if isinstance(reply, Grammar):
                self._on_grammar(self._converter.grammar, reply)
        while True:
            await asyncio.sleep(1.0)
            now = asyncio.get_running_loop().time()
            for session in list(self._sessions.values()):
                if not session.stopping and now - session.last_heard > self.limits.idle_seconds:
                    _LOGGER.info(
                        "session %s idle for %g s: stopped", session.name, self.limits.idle_seconds
                    )
                    self._stop(session)

    # --- grammar ---------------------------------------------------------------------------

    def _on_grammar(self, _key: str, grammar: Grammar) -> None:
        if grammar.version in (self._grammar, self._wanted.version if self._wanted else ""):
            return
        self._wanted = grammar
        if self._compiling is None or self._compiling.done():
            self._compiling = asyncio.create_task(self._compile())

    async def _compile(self) -> None:
        """Compile the newest grammar off the loop; one compile at a time, latest wins."""
        while self._wanted is not None and self._wanted.version != self._grammar:
            grammar = self._wanted
            try:
                missing = await asyncio.to_thread(self.engine.use_grammar, grammar)
            except EngineError as exc:
                _LOGGER.error("grammar %s not used: %s", grammar.version, exc)
                self._publish_status(f"grammar {grammar.version} not used: {exc}")
                self._wanted = None
                return
            self._grammar = grammar.version
            self._unpronounceable = missing
            if missing:
                _LOGGER.warning(
                    "grammar %s: no pronunciation for %s; commands with them cannot be heard",
                    grammar.version,
                    ", ".join(missing),
                )
            _LOGGER.info(
                "listening with grammar %s (%d phrases)", grammar.version, len(grammar.phrases)
            )
            self._publish_status(f"listening for {len(grammar.phrases)} phrases")

    def _publish_status(self, detail: str) -> None:
        assert self._status is not None
        self._status.publish(
            SttStatus(
                engine=self.engine.name,
                ready=bool(self._grammar),
                grammar_version=self._grammar,
                detail=detail,
                sessions=len(self._sessions),
                unpronounceable=self._unpronounceable,
            )
        )

    # --- audio -----------------------------------------------------------------------------

    def _on_audio(self, key: str, message: AudioMessage) -> None:
        name = last_chunk(key)
        session = self._sessions.get(name)
        match message:
            case AudioStart():
                if session is not None:
                    return  # a repeated start: the session goes on
                if len(self._sessions) >= self.limits.max_sessions:
                    _LOGGER.warning(
                        "session %s refused: %d sessions open already", name, len(self._sessions)
                    )
                    return
                self._sessions[name] = Session(name, self)
                _LOGGER.info("session %s started", name)
            case AudioChunk():
                if session is None:
                    _LOGGER.warning("audio for session %s, which was not started: dropped", name)
                elif not session.stopping:
                    session.feed(message)
            case AudioStop():
                if session is None:
                    _LOGGER.warning("stop for session %s, which was not started: ignored", name)
                else:
                    self._stop(session)

    def _stop(self, session: Session) -> None:
        session.stop()

        async def forget() -> None:
            await session.closed()
            if self._sessions.get(session.name) is session:
                del self._sessions[session.name]
            _LOGGER.info("session %s ended", session.name)

        task = asyncio.create_task(forget())
        self._endings.add(task)
        task.add_done_callback(self._endings.discard)

    async def publish(self, session: str, event: Event) -> None:
        """Put one recogniser event on the bus; a final one is checked against the orders."""
        match event:
            case SpeechStarted():
                pass
            case Heard(utterance=utterance, text=text):
                partial = PartialTranscript(session=session, utterance=utterance, text=text)
                self.bus.publish(self._keys.partial, partial, superseded=True)
            case Final():
                transcript = await self._judge(session, event)
                _LOGGER.info(
                    "session %s utterance %d: %r%s",
                    session,
                    event.utterance,
                    transcript.text,
                    f" rejected: {transcript.reason}" if transcript.rejected else "",
                )
                self.bus.publish(self._keys.transcript, transcript)

    async def _judge(self, session: str, final: Final) -> Transcript:
        reason = final.rejection
        if not reason and not self._grammar:
            reason = "no grammar yet: is the converter running?"
        if not reason:
            reason = await self._parse_problem(final.text)
        return Transcript(
            text=final.text,
            confidence=final.confidence,
            session=session,
            utterance=final.utterance,
            rejected=bool(reason),
            reason=reason,
            speech_start=round(final.speech_start, 3),
            speech_end=round(final.speech_end, 3),
        )

    async def _parse_problem(self, text: str) -> str:
        """Why `text` does not make whole orders, or '' when it does (or when the
        converter cannot tell now: it parses the transcript again anyway)."""
        try:
            reply = await self.bus.request(
                self._converter.parse, ParseRequest(text=text), self._parse_decode
            )
        except BusError as exc:
            _LOGGER.warning("could not check %r with the converter: %s", text, exc)
            return ""
        if isinstance(reply, Failed):
            return ""
        result = reply.result
        if result.errors:
            return f"not a command: {result.errors[0].reason}"
        if not result.orders:
            return "not a command"
        return ""
