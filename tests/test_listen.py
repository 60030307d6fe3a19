"""`voicectl listen` against the whole stack: a file, and standard input fed at real time as
a microphone would be, become orders the simulator carries out; the wake phrase gates
commands; "stop" alone stops a moving robot without it; a read-back answered "no", or not
at all, moves nothing."""

from __future__ import annotations

import asyncio
import json
import os
import queue
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
import wave
from pathlib import Path

import numpy as np
import pytest

from harness.ports import free_port
from harness.pulse import PulseAudio
from harness.pulse import unavailable as pulse_unavailable
from harness.speech_set import pink_noise
from harness.wait import async_wait_until, wait_until
from voicectl.services.listen.listener import ECHO_TAIL
from voicectl.services.stt.audio import read_wav
from voicectl.shared.bus import Bus
from voicectl.shared.client import VoicectlClient
from voicectl.shared.keys import RobotKeys, last_chunk
from voicectl.shared.messages import (
    GetState,
    OrderStatus,
    PartialTranscript,
    Proposal,
    Release,
    State,
    StateReply,
)

from .conftest import REPO, Speak, Stack
from .support import joined, on_bus
from .test_docs import block_after
from .test_hints import BARE_PATH
from .test_panel_browser import silent_wav

pytestmark = pytest.mark.e2e

VOICE = "flite:rms"
"""A voice the spotter and both ears hear well (bench/wake.py has them all)."""
HELD_OUT = "flite:slt"
"""A voice of bench/wake.py's test split: the shipped wake model never heard it."""
CHUNK = 3200
"""100 ms of 16 kHz 16-bit audio: what the feeder writes at a time."""


class Mouth:
    """`voicectl listen -` with a room that is never silent: faint pink noise at real
    time, and whatever `say` queues in its place."""

    def __init__(self, stack: Stack, *args: str) -> None:
        self.lines: list[str] = []
        self._said: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self._room = pink_noise(16000 * 60, 60.0, seed=5)
        self._process = subprocess.Popen(
            [sys.executable, "-m", "voicectl", "listen", "-", "--connect", stack.router, *args],
            stdin=subprocess.PIPE,
            stderr=subprocess.PIPE,
            cwd=REPO,
            env=stack.env,
        )
        self._closing = threading.Event()
        self._threads = [
            threading.Thread(target=self._feed, daemon=True),
            threading.Thread(target=self._read, daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def say(self, wav: Path) -> None:
        self._said.put(read_wav(wav))

    def heard(self, text: str) -> int:
        """How many log lines so far contain `text`."""
        return sum(text in line for line in list(self.lines))

    def close(self) -> int:
        self._closing.set()
        self._threads[0].join(timeout=5)
        try:
            code = self._process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self._process.kill()
            code = self._process.wait()
        self._threads[1].join(timeout=5)
        if self._process.stderr is not None:
            self._process.stderr.close()
        return code

    def _feed(self) -> None:
        assert self._process.stdin is not None
        started, sent, at = time.monotonic(), 0, 0
        pending = b""
        try:
            while not self._closing.is_set():
                if not pending:
                    try:
                        pending = self._said.get_nowait()
                    except queue.Empty:
                        room = self._room[at : at + CHUNK // 2]
                        at = (at + CHUNK // 2) % (len(self._room) - CHUNK)
                        pending = room.astype("<i2").tobytes()
                piece, pending = pending[:CHUNK], pending[CHUNK:]
                self._process.stdin.write(piece)
                self._process.stdin.flush()
                sent += len(piece)
                ahead = started + sent / 32000 - time.monotonic()
                if ahead > 0:
                    time.sleep(ahead)
        except (BrokenPipeError, ValueError):
            return
        self._process.stdin.close()

    def _read(self) -> None:
        assert self._process.stderr is not None
        for raw in self._process.stderr:
            line = raw.decode(errors="replace").rstrip()
            self.lines.append(line)
            print("listen:", line)


def state(stack: Stack) -> State:
    async def ask(bus: Bus) -> State:
        reply = await VoicectlClient(bus).ask("robot", GetState())
        assert isinstance(reply, StateReply)
        return reply.state

    return on_bus(stack.router, ask)


def descriptions(known: State) -> list[tuple[str, OrderStatus]]:
    records = [*known.history, *known.queue] + ([known.current] if known.current else [])
    return [(record.order.description, record.status) for record in records]


def test_a_file_becomes_orders_the_simulator_carries_out(
    photo_at_once_stack: Stack, tmp_path: Path
) -> None:
    """docs/listen.md's example, run line by line (its /tmp files in the test's own)."""
    stack = photo_at_once_stack
    block = block_after(REPO / "docs" / "listen.md", "heard through the whole stack", "sh")
    for command in block.strip().splitlines():
        argv = shlex.split(command.replace("/tmp/", f"{tmp_path}/"))
        if argv[0] == ".venv/bin/voicectl":
            argv = [sys.executable, "-m", "voicectl", *argv[1:], "--connect", stack.router]
        done = subprocess.run(argv, capture_output=True, text=True, cwd=REPO, env=stack.env)
        assert done.returncode == 0, (command, done.stderr)
    wait_until(
        lambda: ("take picture", OrderStatus.SUCCEEDED) in descriptions(state(stack)),
        60.0,
        "the spoken orders to run",
    )
    assert descriptions(state(stack)) == [  # history: the latest first
        ("take picture", OrderStatus.SUCCEEDED),
        ("turn left", OrderStatus.SUCCEEDED),
    ]


async def test_the_end_of_a_file_waits_for_the_answer_to_what_was_said_last(
    router: str, tmp_path: Path
) -> None:
    """A recogniser that answers after the listener went back to sleep (a loaded host's,
    seconds after the audio ended) is still heard: the file's end waits for the answer to
    every utterance the recogniser began to hear. The recogniser is a stand-in at the bus
    seam, with the converter's answer: a partial transcript while the file plays, the
    proposal only once the listener has put its session to sleep."""
    quiet = silent_wav(tmp_path / "quiet.wav", 1.0)
    listener = await asyncio.create_subprocess_exec(
        *[sys.executable, "-m", "voicectl", "listen", str(quiet), "--awake", "0.2"],
        *["--no-stop-word", "--connect", router],
        stderr=asyncio.subprocess.PIPE,
        cwd=REPO,
    )
    said: list[str] = []

    async def read() -> None:
        assert listener.stderr is not None
        async for line in listener.stderr:
            said.append(line.decode().rstrip())

    reading = asyncio.ensure_future(read())
    keys = RobotKeys("robot")
    try:
        with joined(router) as bus:
            sessions: list[str] = []

            def streamed(key: str, _audio: bytes) -> None:
                sessions.append(last_chunk(key))

            bus.subscribe(keys.stt_audio_any, bytes, streamed)
            await async_wait_until(lambda: sessions, 30.0, "the listener's audio session")
            session = sessions[0]
            bus.publish(keys.partial, PartialTranscript(session=session, utterance=0, text="turn"))
            await async_wait_until(
                lambda: any(f"session {session} ended" in line for line in said),
                30.0,
                "the listener to put its session to sleep",
            )
            bus.publish(
                keys.proposal,
                Proposal(transcript="turn left", session=session, utterance=0, rejected=True),
            )
            async with asyncio.timeout(60):
                code = await listener.wait()
    finally:
        if listener.returncode is None:
            listener.kill()
            await listener.wait()
        await reading
    assert code == 0, said
    assert any("answer: " in line for line in said), said


def copy_checkout(to: Path) -> None:
    """The checkout's files as a clone has them (tracked, and new ones not ignored; none of
    its .venv), symbolic links kept as links."""
    listed = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        capture_output=True,
        cwd=REPO,
        check=True,
    ).stdout.decode()
    for name in filter(None, listed.split("\0")):
        source = REPO / name
        if not source.is_symlink() and not source.exists():
            continue  # deleted, not yet committed
        (to / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source, to / name, follow_symlinks=False)


@pytest.mark.install
@pytest.mark.timeout(900)
def test_the_docs_examples_run_as_written_right_after_scripts_up(tmp_path: Path) -> None:
    """docs/listen.md's examples in a clone that `scripts/up` itself installed (its .venv,
    nothing on PATH), against the stack `scripts/up` starts: the device listing, then the
    spoken file, whose orders `voicectl history` lists. The stack is on ports of the
    test's own, which the examples reach through ZENOH_CONNECT; their /tmp files are the
    test's own."""
    clone = tmp_path / "clone"
    copy_checkout(clone)
    env = {
        **{k: v for k, v in os.environ.items() if k not in ("VOICECTL_VENV", "VIRTUAL_ENV")},
        "PATH": BARE_PATH,
        "VOICECTL_DATA": str(tmp_path / "data"),
        "PYTHONUNBUFFERED": "1",
    }
    # scripts/up's own steps: the Debian packages, the virtualenv; `up --help` then ends it.
    installed = subprocess.run(
        ["scripts/up", "--help"], cwd=clone, env=env, capture_output=True, text=True, timeout=840
    )
    assert installed.returncode == 0, installed.stdout + installed.stderr
    router = f"tcp/127.0.0.1:{free_port()}"
    up = subprocess.Popen(
        ["scripts/up", "--router", router, "--port", str(free_port()), "--time-scale", "10"],
        cwd=clone,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    said: list[str] = []
    reader = threading.Thread(target=lambda: said.extend(up.stdout or []), daemon=True)
    reader.start()
    examples = {**env, "ZENOH_CONNECT": router}

    def run(command: str) -> subprocess.CompletedProcess[str]:
        command = command.replace("/tmp/", f"{tmp_path}/")
        done = subprocess.run(
            ["bash", "-c", command], cwd=clone, env=examples, capture_output=True, text=True
        )
        print(f"$ {command}", done.stderr, sep="\n")
        assert done.returncode == 0, (command, done.stdout, done.stderr)
        return done

    def history() -> list[tuple[str, str]]:
        page = json.loads(run(".venv/bin/voicectl history").stdout)
        return [(record["order"]["description"], record["status"]) for record in page["records"]]

    try:
        wait_until(
            lambda: any("voicectl up: ready" in line for line in said) or up.poll() is not None,
            180.0,
            "the stack scripts/up starts",
        )
        assert up.poll() is None, "".join(said)
        doc = REPO / "docs" / "listen.md"
        listing = block_after(doc, "# Hands-free", "sh").strip()
        assert listing == ".venv/bin/voicectl listen --list-devices"
        run(listing)
        for command in block_after(doc, "heard through the whole stack", "sh").strip().splitlines():
            run(command)
        wait_until(
            lambda: ("take picture", "succeeded") in history(), 60.0, "the spoken orders to run"
        )
        assert history() == [("take picture", "succeeded"), ("turn left", "succeeded")]
    finally:
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGINT)
            try:
                up.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(up.pid, signal.SIGKILL)
                up.wait()
        reader.join(timeout=5)
        if up.stdout is not None:
            up.stdout.close()
        print("".join(said))


def test_the_wake_phrase_gates_commands_and_stop_needs_none(stack: Stack, speech: Speak) -> None:
    mouth = Mouth(stack, "--wake", "hey robot", "--awake", "3")
    try:
        wait_until(lambda: mouth.heard("listening for 'hey robot'"), 30.0, "the listener")
        mouth.say(speech("go to the kitchen", VOICE))  # no wake phrase: not for the robot
        mouth.say(speech("hey robot, turn left", VOICE))
        wait_until(
            lambda: ("turn left", OrderStatus.SUCCEEDED) in descriptions(state(stack)),
            60.0,
            "the command after the wake phrase to run",
        )
        assert mouth.heard("heard the wake phrase") == 1
        assert not [d for d, _ in descriptions(state(stack)) if "kitchen" in d]

        async def drive(bus: Bus) -> list[str]:
            # Back and forth, inside the map whichever way the robot faces: long enough
            # to be under way when "stop" is heard on a busy machine (a goal off the map
            # failed, ending the drive before the stop was said).
            client = VoicectlClient(bus)
            legs = ["move forward nine meters", "move back nine meters"] * 4
            parsed = await client.parse(" then ".join(legs))
            assert len(parsed.orders) == len(legs), parsed
            return await client.submit("robot", parsed.orders, "a long drive")

        on_bus(stack.router, drive)
        wait_until(lambda: state(stack).current is not None, 30.0, "the drive to start")
        mouth.say(speech("stop", VOICE))  # no wake phrase

        def settled() -> bool:
            """Stopped, and nothing running or queued. (The state never says stopped
            beside a running order: tests/test_supervisor.py.)"""
            known = state(stack)
            return known.stopped and known.current is None and not known.queue

        wait_until(settled, 30.0, "the spoken stop")
        assert mouth.heard("heard 'stop'") == 1

        async def release(bus: Bus) -> None:
            await VoicectlClient(bus).ask("robot", Release())

        on_bus(stack.router, release)
    finally:
        assert mouth.close() == 0


def test_a_trained_wake_phrase_puts_the_command_after_it_in_the_queue(
    stack: Stack, speech: Speak, tmp_path: Path
) -> None:
    """`voicectl listen --wake MODEL FILE`, with the shipped model and a voice it was
    neither trained nor tuned on: a command without the phrase is not taken; one after
    "hey rover" and a pause, which wakes the spotter without making it sure, is not either,
    the recogniser's check having turned the phrase down (said in one breath with a
    command, "hey rover" makes the spotter sure: docs/listen.md); the one said after the
    phrase in the same breath is."""
    model = REPO / "services" / "listen" / "hey_robot.npz"
    said = tmp_path / "said.wav"
    with wave.open(str(said), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(16000)
        out.writeframes(read_wav(speech("go to the kitchen", HELD_OUT)))
        out.writeframes(read_wav(speech("hey rover", HELD_OUT)))
        out.writeframes(read_wav(speech("take a picture", HELD_OUT)))
        out.writeframes(bytes(32000 * 3))  # the listener falls asleep again
        out.writeframes(read_wav(speech("hey robot, turn left", HELD_OUT)))
    listen = [sys.executable, "-m", "voicectl", "listen", str(said), "--wake", str(model)]
    done = subprocess.run(
        [*listen, "--awake", "2", "--connect", stack.router],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=stack.env,
    )
    print(done.stderr)
    assert done.returncode == 0
    wait_until(
        lambda: ("turn left", OrderStatus.SUCCEEDED) in descriptions(state(stack)),
        60.0,
        "the command after the trained wake phrase to run",
    )
    assert done.stderr.count("heard the wake phrase") == 2
    assert done.stderr.count("wake phrase not confirmed") == 1
    assert done.stderr.count("wake phrase sure") == 1
    assert not [d for d, _ in descriptions(state(stack)) if "kitchen" in d or "picture" in d]


def test_a_read_back_answered_no_or_not_at_all_moves_nothing(stack: Stack, speech: Speak) -> None:
    """demo.yaml asks before going to the dumpster: "no" and silence move nothing, "yes"
    (the check that the test can fail) sends it."""
    mouth = Mouth(stack, "--wake", "hey robot", "--awake", "2")
    command = speech("hey robot, go to the dumpster", VOICE)
    try:
        wait_until(lambda: mouth.heard("listening for 'hey robot'"), 30.0, "the listener")
        for answer, logged in (("no", "confirmation: no"), (None, "no answer"), ("yes", ": yes")):
            asked = mouth.heard("Yes or no?")
            mouth.say(command)
            wait_until(lambda n=asked: mouth.heard("Yes or no?") > n, 30.0, "the read-back")
            if answer is not None:
                mouth.say(speech(answer, VOICE))
            wait_until(lambda text=logged: mouth.heard(text), 30.0, f"the answer {answer!r}")
            # Asleep again, for the next wake phrase: every session a wake phrase opened
            # has ended (a slow read-back can come after its session ended).
            wait_until(
                lambda: mouth.heard(" ended") >= mouth.heard("heard the wake phrase"),
                30.0,
                "the listener to sleep",
            )
        wait_until(
            lambda: [d for d, _ in descriptions(state(stack)) if "dumpster" in d],
            30.0,
            "the order said yes to",
        )
        assert [d for d, _ in descriptions(state(stack)) if "dumpster" in d] == ["reach dumpster"]
    finally:
        assert mouth.close() == 0


needs_device = pytest.mark.skipif(
    pulse_unavailable() is not None and not os.environ.get("CI"), reason=f"{pulse_unavailable()}"
)


@needs_device
def test_through_a_sound_device_the_robot_never_hears_its_own_voice(
    stack: Stack, speech: Speak
) -> None:
    """A real device path: a private PulseAudio's null sink, whose monitor is the
    listener's microphone and into which it speaks its answers. The answer "turn left" is
    played back into the microphone; muted while it speaks, the listener does not take its
    own words for a second order."""
    with PulseAudio() as pulse:
        env = {**stack.env, **pulse.env}
        listen = subprocess.Popen(
            [
                *(sys.executable, "-m", "voicectl", "listen", "mic", "--connect", stack.router),
                *("--speak", "--speaker", "speaker", "--awake", "3"),
            ],
            stderr=subprocess.PIPE,
            text=True,
            cwd=REPO,
            env=env,
        )
        lines: list[str] = []

        def read() -> None:
            assert listen.stderr is not None
            for line in listen.stderr:
                lines.append(line.rstrip())
                print("listen:", line.rstrip())

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        try:
            wait_until(lambda: any("listening for commands" in x for x in lines), 30, "listen")
            pulse.play(speech("turn left", VOICE))
            with pulse.recording() as recording:  # from here on, only the robot speaks
                wait_until(
                    lambda: spoke(lines) >= 2, 60.0, "the order and its outcome to be spoken"
                )
                time.sleep(ECHO_TAIL + 0.2)  # a timer of the listener, not a peer to wait for
                heard = recording.pcm
            # The answers did reach the microphone's path.
            assert loudest(heard) > 1000
            pulse.play(speech("turn right", VOICE))
            wait_until(
                lambda: ("turn right", OrderStatus.SUCCEEDED) in descriptions(state(stack)),
                60.0,
                "the second command to run",
            )
            # Whatever the microphone heard of the robot's voice came before "turn right".
            assert descriptions(state(stack)) == [
                ("turn right", OrderStatus.SUCCEEDED),
                ("turn left", OrderStatus.SUCCEEDED),
            ]
        finally:
            listen.send_signal(signal.SIGINT)
            assert listen.wait(timeout=30) == 0, "\n".join(lines)
            reader.join(timeout=5)
            if listen.stderr is not None:
                listen.stderr.close()


def spoke(lines: list[str]) -> int:
    return sum("spoke:" in line for line in lines)


def loudest(pcm: bytes) -> float:
    samples = np.frombuffer(pcm[: len(pcm) // 2 * 2], dtype="<i2").astype(np.float32)
    return float(np.abs(samples).max()) if len(samples) else 0.0


SPANISH = REPO / "tests" / "data" / "gira-a-la-izquierda-kokoro-em_santa.wav"
"""Kokoro's Spanish em_santa: "gira a la izquierda y luego ve a la cocina"
(tests/test_panel_languages.py says how it was made)."""


def test_spanish_heard_by_one_ear_is_read_back_and_sent_on_si(stack: Stack, speech: Speak) -> None:
    """--language es: Whisper alone hears it, so its orders are read back in Spanish; "no"
    sends nothing, "sí" (the check that the test can fail) sends them."""
    mouth = Mouth(stack, "--language", "es", "--awake", "2")
    try:
        wait_until(lambda: mouth.heard("listening"), 30.0, "the listener")
        for answer, logged in (("no", "confirmation: no"), ("sí", "confirmation: si")):
            asked = mouth.heard("¿Sí o no?")
            mouth.say(SPANISH)
            wait_until(lambda n=asked: mouth.heard("¿Sí o no?") > n, 60.0, "the read-back")
            mouth.say(speech(answer, "espeak:es", 150))
            wait_until(lambda text=logged: mouth.heard(text), 30.0, f"the answer {answer!r}")
            if answer == "no":
                assert not descriptions(state(stack))
        assert mouth.heard("answer: gira a la izquierda, luego ve a la cocina. ¿Sí o no?") == 2
        wait_until(
            lambda: ("ve a la cocina", OrderStatus.SUCCEEDED) in descriptions(state(stack)),
            60.0,
            "the orders said sí to",
        )
        assert [d for d, _ in descriptions(state(stack))] == [
            "ve a la cocina",
            "gira a la izquierda",
        ]
    finally:
        assert mouth.close() == 0
