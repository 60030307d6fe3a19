"""The speech recogniser as a process on a real Zenoh router, with the real converter and
both ears (pocketsphinx and Moonshine) on generated speech: audio sessions in, partial and
final transcripts and proposals out."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import os
import shutil
import time
import wave
from collections.abc import AsyncIterator
from pathlib import Path

import msgspec
import pytest

from harness.client import Client
from harness.processes import Process
from harness.speech_set import in_babble
from harness.wait import async_wait_until
from voicectl.services.stt.audio import frames, read_wav
from voicectl.shared.bus import Bus, Stream, json_decoder
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.messages import (
    FRAME_BYTES,
    MAX_CHECK_SECONDS,
    AudioChunk,
    AudioStart,
    AudioStop,
    CheckPhrase,
    Failed,
    Grammar,
    OrderStatus,
    PartialTranscript,
    PhraseCheck,
    Proposal,
    SessionEnded,
    SttReply,
    SttStatus,
    Transcript,
)
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Pose2D, Ros2Codec, RosDistro

from .conftest import REPO, Processes, Speak, Stack
from .support import joined

ORDERS = REPO / "orders"
KEYS = RobotKeys("robot")
WAIT = 60.0
"""Generous: the machine is shared; every wait ends as soon as the data is there."""
CHUNK_FRAMES = 5
"""100 ms per chunk, as a browser batches its 20 ms frames."""

WAVE = """\
    wave:
      voice_alias: "wave your hand"
      label: "wave"
"""


class Listener:
    """The test's subscriptions to what the recogniser and the converter publish."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.partials: list[tuple[float, PartialTranscript]] = []
        self.finals: list[tuple[float, Transcript]] = []
        self.proposals: list[Proposal] = []
        self.statuses: list[SttStatus] = []
        bus.subscribe(KEYS.partial, json_decoder(PartialTranscript), self._partial)
        bus.subscribe(KEYS.transcript, json_decoder(Transcript), self._final)
        bus.subscribe(KEYS.proposal, json_decoder(Proposal), lambda _k, m: self.proposals.append(m))
        bus.subscribe(
            KEYS.stt_status,
            json_decoder(SttStatus),
            lambda _k, m: self.statuses.append(m),
            history=True,
        )

    def _partial(self, _key: str, message: PartialTranscript) -> None:
        self.partials.append((time.monotonic(), message))

    def _final(self, _key: str, message: Transcript) -> None:
        self.finals.append((time.monotonic(), message))

    async def ready(self) -> SttStatus:
        await async_wait_until(
            lambda: any(s.ready for s in self.statuses), WAIT, "the recogniser to have a grammar"
        )
        return next(s for s in reversed(self.statuses) if s.ready)

    async def final(self, session: str, count: int = 1) -> list[Transcript]:
        def mine() -> list[Transcript]:
            return [t for _, t in self.finals if t.session == session]

        await async_wait_until(lambda: len(mine()) >= count, WAIT, f"{count} final(s) of {session}")
        return mine()

    async def proposal(self, session: str) -> Proposal:
        await async_wait_until(
            lambda: any(p.session == session for p in self.proposals),
            WAIT,
            f"a proposal for {session}",
        )
        return next(p for p in self.proposals if p.session == session)


async def stream(bus: Bus, session: str, wav: Path, stop: bool = True) -> None:
    """Send a WAV file as one session, 100 ms per chunk, as fast as the bus takes it."""
    sender = bus.stream(KEYS.stt_audio(session))
    assert await sender.matched(WAIT), "the recogniser does not subscribe to audio"
    sender.send(AudioStart())
    chunks = _chunks(read_wav(wav))
    for seq, pcm in enumerate(chunks):
        sender.send(AudioChunk(seq=seq, pcm=pcm))
        await asyncio.sleep(0)
    if stop:
        sender.send(AudioStop())


def _chunks(pcm: bytes) -> list[bytes]:
    split = frames(pcm)
    return [b"".join(split[i : i + CHUNK_FRAMES]) for i in range(0, len(split), CHUNK_FRAMES)]


@contextlib.asynccontextmanager
async def scenario(
    router: str, processes: Processes, orders: Path = ORDERS, stt_args: tuple[str, ...] = ()
) -> AsyncIterator[Listener]:
    """A converter and a recogniser, and the test listening to what they say."""
    with joined(router) as bus:
        listener = Listener(bus)
        processes.start("voicectl.services.converter", "--connect", router, "--orders", str(orders))
        processes.start("voicectl.services.stt", "--connect", router, "--debug", *stt_args)
        await listener.ready()
        yield listener


async def test_speech_becomes_a_proposal_while_partials_grow(
    router: str, processes: Processes, speech: Speak
) -> None:
    wav = speech("turn left then reach the kitchen")

    async with scenario(router, processes) as listener:
        await stream(listener.bus, "s1", wav)
        [final] = await listener.final("s1")
        assert final.text == "turn left then reach the kitchen"
        assert not final.rejected, final.reason
        assert final.confidence is not None
        assert final.confidence > 0.5
        assert final.speech_start is not None
        assert 0.3 < final.speech_start < 0.7
        ended = next(at for at, t in listener.finals if t.session == "s1")
        before = [p.text for at, p in listener.partials if p.session == "s1" and at <= ended]
        assert len(set(before)) >= 2, before
        assert max(len(text.split()) for text in before) >= 3, before
        proposal = await listener.proposal("s1")
        assert [(o.order, o.case) for o in proposal.orders] == [
            ("rotation", "left"),
            ("goal", "kitchen"),
        ]
        assert not proposal.rejected
        assert proposal.errors == []


async def test_speech_sent_before_the_grammar_is_heard_once_it_comes(
    router: str, processes: Processes, speech: Speak
) -> None:
    """A session opened while the stack starts (the recogniser up, the converter not yet)
    is held, not refused: the CI run that found it lost a hands-free command this way."""
    wav = speech("turn right")
    with joined(router) as bus:
        listener = Listener(bus)
        stt = processes.start("voicectl.services.stt", "--connect", router, "--debug")
        await stream(bus, "early", wav, stop=False)
        await async_wait_until(
            lambda: "session early cannot be recognised yet" in processes.log(stt),
            WAIT,
            "the recogniser to hold the early audio",
        )
        processes.start("voicectl.services.converter", "--connect", router, "--orders", str(ORDERS))
        await listener.ready()
        bus.publish(KEYS.stt_audio("early"), AudioStop())
        [final] = await listener.final("early")
        assert final.text == "turn right"
        assert not final.rejected, final.reason
        assert [o.order for o in (await listener.proposal("early")).orders] == ["rotation"]


async def test_speech_that_is_not_a_command_is_rejected(
    router: str, processes: Processes, speech: Speak
) -> None:
    wav = speech("what is the weather like")

    async with scenario(router, processes) as listener:
        await stream(listener.bus, "chat", wav)
        await listener.final("chat")
        proposal = await listener.proposal("chat")  # rejected by the recogniser or the converter
        assert proposal.rejected
        assert proposal.orders == []
        assert "not a command" in proposal.errors[0].reason


async def test_commands_joined_by_and_with_silence_after_become_two_orders(
    router: str, processes: Processes, speech: Speak, tmp_path: Path
) -> None:
    """Moonshine hears "and" where the grammar knows only "then"; 1.5 s of digital silence
    after the command (a muted microphone) adds no word."""
    pcm = read_wav(speech("turn right and move forward one meter", "flite:slt"))
    wav = _wav(tmp_path / "and.wav", pcm + bytes(int(1.5 * 16000) * 2))

    async with scenario(router, processes) as listener:
        await stream(listener.bus, "and", wav)
        proposal = await listener.proposal("and")
        assert [o.description for o in proposal.orders] == ["turn right", "move forward 1 m"]
        assert not proposal.rejected, proposal.errors
        assert [h.ear for h in proposal.hearings][:2] == ["grammar", "moonshine"]
        assert proposal.decision
        [final] = await listener.final("and")
        assert final.transcription is not None
        assert not final.transcription.text.lower().rstrip(".").endswith("then")


async def test_a_non_command_in_babble_becomes_no_order(
    router: str, processes: Processes, speech: Speak, tmp_path: Path
) -> None:
    talkers = [
        read_wav(speech(text, voice))
        for text, voice in (
            ("the children are playing outside", "festival:kal_diphone"),
            ("we need more paper for the printer", "flite:rms"),
            ("it was a long and quiet afternoon", "flite:slt"),
            ("nobody answered the door", "flite:kal16"),
        )
    ]
    said = read_wav(speech("could you please pass me the salt", "flite:awb"))
    wav = _wav(tmp_path / "babble.wav", in_babble(said, talkers, snr=10.0))

    async with scenario(router, processes) as listener:
        await stream(listener.bus, "babble", wav)
        await async_wait_until(
            lambda: any(p.session == "babble" for p in listener.proposals), WAIT, "a proposal"
        )
        mine = [p for p in listener.proposals if p.session == "babble"]
        assert all(p.rejected and not p.orders for p in mine), mine


def _wav(path: Path, pcm: bytes) -> Path:
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(16000)
        out.writeframes(pcm)
    return path


async def test_two_sessions_at_once_keep_their_own_speech(
    router: str, processes: Processes, speech: Speak
) -> None:
    first = _chunks(read_wav(speech("turn left")))
    second = _chunks(read_wav(speech("reach the kitchen", "festival:kal_diphone")))

    async with scenario(router, processes) as listener:
        senders = [listener.bus.stream(KEYS.stt_audio(name)) for name in ("a", "b")]
        for sender in senders:
            assert await sender.matched(WAIT)
            sender.send(AudioStart())
        for seq in range(max(len(first), len(second))):  # interleaved, chunk by chunk
            for sender, chunks in zip(senders, (first, second), strict=True):
                if seq < len(chunks):
                    sender.send(AudioChunk(seq=seq, pcm=chunks[seq]))
            await asyncio.sleep(0.01)
        for sender in senders:
            sender.send(AudioStop())
        [a] = await listener.final("a")
        [b] = await listener.final("b")
        assert (a.text, b.text) == ("turn left", "reach the kitchen")
        assert not a.rejected
        assert not b.rejected


async def test_a_grammar_change_applies_without_a_restart(
    router: str, processes: Processes, speech: Speak, tmp_path: Path
) -> None:
    orders = tmp_path / "orders"
    shutil.copytree(ORDERS, orders)
    wav = speech("wave your hand")

    async with scenario(router, processes, orders=orders) as listener:
        before = await listener.ready()
        await stream(listener.bus, "old", wav)
        await listener.final("old")
        assert (await listener.proposal("old")).rejected
        demo = orders / "demo.yaml"
        temporary = demo.with_suffix(".tmp")
        temporary.write_text(demo.read_text() + WAVE)
        os.replace(temporary, demo)
        await async_wait_until(
            lambda: (
                listener.statuses[-1].ready
                and listener.statuses[-1].grammar_version != before.grammar_version
            ),
            WAIT,
            "the recogniser to switch grammars",
        )
        await stream(listener.bus, "new", wav)
        [new] = await listener.final("new")
        assert new.text == "wave your hand"
        assert not new.rejected, new.reason
        assert [o.order for o in (await listener.proposal("new")).orders] == ["wave"]


async def test_bad_input_is_logged_and_dropped_and_sessions_go_on(
    router: str, processes: Processes, speech: Speak
) -> None:
    wav = speech("turn right")

    async with scenario(router, processes) as listener:
        bus = listener.bus
        bus.session.put(KEYS.stt_audio("junk"), b"\xff\x00 not json")
        odd = base64.b64encode(b"\x00" * 700).decode()  # 700 bytes: not whole 20 ms frames
        bus.session.put(KEYS.stt_audio("junk"), f'{{"type":"audiochunk","seq":0,"pcm":"{odd}"}}')
        bus.publish(KEYS.stt_audio("nostart"), AudioChunk(seq=0, pcm=b"\x00" * 640))
        bus.publish(KEYS.stt_audio("nostart"), AudioStop())
        # An empty grammar, as a broken converter might publish it: the old one stays.
        bus.publish(ConverterKeys().grammar("en"), Grammar(jsgf="", version="empty"))
        await stream(bus, "good", wav)
        [final] = await listener.final("good")
        assert final.text == "turn right"
        assert not final.rejected
        assert listener.statuses[-1].ready
    log = processes.log(next(p for name, p, _ in processes.started if name == "stt"))
    # One line for the junk (the frames that are not whole are the next warning of the same
    # subscription within shared/throttle.py's interval: held back, not logged).
    assert log.count("dropped undecodable message on voice/robot/stt/audio/junk") == 1
    assert log.count("audio for session nostart, not started: dropped") == 1  # once
    assert "stop for session nostart, which was not started: ignored" in log
    assert "grammar empty not used: grammar empty: JSGF grammar has no public rule" in log


async def test_speech_that_goes_on_is_cut_at_the_maximum_utterance(
    router: str, processes: Processes, speech: Speak
) -> None:
    wav = speech(
        "turn left then reach the kitchen then move forward then turn right", "festival:kal_diphone"
    )

    async with scenario(router, processes, stt_args=("--max-utterance", "1.5")) as listener:
        await stream(listener.bus, "long", wav, stop=False)
        finals = await listener.final("long", count=2)  # before any stop was sent
        assert all(t.speech_end is not None for t in finals)
        first = finals[0]
        assert first.speech_start is not None
        assert first.speech_end is not None
        assert first.speech_end - first.speech_start < 2.0


async def _spoken_to_the_stack(stack: Stack, wav: Path, expected: list[str]) -> Pose2D:
    """Stream `wav` to the stack's recogniser as a microphone would, send what it proposes
    (as Send does: only a proposal without doubts), and return the simulated robot's pose
    once the orders have run."""
    pose: list[Pose2D] = []
    codec = Ros2Codec(RosDistro.JAZZY)
    with joined(stack.router) as bus:
        listener = Listener(bus)
        await listener.ready()
        await stream(bus, "mic", wav)
        proposal = await listener.proposal("mic")
        assert not proposal.rejected, proposal
        assert proposal.doubts == [], proposal
        assert [o.description for o in proposal.orders] == expected
        client = Client(bus, "robot")
        ids = await client.submit(*proposal.orders)
        finished = [await client.finished(i, timeout=WAIT) for i in ids]
        assert [r.status for r in finished] == [OrderStatus.SUCCEEDED] * len(ids)
        bus.subscribe(RobotNames().odom, codec.read_odometry, lambda _k, o: pose.append(o.pose))
        await async_wait_until(lambda: pose, 30.0, "odometry")
    return pose[-1]


@pytest.mark.e2e
async def test_speech_streamed_to_voicectl_up_moves_the_simulated_robot(
    stack: Stack, speech: Speak
) -> None:
    """Done-when of the speech issue: generated speech from the shipped orders, streamed to
    the stack's recogniser, becomes orders that the simulated robot carries out."""
    # Flite's slt, as the panel's speech test: the open decode hears Festival's kal diphone
    # voice say "them both to the future if", which is rightly too foreign to obey.
    wav = speech("please turn left then go to the kitchen", "flite:slt")
    pose = await _spoken_to_the_stack(stack, wav, ["turn left", "reach kitchen"])
    assert abs(pose.x - 3.0) < 0.1
    assert abs(pose.y - 5.0) < 0.1


@pytest.mark.e2e
async def test_a_person_saying_go_forward_ten_meters_moves_the_robot_ten_metres(
    stack: Stack, people: dict[str, Path]
) -> None:
    """Done-when of the hearing issue: a real recording of a man (pocketsphinx's own test
    clip), once heard as "two", now moves the simulated robot ten metres."""
    pose = await _spoken_to_the_stack(stack, people["real-goforward"], ["move forward 10 m"])
    assert abs(pose.x - 10.0) < 0.2, pose
    assert abs(pose.y) < 0.2, pose


async def test_memory_goes_back_when_the_sessions_close(
    router: str, processes: Processes, speech: Speak
) -> None:
    """Each open session holds a decoder of tens of megabytes; once they close, the
    recogniser gives that memory back instead of staying at its peak."""
    chunks = _chunks(read_wav(speech("turn left")))

    def rss_mb(pid: int) -> float:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS"):
                return int(line.split()[1]) / 1024
        raise AssertionError("no VmRSS")

    async with scenario(router, processes) as listener:
        (_, stt, _) = next(p for p in processes.started if p[0] == "stt")
        names = [f"m{n}" for n in range(4)]
        senders = [listener.bus.stream(KEYS.stt_audio(name)) for name in names]
        for sender in senders:
            assert await sender.matched(WAIT)
            sender.send(AudioStart())
        for seq, pcm in enumerate(chunks):
            for sender in senders:
                sender.send(AudioChunk(seq=seq, pcm=pcm))
            await asyncio.sleep(0.01)

        async def room() -> None:
            """The room's silence as time passes, as a microphone goes on sending it: a
            session that sends less than that is closed (a trickle), and under load the
            four decodes may take longer than that allows."""
            for seq in itertools.count(len(chunks)):
                await asyncio.sleep(0.1)
                for sender in senders:
                    sender.send(AudioChunk(seq=seq, pcm=bytes(3200)))

        murmur = asyncio.ensure_future(room())
        try:
            for name in names:
                await listener.final(name)
            peak = rss_mb(stt.pid)
        finally:
            murmur.cancel()
        for sender in senders:
            sender.send(AudioStop())
        await async_wait_until(
            lambda: (
                "session m3 ended" in processes.log(stt)
                and "session m0 ended" in processes.log(stt)
            ),
            WAIT,
            "the sessions to end",
        )
        await async_wait_until(
            lambda: rss_mb(stt.pid) < peak - 80, 10.0, f"RSS to fall from {peak:.0f} MB"
        )


CHECKED = json_decoder(SttReply)


def check_request(pcm: bytes, phrase: str, **fields: object) -> bytes:
    """A phrase check as JSON, built by hand: a client need not be voicectl's, and
    `CheckPhrase` itself refuses what the recogniser must refuse."""
    request = {"type": "checkphrase", "pcm": base64.b64encode(pcm).decode(), "phrase": phrase}
    return msgspec.json.encode({**request, **fields})


async def test_a_phrase_to_check_is_a_few_words(
    router: str, processes: Processes, speech: Speak
) -> None:
    """Issue 43: a check of "hey robot " * 800 took 7.9 CPU-seconds and 0.7 GB. A phrase
    is a few words: a longer one is refused at the edge, at once, and checks go on."""
    pcm = read_wav(speech("hey robot"))[: int(MAX_CHECK_SECONDS * 32000)]
    async with scenario(router, processes) as listener:
        bus = listener.bus
        for phrase in ("hey robot " * 40, "one two three four five six seven eight nine"):
            raw = await bus.request_bytes(KEYS.stt_check, check_request(pcm, phrase), WAIT)
            reply = CHECKED(raw)
            assert isinstance(reply, Failed), reply
            assert "undecodable request" in reply.reason
            assert "64" in reply.reason or "8 words" in reply.reason, reply.reason
        reply = await bus.request(KEYS.stt_check, CheckPhrase(pcm=pcm, phrase="hey robot"), CHECKED)
        assert isinstance(reply, PhraseCheck), reply
        assert reply.checked


async def test_phrase_checks_wait_in_a_short_queue_and_none_runs_for_nobody(
    router: str, processes: Processes, speech: Speak
) -> None:
    """Issue 43: 300 checks asked at once with a 5 s timeout kept the recogniser busy 12 s
    after every asker had gone. Checks now wait in a short queue, past which the asker
    hears at once that the recogniser is busy, and one whose asker would be gone by its
    turn is dropped, never run."""
    pcm = read_wav(speech("hey robot"))[: int(MAX_CHECK_SECONDS * 32000)]
    async with scenario(router, processes) as listener:
        bus = listener.bus

        async def ask(wait: float) -> object:
            request = CheckPhrase(pcm=pcm, phrase="hey robot", wait=wait)
            return await bus.request(KEYS.stt_check, request, CHECKED, WAIT)

        replies = await asyncio.gather(*(ask(5.0) for _ in range(20)))
        busy = [r for r in replies if isinstance(r, Failed) and "busy" in r.reason]
        checked = [r for r in replies if isinstance(r, PhraseCheck) and r.checked]
        assert busy, replies
        assert len(busy) + len(checked) == len(replies), replies
        # Askers that wait 10 ms: none can be answered in time, so none is checked.
        replies = await asyncio.gather(*(ask(0.01) for _ in range(5)))
        assert all(isinstance(r, Failed) and "not checked" in r.reason for r in replies), replies
        assert isinstance(await ask(5.0), PhraseCheck)  # and the next asker is answered


async def test_a_session_whose_sender_went_quiet_is_dropped_not_recognised(
    router: str, processes: Processes, speech: Speak
) -> None:
    """A session's sender gone (nothing for `--idle` seconds) in the middle of speech:
    what it said is dropped, not made into a transcript nobody waits for."""
    said = read_wav(speech("turn left then reach the kitchen then turn right"))
    async with scenario(router, processes, stt_args=("--idle", "2")) as listener:
        bus = listener.bus
        ended: list[SessionEnded] = []
        bus.subscribe(
            KEYS.stt_session("cut"), json_decoder(SessionEnded), lambda _k, m: ended.append(m)
        )
        sender = bus.stream(KEYS.stt_audio("cut"))
        assert await sender.matched(WAIT)
        sender.send(AudioStart())
        half = _chunks(said[: len(said) // 2])  # mid-sentence: the utterance is open
        for seq, pcm in enumerate(half):
            sender.send(AudioChunk(seq=seq, pcm=pcm))
        await async_wait_until(lambda: ended, WAIT, "the quiet session to be ended")
        assert "no audio for 2 s" in ended[0].reason
        # A session after it: its transcript comes after any of the first one's would.
        await stream(bus, "after", speech("turn right"))
        await listener.final("after")
        assert [t for _, t in listener.finals if t.session == "cut"] == []


async def test_trickling_sessions_are_closed_and_a_microphone_gets_in(
    router: str, processes: Processes
) -> None:
    """Issue 43: sessions sending a 20 ms chunk every 10 s were never idle long enough to
    be closed, and kept every microphone out ("busy"). A session that sends far less audio
    than time passes is closed, and told why; so is one open past the longest allowed."""
    limits = ("--max-sessions", "2", "--audio-window", "2", "--max-session", "4")
    async with scenario(router, processes, stt_args=limits) as listener:
        bus = listener.bus
        ended: dict[str, list[SessionEnded]] = {}

        def opened(name: str) -> Stream:
            ended[name] = []
            bus.subscribe(
                KEYS.stt_session(name),
                json_decoder(SessionEnded),
                lambda _k, m: ended[name].append(m),
            )
            sender = bus.stream(KEYS.stt_audio(name))
            sender.send(AudioStart())
            return sender

        async def send(sender: Stream, every: float) -> None:
            for seq in itertools.count():
                sender.send(AudioChunk(seq=seq, pcm=bytes(FRAME_BYTES * 5)))  # 100 ms
                await asyncio.sleep(every)

        assert await bus.stream(KEYS.stt_audio("probe")).matched(WAIT)
        tricklers = [asyncio.create_task(send(opened(n), 2.0)) for n in ("t1", "t2")]
        try:
            await async_wait_until(
                lambda: "session t2 started" in processes.log(stt_process(processes)),
                WAIT,
                "the tricklers' sessions",
            )
            opened("refused")
            await async_wait_until(lambda: ended["refused"], WAIT, "the third to be refused")
            assert ended["refused"][0].refused
            await async_wait_until(
                lambda: ended["t1"] and ended["t2"], WAIT, "the tricklers to be closed"
            )
            assert "of audio in 2 s" in ended["t1"][0].reason, ended["t1"]
            assert not ended["t1"][0].refused
        finally:
            for task in tricklers:
                task.cancel()
        talker = asyncio.create_task(send(opened("mic"), 0.1))  # as a microphone sends
        try:
            await async_wait_until(lambda: ended["mic"], WAIT, "the long session to be closed")
        finally:
            talker.cancel()
        assert "open for 4 s, the longest a session may be" in ended["mic"][0].reason


def stt_process(processes: Processes) -> Process:
    return next(p for name, p, _ in processes.started if name == "stt")


async def test_a_flood_of_bad_audio_messages_logs_a_line_per_kind(
    router: str, processes: Processes
) -> None:
    """Issue 43: every refused start, chunk out of order, chunk for no session and chunk
    dropped logged a line (200 chunks, 200 lines). Now each kind is said at most once
    every 10 s, as undecodable messages are (shared/throttle.py)."""
    async with scenario(router, processes, stt_args=("--max-sessions", "1")) as listener:
        bus = listener.bus
        good = bus.stream(KEYS.stt_audio("good"))
        assert await good.matched(WAIT)
        good.send(AudioStart())
        log = lambda: processes.log(stt_process(processes))  # noqa: E731
        await async_wait_until(lambda: "session good started" in log(), WAIT, "the session")
        second = bytes(FRAME_BYTES * 50)
        for n in range(50):
            bus.publish(KEYS.stt_audio(f"more{n}"), AudioStart())  # refused: one is open
            bus.publish(KEYS.stt_audio(f"none{n}"), AudioChunk(seq=0, pcm=bytes(FRAME_BYTES)))
            bus.publish(KEYS.stt_audio(f"none{n}"), AudioStop())
        for seq in range(0, 100, 2):  # every other chunk missing, and 50 s at once
            good.send(AudioChunk(seq=seq, pcm=second))
        good.send(AudioStop())
        await async_wait_until(lambda: "session good ended" in log(), WAIT, "the session's end")
    said = log()
    for line in (
        "refused: 1 sessions open already",
        "not started: dropped",
        "which was not started: ignored",
        "audio was lost or reordered",
        "falls behind",
    ):
        assert 1 <= said.count(line) <= 2, (line, said.count(line))
