"""Hands-free latency on the whole local stack: `voicectl listen -` fed at real time.

    .venv/bin/python -m bench.listen [--rounds 10]

Starts `voicectl up` (the simulator at real speed) and a listener with the wake phrase
"hey robot" and a voice (espeak-ng, into a WAV file), and feeds its standard input at
real-time pace as a microphone would: faint pink noise, and test-split voices saying
(harness/speech_set.py voices; Flite's slt and Festival's HTS voice, which the spotter
hears):

1. "hey robot": from the end of the phrase to the listener opening its audio session
   (its log line "heard the wake phrase"). Target 300 ms p95.
2. "stop" alone while a drive runs: from the end of the word to the first zero velocity
   on the robot's cmd_vel. Target 300 ms p95.
3. "hey robot, turn left": from the end of the command to the listener starting its
   answer ("answer: ..." in its log), plus the time espeak-ng takes to make the answer,
   measured here on the same words. Target 1 s p95.

Beside them, as the baseline measured in the same run: the same STOP sent with `voicectl
stop`'s client at the moment the word ends (no ear in the way).
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

from harness.measure import Robot, line
from harness.processes import REPO
from harness.speech_set import Voice, pink_noise, speak
from harness.stack import stack_up
from voicectl.services.stt.audio import read_wav
from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.client import VoicectlClient
from voicectl.shared.config import cache_dir
from voicectl.shared.messages import GetState, Release, StateReply
from voicectl.shared.tts import load_voice

VOICES = [Voice("flite", "slt"), Voice("festival", "cmu_us_slt_arctic_hts")]
CHUNK = 640


class Feeder:
    """Standard input of the listener at real time; `say` returns the wall time at which
    the speech in the file ended (its last spoken sample written)."""

    def __init__(self, process: subprocess.Popen[bytes]) -> None:
        self._process = process
        self._queue: queue.SimpleQueue[tuple[bytes, float, threading.Event, list[float]]] = (
            queue.SimpleQueue()
        )
        self._room = pink_noise(16000 * 30, 60.0, seed=9).astype("<i2").tobytes()
        threading.Thread(target=self._run, daemon=True).start()

    def say(self, path: Path, speech_end: float) -> float:
        done, ended = threading.Event(), [0.0]
        self._queue.put((read_wav(path), speech_end, done, ended))
        done.wait(60)
        return ended[0]

    def _run(self) -> None:
        assert self._process.stdin is not None
        started, sent, room = time.monotonic(), 0, 0
        while self._process.poll() is None:
            try:
                pcm, end, done, ended = self._queue.get_nowait()
            except queue.Empty:
                pcm, end, done, ended = self._room[room : room + 3200], -1.0, None, []
                room = (room + 3200) % (len(self._room) - 3200)
            for at in range(0, len(pcm), CHUNK):
                self._process.stdin.write(pcm[at : at + CHUNK])
                self._process.stdin.flush()
                sent += CHUNK
                if end >= 0 and not ended[0] and at + CHUNK >= end * 32000:
                    ended[0] = time.time()
                ahead = started + sent / 32000 - time.monotonic()
                if ahead > 0:
                    time.sleep(ahead)
            if done is not None:
                done.set()


def logged_after(lines: list[str], text: str, after: float, timeout: float = 10.0) -> float | None:
    """The wall time of the first log line holding `text` logged after `after`."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for entry in list(lines):
            if text in entry:
                stamp = datetime.datetime.strptime(entry[:23], "%Y-%m-%d %H:%M:%S,%f")
                at = stamp.timestamp()
                if at > after:
                    return at
        time.sleep(0.01)
    return None


def start_listener(router: str, said: Path, lines: list[str]) -> subprocess.Popen[bytes]:
    """The listener, its log lines gathered into `lines` as they come."""
    listener = subprocess.Popen(
        [
            *(sys.executable, "-m", "voicectl", "listen", "-", "--connect", router),
            *("--wake", "hey robot", "--awake", "1.5", "--speak", "--speaker", str(said)),
        ],
        stdin=subprocess.PIPE,
        stderr=subprocess.PIPE,
        cwd=REPO,
    )

    def read() -> None:
        assert listener.stderr is not None
        for raw in listener.stderr:
            lines.append(raw.decode(errors="replace").rstrip())

    threading.Thread(target=read, daemon=True).start()
    return listener


async def main_async(
    args: argparse.Namespace, router: str, listener: subprocess.Popen[bytes], lines: list[str]
) -> None:
    directory = cache_dir() / "bench-listen"
    phrase = [speak("hey robot", voice, directory) for voice in VOICES]
    stop = [speak("stop", voice, directory) for voice in VOICES]
    command = [speak("hey robot, turn left", voice, directory) for voice in VOICES]
    feeder = Feeder(listener)
    wake: list[float] = []
    stops: list[float] = []
    direct: list[float] = []
    answers: list[float] = []
    missed = {"wake": 0, "stop": 0, "answer": 0}
    with Bus.open(BusOptions(connect=[router]), asyncio.get_running_loop()) as bus:
        client = VoicectlClient(bus)
        robot = Robot()
        robot.listen(bus)
        await asyncio.to_thread(logged_after, lines, "listening for", 0.0, 60.0)
        for round_ in range(args.rounds):
            n = round_ % len(VOICES)
            ended = await asyncio.to_thread(
                feeder.say, directory / phrase[n].file, phrase[n].speech_end
            )
            heard = await asyncio.to_thread(logged_after, lines, "heard the wake phrase", ended - 1)
            if heard is None:
                missed["wake"] += 1
            else:
                wake.append(heard - ended)
            await asyncio.to_thread(logged_after, lines, "ended", ended, 10.0)

            ended = await asyncio.to_thread(
                feeder.say, directory / command[n].file, command[n].speech_end
            )
            answered = await asyncio.to_thread(logged_after, lines, "answer: turn left", ended)
            if answered is None:
                missed["answer"] += 1
            else:
                answers.append(answered - ended)
            await asyncio.to_thread(logged_after, lines, "ended", ended, 10.0)

            for spoken in (True, False):
                parsed = await client.parse("move forward ten meters")
                await client.submit("robot", parsed.orders, "bench")
                await until_running(client)
                await asyncio.sleep(0.5)
                if spoken:
                    ended = await asyncio.to_thread(
                        feeder.say, directory / stop[n].file, stop[n].speech_end
                    )
                    mono = time.monotonic() - (time.time() - ended)
                else:
                    mono = time.monotonic()
                    await client.stop("robot")
                zero = await Robot.first(robot.zero, mono, 5.0)
                if zero is None:
                    missed["stop"] += spoken
                    await client.stop("robot")
                else:
                    (stops if spoken else direct).append(zero - mono)
                await client.ask("robot", Release())
        synth = load_voice("espeak-ng")
        made = []
        for _ in range(20):
            started = time.perf_counter()
            synth.speak("turn left")
            made.append(time.perf_counter() - started)
    print(line("wake phrase end -> listening", wake, "<= 300 ms p95"))
    print(line("spoken 'stop' end -> zero velocity", stops, "<= 300 ms p95"))
    print(line("baseline: client STOP -> zero velocity", direct))
    print(line("command end -> answer begins", answers))
    print(line("espeak-ng makes 'turn left'", made))
    print(f"not heard: {missed} of {args.rounds} rounds each")
    if args.log:
        print("\n".join(lines))


async def until_running(client: VoicectlClient, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        reply = await client.ask("robot", GetState())
        if isinstance(reply, StateReply) and reply.state.current is not None:
            return
        await asyncio.sleep(0.02)
    raise SystemExit("the drive did not start")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=10)
    parser.add_argument("--log", action="store_true", help="print the listener's log")
    args = parser.parse_args()
    said = cache_dir() / "bench-listen" / "answers.wav"  # the listener's voice: a file
    said.unlink(missing_ok=True)
    with stack_up("voicectl-bench-listen-") as (_, stack_lines, _, _, router):
        lines: list[str] = []
        listener = start_listener(router, said, lines)
        try:
            asyncio.run(main_async(args, router, listener, lines))
        finally:
            listener.terminate()
            listener.wait(10)
            if args.log:
                print("\n".join(x for x in stack_lines if "utterance" in x or "->" in x))


if __name__ == "__main__":
    main()
