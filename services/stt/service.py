"""The recogniser on the bus: audio sessions in, partial and final transcripts out.

Each session (``voice/<robot>/stt/audio/<session>``) gets its own recogniser, run on a
thread of its own, so a slow session never delays another and decoding never blocks the
event loop. A final transcript is rejected (never to become orders) when the engine finds
no command in the speech, or too little confidence, or its second opinion says it was not
a command; the converter, which parses it once, rejects it too when it does not make whole
orders: a grammar-bound recogniser forces some command out of any speech.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import ctypes
import logging
import queue
import threading
import time
from dataclasses import dataclass

from voicectl.shared.bus import Bus, Latest, json_decoder
from voicectl.shared.keys import ConverterKeys, RobotKeys, last_chunk
from voicectl.shared.messages import (
    AudioChunk,
    AudioMessage,
    AudioStart,
    AudioStop,
    CheckPhrase,
    Grammar,
    Message,
    OrdersStatus,
    PartialTranscript,
    SessionEnded,
    SttStatus,
    Transcript,
    excerpt,
)
from voicectl.shared.process import Service
from voicectl.shared.throttle import Throttled

from .audio import BYTES_PER_SECOND
from .checks import PhraseChecks
from .engine import Engine, EngineError, Final, Heard, Recogniser, RecognitionEvent, SpeechStarted

_LOGGER = logging.getLogger(__name__)

MAX_LANGUAGES = 32
"""Languages whose grammar one recogniser follows at most: each is a subscription."""


@dataclass(frozen=True)
class SessionLimits:
    """What keeps one client from taking the service down."""

    max_utterance: float = 15.0
    """Seconds; an utterance that goes on longer is cut and recognised as it is."""
    max_sessions: int = 8
    """Open sessions per robot; each holds a decoder (about 30 MB for pocketsphinx)."""
    idle_seconds: float = 30.0
    """A session that sends nothing for this long is ended, what it holds dropped: its
    sender has gone."""
    max_backlog: float = 5.0
    """Seconds of audio waiting to be decoded before a session's new audio is dropped."""
    max_session: float = 300.0
    """Seconds a session may stay open: sessions held open lock everyone else out. Past
    it the session ends (its utterance in progress is finished); a person opens another."""
    min_audio: float = 0.25
    """Seconds of audio a session must send per second, over each `audio_window`: a
    microphone sends one, and a session that trickles far less holds a place nobody
    speaks in (eight such kept every microphone out, never idle long enough to close)."""
    audio_window: float = 10.0
    """Seconds over which `min_audio` is measured."""


class Session:
    """One audio stream: its recogniser on a thread of its own, fed straight from Zenoh's
    thread; only the recogniser's events (a few a second) go through the loop.

    Handing every 20 ms chunk through the loop to a thread pool cost 40 % more CPU than
    decoding in bulk, most of it in waking threads: here a chunk wakes one thread.
    """

    def __init__(
        self,
        name: str,
        service: SttService,
        loop: asyncio.AbstractEventLoop,
        language: str = "",
    ) -> None:
        self.name = name
        self.language = language or service.language
        """What the person speaks: the session's own choice, else the recogniser's."""
        self._service = service
        self._loop = loop
        self._inbox: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._events: asyncio.Queue[RecognitionEvent | None] = asyncio.Queue()
        self._next_seq = 0
        self._backlog = 0
        """Bytes in the inbox, not yet decoded (updated on both threads under the lock)."""
        self._lock = threading.Lock()
        self.last_heard = time.monotonic()
        self.opened = self.last_heard
        self._window = (self.opened, 0)
        """Since when audio is counted, and how many bytes came since (under the lock)."""
        self.stopping = False
        self.finished = loop.create_future()
        """Done once the last event of the session is published."""
        self._aborted = False
        self._publisher: asyncio.Task[None] | None = None
        self._recogniser: Recogniser | None = None
        self._refused = ""
        """Why no recogniser could be made (no grammar yet); said at the end if it lasts."""
        self._held: collections.deque[bytes] = collections.deque()
        """Audio heard while no recogniser could be made (on the session's thread)."""
        loop.call_soon_threadsafe(self._start_publisher)  # made on Zenoh's thread
        self._thread = threading.Thread(target=self._work, name=f"stt-{name}", daemon=True)
        self._thread.start()

    def feed(self, chunk: AudioChunk) -> None:
        """On Zenoh's thread: queue the audio for the recogniser."""
        self.last_heard = time.monotonic()
        if chunk.seq != self._next_seq:
            self._service.noise.warning(
                "order",
                "session %s: chunk %d arrived, %d expected; audio was lost or reordered",
                self.name,
                chunk.seq,
                self._next_seq,
            )
        self._next_seq = chunk.seq + 1
        with self._lock:
            since, received = self._window
            self._window = (since, received + len(chunk.pcm))
            if self._backlog + len(chunk.pcm) > self._service.limits.max_backlog * BYTES_PER_SECOND:
                self._service.noise.warning(
                    "behind",
                    "session %s falls behind: %d ms dropped",
                    self.name,
                    len(chunk.pcm) // 32,
                )
                return
            self._backlog += len(chunk.pcm)
        self._inbox.put(chunk.pcm)

    def stop(self) -> None:
        """Any thread: finish the utterance in progress, then release the recogniser."""
        with self._lock:
            if self.stopping:
                return
            self.stopping = True
        self._inbox.put(None)

    def audio_sent(self, now: float, window: float) -> float | None:
        """Seconds of audio received over the last `window` seconds, once that much time
        has passed since the count began (a new count begins then); None before."""
        with self._lock:
            since, received = self._window
            if now - since < window:
                return None
            self._window = (now, 0)
        return received / BYTES_PER_SECOND

    def drop(self) -> None:
        """Any thread: end the session without recognising what it still holds: its
        sender has gone, and nobody would act on a transcript made now."""
        self._aborted = True
        self.stop()

    def abort(self) -> None:
        """The service is stopping: drop what is queued and end the thread now."""
        self.drop()
        self._thread.join(timeout=5.0)
        if self._publisher is not None:
            self._publisher.cancel()

    # --- on the session's thread ---------------------------------------------------------

    def _work(self) -> None:
        while (pcm := self._inbox.get()) is not None:
            with self._lock:
                self._backlog -= len(pcm)
            if not self._aborted:
                self._recognise(pcm)
        if not self._aborted:
            self._recognise(b"")  # a grammar that came after the last audio still hears it
        self._post([*self._finish(), None])  # None: the end of the session for the publisher

    def _recognise(self, pcm: bytes) -> None:
        """Feed `pcm` to the recogniser, made at the first audio. Before any grammar none
        can be made: the audio is held (its last `max_utterance` seconds) and heard once
        the grammar comes, so a session opened while the stack starts is not lost."""
        try:
            if self._recogniser is None:
                if pcm:
                    self._held.append(pcm)
                if not self._held:
                    return
                self._recogniser = self._service.engine.recogniser(
                    self._service.limits.max_utterance, language=self.language
                )
                if self._refused:
                    _LOGGER.info("session %s is recognised from now on", self.name)
                while self._held:
                    self._post(self._recogniser.accept(self._held.popleft()))
            elif pcm:
                self._post(self._recogniser.accept(pcm))
        except EngineError as exc:
            if not self._refused:
                _LOGGER.warning("session %s cannot be recognised yet: %s", self.name, exc)
            self._refused = str(exc)
            if self._recogniser is not None:
                self._held.clear()
            limit = self._service.limits.max_utterance * BYTES_PER_SECOND
            while sum(map(len, self._held)) > limit:  # only until the grammar comes
                self._held.popleft()
        except Exception:
            _LOGGER.exception("session %s: the recogniser failed; audio dropped", self.name)

    def _finish(self) -> list[RecognitionEvent]:
        """The utterance in progress, or why the session could not be heard at all."""
        try:
            if self._recogniser is not None:
                events = [] if self._aborted else self._recogniser.finish()
                self._recogniser.close()
                return events
            if self._refused:
                return [Final(0, "", 0.0, f"cannot recognise: {self._refused}", 0.0, 0.0)]
        except Exception:
            _LOGGER.exception("session %s: the recogniser failed at the end", self.name)
        return []

    def _post(self, events: list[RecognitionEvent] | list[RecognitionEvent | None]) -> None:
        for event in events:
            with contextlib.suppress(RuntimeError):  # the loop is closing
                self._loop.call_soon_threadsafe(self._events.put_nowait, event)

    # --- on the loop ----------------------------------------------------------------------

    def _start_publisher(self) -> None:
        self._publisher = asyncio.create_task(self._publish_events())

    async def _publish_events(self) -> None:
        try:
            while (event := await self._events.get()) is not None:
                await self._service.publish(self.name, event)
        finally:
            if not self.finished.done():
                self.finished.set_result(None)


class SttService(Service):
    """Serves one robot's audio sessions with one engine, following the converter's grammar.

    A service (shared/process.py): `start()` subscribes and announces it, `run()` ends
    sessions that went quiet, `stop()` aborts the sessions still open.
    """

    def __init__(
        self, bus: Bus, robot: str, engine: Engine, limits: SessionLimits, language: str = "en"
    ) -> None:
        self._robot = robot
        self.language = language
        """What its sessions are heard in unless a session says otherwise (`--language`)."""
        self.bus = bus
        self.engine = engine
        self.limits = limits
        self._keys = RobotKeys(robot)
        self._converter = ConverterKeys()
        self._sessions: dict[str, Session] = {}
        self._sessions_lock = threading.Lock()
        """Sessions are opened and fed on Zenoh's thread, and ended on the loop."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._grammars: dict[str, str] = {}
        """Version of the grammar in use, per language; none before the first."""
        self._wanted: dict[str, Grammar] = {}
        self._following: set[str] = set()
        """The languages whose grammar it subscribes to."""
        self._compiling: asyncio.Task[None] | None = None
        self._status: Latest | None = None
        self._unpronounceable: list[str] = []
        self._detail = ""
        self._checks = PhraseChecks(engine.check)
        self.noise = Throttled(_LOGGER)
        """Warnings a sender can cause once per message (refused sessions, chunks out of
        order, for no session or dropped): at most one of a kind every 10 s."""
        self._refused = _Recent(256)
        """Sessions refused or unknown, so that their audio is dropped without a line
        per chunk (the last few hundred names)."""

    async def start(self) -> None:
        self._status = self.bus.latest(self._keys.stt_status)
        self._publish_status("waiting for the converter's grammar")
        self._follow(self.language)
        self.bus.subscribe(
            self._converter.status, json_decoder(OrdersStatus), self._on_orders, history=True
        )
        self._loop = asyncio.get_running_loop()
        self.bus.subscribe(
            self._keys.stt_audio_any, json_decoder(AudioMessage), self._on_audio, on_loop=False
        )
        self.bus.serve(self._keys.stt_check, json_decoder(CheckPhrase), self._on_check)
        self.bus.announce(self._keys.alive("stt"))
        _LOGGER.info("stt ready for robot %s with %s", self._robot, self.engine.name)

    async def stop(self) -> None:
        with self._sessions_lock:
            sessions = list(self._sessions.values())
            self._sessions.clear()
        for session in sessions:
            session.abort()

    async def run(self) -> None:
        """Stop sessions that went quiet; runs until cancelled."""
        while True:
            await asyncio.sleep(1.0)
            now = time.monotonic()
            with self._sessions_lock:
                sessions = list(self._sessions.values())
            for session in sessions:
                ending = None if session.stopping else self._ending(session, now)
                if ending is not None:
                    reason, drop = ending
                    _LOGGER.info("session %s closed: %s", session.name, reason)
                    self._stop(session, drop)
                    self._tell(session.name, SessionEnded(reason=reason))

    def _ending(self, session: Session, now: float) -> tuple[str, bool] | None:
        """Why `session` must end now, and whether what it holds is dropped (nobody
        speaks in it); None while it may go on."""
        limits = self.limits
        if now - session.last_heard > limits.idle_seconds:
            return f"no audio for {limits.idle_seconds:g} s: the microphone closed", True
        if now - session.opened > limits.max_session:
            return (
                f"open for {limits.max_session:g} s, the longest a session may be: start a new one",
                False,
            )
        sent = session.audio_sent(now, limits.audio_window)
        if sent is not None and sent < limits.min_audio * limits.audio_window:
            return (
                f"{sent:.1f} s of audio in {limits.audio_window:g} s: a microphone sends "
                "as much audio as time passes",
                True,
            )
        return None

    async def _on_check(self, request: CheckPhrase) -> Message:
        return await self._checks.ask(request)

    # --- grammar ---------------------------------------------------------------------------

    @property
    def _grammar(self) -> str:
        """The version of the grammar its own language is heard with; '' before it."""
        return self._grammars.get(self.language, "")

    def _on_orders(self, _key: str, status: OrdersStatus) -> None:
        """The converter's orders are in these languages: follow the grammar of each this
        engine hears. One key per language, each asked for its history: a late subscriber
        to all of them at once (`grammar/*`) was given only some (zenoh 1.10)."""
        for language in status.languages[:MAX_LANGUAGES]:
            if language in self.engine.languages:
                self._follow(language)

    def _follow(self, language: str) -> None:
        if language in self._following or len(self._following) >= MAX_LANGUAGES:
            return
        try:
            key = self._converter.grammar(language)
        except ValueError:
            return  # no language code: a converter on this bus does not send it
        self._following.add(language)
        self.bus.subscribe(key, json_decoder(Grammar), self._on_grammar, history=True)

    def _on_grammar(self, _key: str, grammar: Grammar) -> None:
        language = grammar.language
        if language not in self.engine.languages:
            return  # orders in a language this engine does not hear: no session can ask
        wanted = self._wanted.get(language)
        if grammar.version in (self._grammars.get(language), wanted.version if wanted else ""):
            return
        self._wanted[language] = grammar
        if self._compiling is None or self._compiling.done():
            self._compiling = asyncio.create_task(self._compile())

    async def _compile(self) -> None:
        """Compile the newest grammars off the loop; one compile at a time, latest wins."""
        while self._wanted:
            language, grammar = next(iter(self._wanted.items()))
            if grammar.version == self._grammars.get(language):
                del self._wanted[language]
                continue
            try:
                missing = await asyncio.to_thread(self.engine.use_grammar, grammar)
            except EngineError as exc:
                _LOGGER.error("grammar %s not used: %s", grammar.version, exc)
                self._publish_status(f"grammar {grammar.version} not used: {exc}")
                if self._wanted.get(language) is grammar:
                    del self._wanted[language]
                continue
            self._grammars[language] = grammar.version
            if language != self.language:
                _LOGGER.info("listening in %s too, with grammar %s", language, grammar.version)
                continue
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
        """Publish the status; an empty `detail` keeps the last one (a session count)."""
        assert self._status is not None
        self._detail = detail or self._detail
        self._status.publish(
            SttStatus(
                engine=self.engine.name,
                ready=bool(self._grammar),
                grammar_version=self._grammar,
                detail=self._detail,
                sessions=len(self._sessions),
                unpronounceable=self._unpronounceable,
            )
        )

    # --- audio -----------------------------------------------------------------------------

    def _on_audio(self, key: str, message: AudioMessage) -> None:
        """On Zenoh's thread: open, feed or stop a session."""
        name = last_chunk(key)
        with self._sessions_lock:
            session = self._sessions.get(name)
            if isinstance(message, AudioStart) and session is None:
                if len(self._sessions) >= self.limits.max_sessions:
                    self.noise.warning(
                        "refused",
                        "session %s refused: %d sessions open already",
                        name,
                        len(self._sessions),
                    )
                    self._refused.add(name)
                    self._tell(
                        name,
                        SessionEnded(
                            reason=f"speech recognition is busy ({len(self._sessions)} "
                            "microphones open): try again when one closes",
                            refused=True,
                        ),
                    )
                    return
                assert self._loop is not None
                language = message.language
                if language and language not in self.engine.languages:
                    self._refused.add(name)
                    self._tell(
                        name,
                        SessionEnded(
                            reason=f"this recogniser ({self.engine.name}) does not hear "
                            f"{language!r}",
                            refused=True,
                        ),
                    )
                    return
                session = self._sessions[name] = Session(name, self, self._loop, language)
                self._refused.discard(name)
                _LOGGER.info("session %s started", name)
                self._loop.call_soon_threadsafe(self._publish_status, "")
                return
        match message:
            case AudioStart():
                pass  # a repeated start: the session goes on
            case AudioChunk():
                if session is None:
                    if name not in self._refused:  # said once, not once per chunk
                        self._refused.add(name)
                        self.noise.warning(
                            "unknown", "audio for session %s, not started: dropped", name
                        )
                elif not session.stopping:
                    session.feed(message)
            case AudioStop():
                if session is None:
                    self.noise.warning(
                        "unknown-stop", "stop for session %s, which was not started: ignored", name
                    )
                else:
                    self._stop(session)

    def _stop(self, session: Session, drop: bool = False) -> None:
        """Any thread: end the session (`drop`: without recognising what it holds); it is
        forgotten once its last event is out."""
        if drop:
            session.drop()
        else:
            session.stop()
        assert self._loop is not None
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self._loop.call_soon_threadsafe(session.finished.add_done_callback, self._forget)

    def _forget(self, finished: asyncio.Future[None]) -> None:
        with self._sessions_lock:
            for name, session in list(self._sessions.items()):
                if session.finished is finished:
                    del self._sessions[name]
                    _LOGGER.info("session %s ended", name)
        self._publish_status("")
        if not self._sessions:  # the decoders are gone: their memory goes back too
            _give_back_memory()

    def _tell(self, session: str, ended: SessionEnded) -> None:
        """Any thread: tell the session's sender how it ended, from the loop (a put that
        may wait for room never runs on Zenoh's thread)."""
        assert self._loop is not None
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self._loop.call_soon_threadsafe(
                self.bus.publish, self._keys.stt_session(session), ended
            )

    async def publish(self, session: str, event: RecognitionEvent) -> None:
        """Put one recogniser event on the bus; a final one carries its verdict."""
        match event:
            case SpeechStarted():
                pass
            case Heard(utterance=utterance, text=text):
                partial = PartialTranscript(session=session, utterance=utterance, text=text)
                self.bus.publish(self._keys.partial, partial, superseded=True)
            case Final():
                transcript = self._judge(session, event)
                _LOGGER.info(
                    "session %s utterance %d: %s%s",
                    session,
                    event.utterance,
                    excerpt(transcript.text),
                    f" rejected: {transcript.reason}" if transcript.rejected else "",
                )
                self.bus.publish(self._keys.transcript, transcript)

    def _judge(self, session: str, final: Final) -> Transcript:
        with self._sessions_lock:
            found = self._sessions.get(session)
        language = found.language if found is not None else self.language
        heard = language in self._grammars
        reason = "" if heard else "no grammar yet: is the converter running?"
        if not heard and language != self.language:
            reason = f"no grammar in {language} yet: are there orders in {language}?"
        return transcript_of(final, session, reason, language)


def transcript_of(
    final: Final, session: str = "", refused: str = "", language: str = "en"
) -> Transcript:
    """The bus message of a recogniser's final result; `refused` rejects it whatever the
    engine said (no grammar yet), the second ear's transcript included."""
    reason = final.rejection or refused
    return Transcript(
        text=final.text,
        confidence=final.confidence,
        session=session,
        utterance=final.utterance,
        rejected=bool(reason),
        reason=reason,
        speech_start=round(final.speech_start, 3),
        speech_end=round(final.speech_end, 3),
        heard=final.heard,
        word_confidences=final.confidences,
        doubts=[] if reason else final.doubts,
        transcription=None if refused else final.transcription,
        third=None if refused else final.third,
        language=language,
        alone=final.alone,
    )


class _Recent:
    """A set that remembers only its last `size` names (thread-safe enough: used under
    the sessions lock)."""

    def __init__(self, size: int) -> None:
        self._size = size
        self._names: collections.OrderedDict[str, None] = collections.OrderedDict()

    def __contains__(self, name: object) -> bool:
        return name in self._names

    def add(self, name: str) -> None:
        self._names[name] = None
        self._names.move_to_end(name)
        while len(self._names) > self._size:
            self._names.popitem(last=False)

    def discard(self, name: str) -> None:
        self._names.pop(name, None)


def _give_back_memory() -> None:
    """Return freed heap to the system: glibc keeps what a closed decoder freed (tens of
    megabytes each) for reuse, so the process would stay at its peak for good."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None).malloc_trim(0)
