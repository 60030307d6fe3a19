"""The robot's own ear: a local audio source streamed to the recogniser, hands-free.

One thread reads the source and does everything that must not wait for the event loop:
the spotter hears every frame; after the wake phrase the audio goes to the recogniser as
an ordinary audio session (the panel's microphone is another); "stop", heard alone while
the robot moves, is acted on from that thread's hit at once. The event loop takes the
converter's proposals for this listener's sessions, submits the whole and certain ones
(asking first when an order says `confirm: true`), and speaks the answers.

Without a wake phrase every utterance goes to the recogniser, as with the panel's open
microphone. Either way only whole orders the recogniser is sure of are submitted: what it
doubts is asked about aloud, never guessed.
"""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec

from voicectl.shared import answers
from voicectl.shared.bus import Bus, Stream, json_decoder
from voicectl.shared.client import Refused, Unreachable, VoicectlClient
from voicectl.shared.edits import ended_by_edit, is_edit
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    FRAME_BYTES,
    MAX_CHECK_SECONDS,
    Asked,
    AudioChunk,
    AudioStart,
    AudioStop,
    CheckPhrase,
    Failed,
    OrderRecord,
    OrderStatus,
    PartialTranscript,
    PhraseCheck,
    Proposal,
    StateUpdate,
    Stopped,
    SttReply,
    Via,
)
from voicectl.shared.process import Service
from voicectl.shared.words import word

from .spotter import (
    STOP_LOOP_PENALTY,
    STOP_THRESHOLD,
    WAKE_LOOP_PENALTY,
    WAKE_THRESHOLD,
    Phrase,
    Spotted,
    Spotter,
)
from .wake_model import TrainedSpotter, WakeModel

_LOGGER = logging.getLogger(__name__)

BYTES_PER_SECOND = 32000
ROOM_BEFORE = 0.6
"""Seconds of the room from before the wake phrase, sent ahead of the command: the
recogniser learns the room's level from the start of a session."""
CHECK_BEFORE = 0.25
"""Seconds before the spotted phrase sent with it for the check, which hears it up to
the moment it was spotted (its boundaries are rough). On the dev split this window
confirmed 13 of 16 phrases said alone with 2 false wakes in 18 minutes; the phrase's
own boundaries gave 12 and 4, the last 1.6 s 15 and 5."""
CHECK_AFTER = 0.05
"""Seconds after a trained phrase's end that the check hears at most: the trained
spotter reports the phrase once the pause after it comes, or 0.3 s on when none does, and
by then a command said in one breath has begun; heard by the check, its words are not
the phrase's. On the dev split (trained spotter, phrase alone clean, in pink noise, in
babble, before a command) 0.05 s confirmed 14, 12, 9 of 16 and 47 of 48; 0.2 s 13, 11, 8
and 42; none after the end 14, 9, 10 and 46."""
CHECK_TIMEOUT = 5.0
RECENT_SESSIONS = 4
PHRASE_SECONDS = 2.0
"""Longer than any wake phrase takes to say."""
ECHO_TAIL = 0.3
"""Seconds the microphone stays muted after the robot's own voice ends (room echo)."""
CONFIRM_SOUNDS = {"en": ("yes", "no"), "es": ("si", "no"), "de": ("ja", "nine")}
"""The spoken "yes" and "no" of each language, as the spotter's English dictionary spells
their sounds (Spanish "sí" is its "si", German "nein" its "nine"): a read-back waits for
one of the two in the listener's language. A language without them sends nothing on a
read-back: its orders are asked, never sent hands-free."""
CONFIRM_THRESHOLD = 1e-10
ANSWER_WAIT = 15.0
"""Seconds the end of a file or standard input waits, at most, for the answer to what was
said last: on a busy host the recogniser finishes an utterance seconds after its audio
ended (and a blip it began to hear may end with no answer at all)."""


@dataclass(frozen=True)
class ListenConfig:
    robot: str
    wake: str = ""
    """The wake phrase pocketsphinx listens for; empty: `wake_model`'s, or none (every
    utterance goes to the recogniser)."""
    wake_model: str = ""
    """A trained wake phrase's file (`voicectl wake train`)."""
    wake_threshold: float | None = None
    """The spotter's threshold; None: `WAKE_THRESHOLD`, or the model's own."""
    wake_check: bool = True
    """Whether the recogniser's neural ear must confirm every wake phrase before anything
    said after it is acted on; without, a trained phrase is checked only when its model is
    not sure of it (`TrainedSpotter.sure`)."""
    stop_word: bool = True
    """Hearing "stop" alone while the robot moves stops it, wake phrase or not."""
    stop_threshold: float = STOP_THRESHOLD
    awake: float = 5.0
    """Seconds the listener stays awake after the wake phrase or the last thing said."""
    confirm_seconds: float = 6.0
    """How long a read-back waits for "yes" or "no"; silence means no."""
    language: str = "en"
    """What the person speaks: the recogniser hears it in it, answers are said in it, and a
    read-back waits for its "yes" ("sí", "ja")."""


@dataclass
class _Awake:
    """A wake phrase heard: one audio session to the recogniser."""

    session: str
    stream: Stream
    seq: int = 0
    last_heard: float = field(default_factory=time.monotonic)
    """When the person last said something in it (monotonic)."""
    checked: asyncio.Future[bool] | None = None
    """Whether the wake phrase was confirmed (`_woken`); None when nothing checks it."""
    sure: asyncio.Future[bool] | None = None
    """Whether the trained spotter is sure of the phrase; None when its phrases are all
    checked, or it is pocketsphinx's."""
    begun: int = -1
    """The last utterance the recogniser has begun to hear (its partial transcripts)..."""
    answered: int = -1
    """...and the last one it has answered (a proposal)."""


Speak = Callable[[str], None]
"""Say a sentence aloud (blocking; the listener mutes its ear meanwhile)."""


def _wake_spotter(config: ListenConfig) -> Spotter | TrainedSpotter | None:
    """The wake phrase's spotter: a trained model's, pocketsphinx's, or none."""
    if config.wake_model:
        return TrainedSpotter(WakeModel.load(Path(config.wake_model)), config.wake_threshold)
    if config.wake:
        threshold = WAKE_THRESHOLD if config.wake_threshold is None else config.wake_threshold
        return Spotter([Phrase(config.wake, threshold)], WAKE_LOOP_PENALTY)
    return None


class Listener(Service):
    """`voicectl listen`: reads `read()` until it returns None (the end of a file), or until
    stopped; `interrupt()` makes a waiting `read()` return None."""

    def __init__(
        self,
        bus: Bus,
        config: ListenConfig,
        read: Callable[[], bytes | None],
        interrupt: Callable[[], None],
        speak: Speak | None = None,
    ) -> None:
        self._bus = bus
        self._config = config
        self._keys = RobotKeys(config.robot)
        self._read = read
        self._interrupt = interrupt
        self._speak = speak
        self._client = VoicectlClient(bus)
        self._asked = Asked(
            via=Via.VOICE, spoken=True, by=f"voicectl listen on {socket.gethostname()}"
        )
        self._check_decoder = json_decoder(SttReply)
        self._loop = asyncio.get_running_loop()
        # Two searches: the wake phrase's (pocketsphinx's is permissive, its false wakes
        # checked; a trained one is its own judge when sure, else checked too), and the stop
        # word's, strict (a stop is acted on at once, unchecked).
        wake = _wake_spotter(config)
        self._trained = wake if isinstance(wake, TrainedSpotter) else None
        self._unsure: _Awake | None = None
        """The session whose trained phrase the spotter may still become sure of (the
        reader's thread)."""
        self._wake_phrase = self._trained.phrase if self._trained is not None else config.wake
        # How far past the phrase's end its check hears: pocketsphinx's search reports the
        # phrase as it ends, and the check hears up to then; a trained one, at the pause.
        self._check_after = CHECK_AFTER if self._trained is not None else math.inf
        self._spotters: list[Spotter | TrainedSpotter] = [
            *([wake] if wake is not None else []),
            *(
                [Spotter([Phrase("stop", config.stop_threshold)], STOP_LOOP_PENALTY)]
                if config.stop_word
                else []
            ),
        ]
        self._answer: Spotter | None = None
        """Listens for "yes" or "no" while an order waits for confirmation."""
        self._answered: asyncio.Future[str] | None = None
        self._recent: deque[tuple[float, bytes]] = deque()
        """(stream time, audio) of the last seconds: the room before a wake phrase."""
        self._clock = 0.0
        self._last_wake = -PHRASE_SECONDS
        """Where the last wake phrase heard began (stream time)."""
        self._awake: _Awake | None = None
        self._sessions: dict[str, _Awake] = {}
        """The last sessions, the current one included, whose proposals are acted on."""
        self._muted_until = 0.0
        """Monotonic time until which the microphone is not heard (the robot speaks)."""
        self._moving = False
        self._stopped = False
        self._mine: set[str] = set()
        """The ids of the orders this listener submitted: their outcomes are said."""
        self._ends: list[Callable[[], None]] = []
        self._reader: threading.Thread | None = None
        self._finished: asyncio.Future[None] = self._loop.create_future()
        self._closing = False
        self._speaking: asyncio.Lock = asyncio.Lock()
        self._tasks: set[asyncio.Future[None]] = set()

    async def start(self) -> None:
        keys = self._keys
        self._ends += [
            self._bus.subscribe(keys.proposal, json_decoder(Proposal), self._on_proposal),
            self._bus.subscribe(keys.partial, json_decoder(PartialTranscript), self._on_partial),
            self._bus.subscribe(
                keys.state, json_decoder(StateUpdate), self._on_state, history=True
            ),
        ]
        if not self._wake_phrase:
            self._wake_now()
        self._reader = threading.Thread(target=self._read_all, name="listen", daemon=True)
        self._reader.start()
        _LOGGER.info(
            "listening for %s%s",
            repr(self._wake_phrase) if self._wake_phrase else "commands",
            " and 'stop'" if self._config.stop_word else "",
        )

    async def run(self) -> None:
        """Until the source ends (then the last session's answers are awaited), or forever;
        meanwhile a pause of `awake` seconds puts the listener back to sleep."""
        while not (self._finished.done() and self._awake is None):
            await asyncio.sleep(0.1)
            self._check_awake()
        # Every utterance the recogniser began to hear gets its answer, however late.
        deadline = self._loop.time() + ANSWER_WAIT
        while any(s.answered < s.begun for s in self._sessions.values()):
            if self._loop.time() > deadline:
                _LOGGER.warning("no answer from the recogniser in %g s: not waiting", ANSWER_WAIT)
                break
            await asyncio.sleep(0.1)
        while self._tasks:  # what the last proposal started: its answer, its submit
            await asyncio.gather(*self._tasks, return_exceptions=True)

    async def stop(self) -> None:
        self._closing = True
        self._interrupt()
        if self._reader is not None:
            await asyncio.to_thread(self._reader.join, 5.0)
        for end in self._ends:
            end()
        self._sleep()

    # --- on the reader's thread --------------------------------------------------------

    def _read_all(self) -> None:
        try:
            while not self._closing and (pcm := self._read()) is not None:
                self._hear(pcm)
        except Exception:  # the reader's end must reach the loop, whatever ended it
            _LOGGER.exception("the audio source failed")
        finally:
            if self._unsure is not None:  # no audio to grow surer on: the check decides
                self._loop.call_soon_threadsafe(self._settle, self._unsure, False)
            self._loop.call_soon_threadsafe(self._ended)

    def _ended(self) -> None:
        if not self._finished.done():
            self._finished.set_result(None)

    def _hear(self, pcm: bytes) -> None:
        start = self._clock
        self._clock += len(pcm) / BYTES_PER_SECOND
        muted = time.monotonic() < self._muted_until
        # While the robot speaks, and while it waits for a yes or no, the recogniser gets
        # the silence of a muted microphone: neither is a command.
        heard = bytes(len(pcm)) if muted or self._answer is not None else pcm
        for at in range(0, len(heard), FRAME_BYTES):  # by 20 ms frames: where a phrase ends
            self._recent.append((start + at / BYTES_PER_SECOND, heard[at : at + FRAME_BYTES]))
        while self._recent and self._recent[0][0] < self._clock - ROOM_BEFORE - 3.0:
            self._recent.popleft()
        awake = self._awake
        if awake is not None:
            self._send(awake, heard)
        if muted:  # the spotters' clocks run on with the stream's
            for spotter in self._spotters:
                spotter.skip(len(pcm))
            self._grow_sure()
            return
        if self._answer is not None:
            for hit in self._answer.accept(pcm):
                self._loop.call_soon_threadsafe(self._on_answer, hit.phrase)
        for spotter in self._spotters:
            for hit in spotter.accept(pcm):
                self._on_hit(hit)
        self._grow_sure()
        # Someone still speaking keeps the listener awake, however late the recogniser's
        # partial transcripts come on a busy host.
        awake = self._awake
        if awake is not None and self._spotters and self._spotters[0].last_loud >= start:
            awake.last_heard = time.monotonic()

    def _on_hit(self, hit: Spotted) -> None:
        if hit.phrase == "stop":
            if self._moving and not self._stopped and hit.alone:
                _LOGGER.info("heard 'stop' at %.2f s: stopping the robot", hit.end)
                self._loop.call_soon_threadsafe(self._stop_robot)
            return
        if self._awake is None:
            _LOGGER.info("heard the wake phrase at %.2f s", hit.end)
            # A search that fired early, on the phrase's first part, and was turned down
            # restarted inside the phrase: this hit's start is then late. The phrase began
            # no later than that first hit.
            if hit.start - self._last_wake < PHRASE_SECONDS:
                hit = Spotted(hit.phrase, self._last_wake, hit.end)
            self._last_wake = hit.start
            awake = self._wake_now()
            # The room before the phrase, then what was said after it: the phrase itself
            # is not for the recogniser, whose grammar does not know it.
            room = [f for at, f in self._recent if hit.start - ROOM_BEFORE <= at < hit.start]
            after = [f for at, f in self._recent if at >= hit.end]
            self._send(awake, b"".join([*room, *after]))
            # Streaming starts at once; what it becomes is submitted only once the trained
            # spotter is sure of the phrase, or the recogniser's neural ear agrees it was
            # said (`_woken`).
            if self._config.wake_check or self._trained is not None:
                phrase = [
                    f
                    for at, f in self._recent
                    if hit.start - CHECK_BEFORE <= at < hit.end + self._check_after
                ]
                doubtful = not self._config.wake_check
                self._unsure = awake if doubtful else None
                pcm = b"".join(phrase)
                self._loop.call_soon_threadsafe(self._check_wake, awake, pcm, doubtful)
        elif self._awake is not None:
            self._awake.last_heard = time.monotonic()

    def _grow_sure(self) -> None:
        """Tell the session whether the trained spotter became sure of its phrase, once it
        knows (`TrainedSpotter.sure`)."""
        if self._unsure is None or self._trained is None:
            return
        sure = self._trained.sure()
        if sure is not None:
            self._loop.call_soon_threadsafe(self._settle, self._unsure, sure)
            self._unsure = None

    def _wake_now(self) -> _Awake:
        session = uuid.uuid4().hex[:16]
        stream = self._bus.stream(self._keys.stt_audio(session))
        stream.send(AudioStart(language=self._config.language))
        awake = _Awake(session, stream)
        self._awake = awake
        self._sessions[session] = awake
        while len(self._sessions) > RECENT_SESSIONS:
            del self._sessions[next(iter(self._sessions))]
        return awake

    def _send(self, awake: _Awake, pcm: bytes) -> None:
        for at in range(0, len(pcm), 32000):  # at most one second per chunk
            awake.stream.send(AudioChunk(seq=awake.seq, pcm=pcm[at : at + 32000]))
            awake.seq += 1

    # --- on the event loop -------------------------------------------------------------

    def _check_wake(self, awake: _Awake, pcm: bytes, doubtful: bool) -> None:
        # Scheduled before `_settle` by the same thread: the future is there when it comes.
        if doubtful:
            awake.sure = self._loop.create_future()
        awake.checked = asyncio.ensure_future(self._woken(awake, pcm))
        awake.checked.add_done_callback(lambda checked: self._false_wake(awake, checked))

    def _settle(self, awake: _Awake, sure: bool) -> None:
        if awake.sure is not None and not awake.sure.done():
            awake.sure.set_result(sure)

    async def _woken(self, awake: _Awake, pcm: bytes) -> bool:
        """A phrase the trained spotter is sure of is taken (it becomes sure within
        `SURE_AFTER` seconds of audio: before the command after it is heard); any other is
        the recogniser's to confirm."""
        if awake.sure is not None and await awake.sure:
            _LOGGER.info("wake phrase sure: taken without the recogniser's check")
            return True
        return await self._heard_wake(pcm)

    def _false_wake(self, awake: _Awake, checked: asyncio.Future[bool]) -> None:
        """A wake the check turned down: back to sleep at once, the recogniser freed."""
        if not checked.cancelled() and not checked.result() and self._awake is awake:
            self._sleep()

    async def _heard_wake(self, pcm: bytes) -> bool:
        """Whether the recogniser's neural ear hears the wake phrase in `pcm` too: the
        spotter alone wakes about 25 times an hour on speech that never says it
        (docs/benchmarks.md). A recogniser without such an ear leaves it to the spotter."""
        request = CheckPhrase(
            pcm=pcm[-int(MAX_CHECK_SECONDS * 32000) :], phrase=self._wake_phrase, wait=CHECK_TIMEOUT
        )
        try:
            reply = await self._bus.request(
                self._keys.stt_check, request, self._check_decoder, CHECK_TIMEOUT
            )
        except BusError as exc:
            _LOGGER.warning("the wake phrase could not be checked (%s): the spotter decides", exc)
            return True
        match reply:
            case PhraseCheck(checked=False):
                return True
            case PhraseCheck(heard=heard, text=text, support=support):
                _LOGGER.info(
                    "wake phrase %s: the recogniser heard %r (%s)",
                    "confirmed" if heard else "not confirmed",
                    text,
                    "no support" if support is None else f"{support:+.2f}",
                )
                return heard
            case Failed(reason=reason):
                _LOGGER.warning("the wake phrase could not be checked (%s)", reason)
                return True
        return True

    def _check_awake(self) -> None:
        """Back to sleep after a pause of `awake` seconds (with a wake phrase), or at the
        end of the source (without one)."""
        awake = self._awake
        if awake is None or self._answered is not None:  # a read-back waits for its answer
            return
        quiet = time.monotonic() - awake.last_heard
        if quiet > self._config.awake and (self._wake_phrase or self._finished.done()):
            self._sleep()

    def _sleep(self) -> None:
        awake, self._awake = self._awake, None
        if awake is not None:
            awake.stream.send(AudioStop())
            awake.stream.close()
            _LOGGER.info("session %s ended", awake.session)

    def _on_partial(self, _key: str, partial: PartialTranscript) -> None:
        awake = self._sessions.get(partial.session)
        if awake is None:
            return
        awake.begun = max(awake.begun, partial.utterance)
        if awake is self._awake:
            awake.last_heard = time.monotonic()

    def _on_proposal(self, _key: str, proposal: Proposal) -> None:
        # A session just put to sleep may still have its last utterance's proposal coming.
        awake = self._sessions.get(proposal.session)
        if awake is None:
            return
        awake.last_heard = time.monotonic()
        awake.answered = max(awake.answered, proposal.utterance)
        self._keep(self._act_on(proposal, awake))

    async def _act_on(self, proposal: Proposal, awake: _Awake) -> None:
        if awake.checked is not None and not await awake.checked:
            _LOGGER.info("a false wake: %r not acted on", proposal.transcript)
            return
        language = self._config.language
        certain = proposal.orders and not (proposal.errors or proposal.doubts or proposal.rejected)
        # Heard by one ear without the evidence to send it alone (decide.py): its orders,
        # read back, are sent on a yes.
        confirm = (
            proposal.confirm
            and proposal.orders
            and not (proposal.errors or proposal.rejected)
            and all(not doubt.alternatives for doubt in proposal.doubts)
        )
        if confirm:
            proposal = msgspec.structs.replace(proposal, doubts=[])
        words = answers.proposal_words(proposal, language)
        if not (certain or confirm):
            await self.say(words)
            return
        plain = [order for order in proposal.orders if not is_edit(order)]
        if confirm or any(order.confirm for order in proposal.orders):
            if not await self._confirmed(words):
                await self.say(word(language, "answer.dropped"))
                return
        elif plain:  # an edit or a question is answered, not read back
            await self.say(answers.orders_words(plain, language))
        try:
            sent = await self._client.send(
                self._config.robot, proposal.orders, proposal.transcript, self._asked
            )
        except (Refused, Unreachable) as exc:
            _LOGGER.warning("not submitted: %s", exc)
            why = answers.short(exc.reason if isinstance(exc, Refused) else str(exc))
            await self.say(word(language, "answer.notSent", why=why))
            return
        self._mine.update(sent.order_ids)
        if sent.order_ids:
            _LOGGER.info("submitted %s: %s", ", ".join(sent.order_ids), proposal.transcript)
        for answered in sent.answers:
            await self.say(answered.answer)

    async def _confirmed(self, words: str) -> bool:
        """Read the orders back and wait for "yes" in the listener's language; "no", or
        nothing, is no."""
        language = self._config.language
        sounds = CONFIRM_SOUNDS.get(language)
        if sounds is None:
            await self.say(word(language, "answer.yesOrNo", words=words))
            _LOGGER.info("no spoken yes in %s: a read-back is not sent hands-free", language)
            return False
        self._answered = self._loop.create_future()
        await self.say(word(language, "answer.yesOrNo", words=words))
        self._answer = Spotter([Phrase(sound, CONFIRM_THRESHOLD) for sound in sounds])
        try:
            async with asyncio.timeout(self._config.confirm_seconds):
                answer = await self._answered
        except TimeoutError:
            answer = ""
        finally:
            self._answer = None
            self._answered = None
            if self._awake is not None:
                self._awake.last_heard = time.monotonic()
        _LOGGER.info("confirmation: %s", answer or "no answer")
        return answer == sounds[0]

    def _on_answer(self, word: str) -> None:
        if self._answered is not None and not self._answered.done():
            self._answered.set_result(word)

    def _on_state(self, _key: str, update: StateUpdate) -> None:
        state = update.state
        self._moving = state.current is not None
        if state.stopped and not self._stopped:  # stopped from elsewhere (the panel, the CLI)
            stopped = Stopped(confirmed=True, detail="")
            self._keep(self.say(answers.stopped_words(stopped, self._config.language)))
        self._stopped = state.stopped
        for record in state.history:
            if record.id in self._mine:
                self._mine.discard(record.id)
                self._said_outcome(record)

    def _said_outcome(self, record: OrderRecord) -> None:
        if record.status is OrderStatus.CANCELLED and self._stopped:
            return  # "stopped" says it
        if ended_by_edit(record):
            return  # the edit's answer said it
        words = answers.outcome_words(record, self._config.language)
        if words:
            self._keep(self.say(words))

    def _stop_robot(self) -> None:
        self._stopped = True
        self._keep(self._stop_now())

    async def _stop_now(self) -> None:
        try:
            stopped = await self._client.stop(self._config.robot)
        except BusError as exc:
            _LOGGER.error("'stop' heard, but nothing could be stopped: %s", exc)
            return
        _LOGGER.info("stopped (%s)", "confirmed" if stopped.confirmed else stopped.detail)
        await self.say(answers.stopped_words(stopped, self._config.language))

    def _keep(self, work: Coroutine[Any, Any, None]) -> None:
        """Run `work` on its own, holding it until done (the loop keeps weak references)."""
        task = asyncio.ensure_future(work)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def say(self, words: str) -> None:
        """Speak `words` if this listener has a voice, muting the ear meanwhile so that
        the robot never hears itself."""
        _LOGGER.info("answer: %s", words)
        speak = self._speak
        if speak is None or not words:
            return
        async with self._speaking:
            self._muted_until = float("inf")
            try:
                await asyncio.to_thread(speak, words)
            except Exception as exc:  # a voice that fails must not end the listener
                _LOGGER.warning("could not speak %r: %s", words, exc)
            else:
                _LOGGER.info("spoke: %s", words)
            finally:
                self._muted_until = time.monotonic() + ECHO_TAIL
