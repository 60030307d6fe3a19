"""From a voice to motion, on the whole local stack, through the paths the panel uses.

    .venv/bin/python -m bench.e2e [--utterances 200] [--clients 20] [--requests 50] [--quick]

Starts `voicectl up` (the simulator at real speed, a data directory of its own, free
ports) and measures what a person waits for:

1. **Speech**: spoken commands (Flite and espeak-ng voices, made with harness/speech_set.py)
   streamed at real-time pace over the panel's /api/audio WebSocket in 20 ms frames;
   end of speech to the final transcript, and to the converter's proposal, both read on
   /api/events as the panel reads them.
2. **Send**: POST /api/submit of the proposal's orders (of the typed text's, when the
   recogniser rejected the speech) to the first motion command at the simulator: its
   navigation goal accepted (the action's status published) or a non-zero cmd_vel, read
   on the bus.
3. **STOP**: POST /api/stop while that order runs, to zero velocity on cmd_vel; then
   POST /api/release.
4. **The panel's API under load**: --clients threads, each making --requests calls to
   state, history, parse and say; latency and errors.

Beside them, in the same run, the raw Zenoh put to subscriber time through the same
router. --quick: 10 utterances and 5 clients of 10 requests, about a minute.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import platform
import random
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import websockets

from harness.measure import MOTION_WAIT, Robot, cpu_seconds, line, percentile, raw_latency
from harness.speech_set import Utterance, Voice, speak
from harness.stack import children, stack_up
from voicectl.services.stt.audio import frames, read_wav
from voicectl.shared.bus import Bus, BusOptions

COMMANDS = (
    "turn left",
    "turn right",
    "move forward one meter",
    "move back one meter",
    "turn left then turn right",
    "reach the kitchen",
    "go to the bathroom",
    "rotate left ninety degrees",
)
"""Orders that move the robot at once: rotations and short moves, so that it stays near
where it started (each is stopped as soon as it moves)."""
VOICES = (Voice("flite", "slt"), Voice("flite", "kal16"), Voice("espeak", "en-us", 150))
FRAME = 0.02


class Events:
    """The panel's event stream, as the panel reads it: finals and proposals by session."""

    def __init__(self) -> None:
        self.finals: dict[str, tuple[float, dict[str, object]]] = {}
        self.proposals: dict[str, tuple[float, dict[str, object]]] = {}
        self.proposal = asyncio.Condition()
        """Notified as each proposal comes."""
        self.idle = asyncio.Event()
        """Set while the recogniser's last status said no audio session is open."""
        self.idle.set()

    async def quiet(self, timeout: float = 10.0) -> None:
        """Until the recogniser has closed every session (each holds a decoder)."""
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self.idle.wait(), timeout)

    async def proposed(self, session: str, timeout: float = 10.0) -> None:
        """Until `session`'s proposal has come, or `timeout` seconds: an utterance still
        being decoded when its microphone stopped is finished then, and a loaded machine
        may take seconds over it."""
        async with self.proposal:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(
                    self.proposal.wait_for(lambda: session in self.proposals), timeout
                )

    async def read(self, client: httpx.AsyncClient) -> None:
        async with client.stream("GET", "/api/events", timeout=None) as response:
            async for text in response.aiter_lines():
                if not text.startswith("data: "):
                    continue
                message = json.loads(text[6:])
                session = str(message.get("session") or "")
                if message.get("type") == "transcript" and session:
                    self.finals[session] = (time.monotonic(), message)
                elif message.get("type") == "proposal" and session:
                    self.proposals[session] = (time.monotonic(), message)
                    async with self.proposal:
                        self.proposal.notify_all()
                elif message.get("type") == "sttstatus":
                    if message.get("sessions"):
                        self.idle.clear()
                    else:
                        self.idle.set()


async def stream(
    port: int, token: str, pcm: bytes, speech_end: float, events: Events
) -> tuple[str, float]:
    """Speak `pcm` into the panel's microphone socket at real-time pace; the session and
    the monotonic time its speech ended."""
    async with websockets.connect(f"ws://127.0.0.1:{port}/api/audio") as socket:
        await socket.send(json.dumps({"token": token, "robot": "robot"}))
        session = str(json.loads(await socket.recv())["session"])
        began = time.monotonic()
        for index, frame in enumerate(frames(pcm)):
            # A microphone sends a frame once it has been heard: at the end of its audio.
            await asyncio.sleep(max(0.0, began + (index + 1) * FRAME - time.monotonic()))
            await socket.send(frame)
        spoken = began + speech_end
        silence = bytes(len(frames(pcm)[0]))
        while session not in events.proposals and time.monotonic() < spoken + 3.0:
            await socket.send(silence)  # a microphone goes on hearing the room
            await asyncio.sleep(FRAME)
        await socket.send(json.dumps({"type": "stop"}))
    await events.proposed(session)
    return session, spoken


@dataclass
class Figures:
    to_final: list[float] = field(default_factory=list)
    to_proposal: list[float] = field(default_factory=list)
    to_motion: list[float] = field(default_factory=list)
    to_zero: list[float] = field(default_factory=list)
    heard_right: int = 0
    rejected: int = 0
    lost: list[str] = field(default_factory=list)


async def voice_to_motion(
    port: int, token: str, router: str, utterances: int, directory: Path
) -> tuple[Figures, list[float]]:
    recordings = [(text, speak(text, voice, directory)) for text in COMMANDS for voice in VOICES]
    figures = Figures()
    events = Events()
    headers = {"Authorization": f"Bearer {token}"}
    loop = asyncio.get_running_loop()
    with Bus.open(BusOptions(connect=[router]), loop) as bus:
        robot = Robot()
        robot.listen(bus)
        raw = await raw_latency(bus)
        async with httpx.AsyncClient(
            base_url=f"http://127.0.0.1:{port}", headers=headers, timeout=30.0
        ) as client:
            reader = asyncio.create_task(events.read(client))
            try:
                for index in range(utterances):
                    text, recording = recordings[index % len(recordings)]
                    await one(
                        client, port, token, (text, recording), directory, events, robot, figures
                    )
            finally:
                reader.cancel()
                with contextlib.suppress(asyncio.CancelledError, httpx.HTTPError):
                    await reader
    return figures, raw


async def one(
    client: httpx.AsyncClient,
    port: int,
    token: str,
    said: tuple[str, Utterance],
    directory: Path,
    events: Events,
    robot: Robot,
    figures: Figures,
) -> None:
    text, recording = said
    pcm = read_wav(directory / recording.file)
    session, spoken = await stream(port, token, pcm, recording.speech_end, events)
    if session not in events.proposals:
        figures.lost.append(f"{text!r}: no proposal")
        return
    final_at = events.finals.get(session, (float("nan"), {}))[0]
    proposal_at, proposal = events.proposals[session]
    figures.to_final.append(final_at - spoken)
    figures.to_proposal.append(proposal_at - spoken)
    orders = proposal.get("orders") or []
    if proposal.get("rejected") or not orders or proposal.get("doubts"):
        figures.rejected += 1
        parsed = (await client.post("/api/parse", json={"text": text})).json()
        orders = parsed["orders"]
    elif normalised(str(proposal.get("transcript"))) == normalised(text):
        figures.heard_right += 1
    sent = time.monotonic()
    answer = await client.post("/api/submit", json={"orders": orders, "transcript": text})
    answer.raise_for_status()
    moved = await robot.first(robot.moved, sent)
    if moved is None:
        figures.lost.append(f"{text!r}: no motion within {MOTION_WAIT:g} s")
    else:
        figures.to_motion.append(moved - sent)
    asked = time.monotonic()
    (await client.post("/api/stop", json={})).raise_for_status()
    zero = await robot.first(robot.zero, asked)
    if zero is None:
        figures.lost.append(f"{text!r}: no zero velocity after STOP")
    else:
        figures.to_zero.append(zero - asked)
    (await client.post("/api/release", json={})).raise_for_status()


def normalised(text: str) -> str:
    """Words that tell orders apart: skip words ("the") may come and go."""
    return " ".join(w for w in text.lower().split() if w not in ("the", "to"))


async def speakers(
    port: int, token: str, directory: Path, stt: int, counts: list[int], rounds: int
) -> list[tuple[int, list[float], float]]:
    """People speaking at once to one recogniser, each over a microphone socket of their
    own: per count, end of speech to final for every utterance, and the recogniser's CPU
    seconds per second of audio streamed (from /proc, over the rounds)."""
    recordings = [speak(text, voice, directory) for text in COMMANDS for voice in VOICES]
    found = []
    async with httpx.AsyncClient(
        base_url=f"http://127.0.0.1:{port}",
        headers={"Authorization": f"Bearer {token}"},
        timeout=30.0,
    ) as client:
        events = Events()
        reader = asyncio.create_task(events.read(client))
        try:
            for count in counts:
                latencies: list[float] = []
                speech = 0.0
                cpu = tree_cpu_seconds(stt)
                for round_ in range(rounds):
                    await events.quiet()
                    chosen = [
                        recordings[(round_ * count + i) % len(recordings)] for i in range(count)
                    ]
                    spoken = await asyncio.gather(
                        *(
                            stream(port, token, read_wav(directory / r.file), r.speech_end, events)
                            for r in chosen
                        )
                    )
                    speech += sum(len(read_wav(directory / r.file)) / 32000 for r in chosen)
                    for session, ended in spoken:
                        if session in events.finals:
                            latencies.append(events.finals[session][0] - ended)
                used = tree_cpu_seconds(stt) - cpu
                found.append((count, latencies, used / speech))
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError, httpx.HTTPError):
                await reader
    return found


def tree_cpu_seconds(pid: int) -> float:
    """CPU time of process `pid` and of its children (the recogniser's decoding workers)."""
    total = cpu_seconds(pid)
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError):  # a thread or a child that just ended
            for child in (task / "children").read_text().split():
                total += cpu_seconds(int(child))
    return total


def api_load(
    port: int, token: str, clients: int, requests: int
) -> tuple[dict[str, list[float]], list[str]]:
    """`clients` threads, each making `requests` calls as a panel does."""

    def request(path: str, body: object | None = None) -> urllib.request.Request:
        return urllib.request.Request(
            f"http://127.0.0.1:{port}{path}",
            data=None if body is None else json.dumps(body).encode(),
            headers={"Authorization": f"Bearer {token}", "Content-Type": "application/json"},
            method="GET" if body is None else "POST",
        )

    calls: list[tuple[str, Callable[[], urllib.request.Request]]] = [
        ("state", lambda: request("/api/state")),
        ("history", lambda: request("/api/history?limit=20")),
        ("parse", lambda: request("/api/parse", {"text": random.choice(COMMANDS)})),
        ("say", lambda: request("/api/say", {"text": "wait one second"})),
    ]
    times: dict[str, list[float]] = {name: [] for name, _ in calls}
    errors: list[str] = []
    lock = threading.Lock()

    def client(seed: int) -> None:
        rng = random.Random(seed)
        for _ in range(requests):
            name, make = rng.choice(calls)
            started = time.monotonic()
            try:
                with urllib.request.urlopen(make(), timeout=30) as answer:
                    answer.read()
            except (urllib.error.URLError, OSError) as exc:
                with lock:
                    errors.append(f"{name}: {exc}")
                continue
            with lock:
                times[name].append(time.monotonic() - started)

    with ThreadPoolExecutor(clients) as pool:
        list(pool.map(client, range(clients)))
    return times, errors


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--utterances", type=int, default=200)
    parser.add_argument("--clients", type=int, default=20)
    parser.add_argument("--requests", type=int, default=50)
    parser.add_argument(
        "--speakers",
        default="1,2,4,6",
        help="how many people speak at once, in turn (comma-separated counts)",
    )
    parser.add_argument("--rounds", type=int, default=5, help="utterances per speaker per count")
    parser.add_argument(
        "--workers", type=int, default=0, help="the recogniser's decoding processes (voicectl up)"
    )
    parser.add_argument("--quick", action="store_true", help="a one-minute run")
    parser.add_argument("--speech", type=Path, default=Path(tempfile.gettempdir()) / "voicectl-e2e")
    args = parser.parse_args()
    if args.quick:
        args.utterances, args.clients, args.requests = 10, 5, 10
        args.speakers, args.rounds = "1,2", 1
    with stack_up("voicectl-e2e-", "--workers", str(args.workers)) as stack:
        up, _lines, data, port, router = stack
        token = (data / "token").read_text().strip()
        figures, raw = asyncio.run(
            voice_to_motion(port, token, router, args.utterances, args.speech)
        )
        stt = children(up.pid)["stt"]
        counts = [int(n) for n in args.speakers.split(",")]
        crowd = asyncio.run(speakers(port, token, args.speech, stt, counts, args.rounds))
        load, errors = api_load(port, token, args.clients, args.requests)
    print(
        f"e2e: {time.strftime('%Y-%m-%d')}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}; voicectl up, "
        f"simulator at real speed"
    )
    spoken = len(figures.to_proposal)
    print(
        f"{args.utterances} utterances streamed at real time; {spoken} proposals; heard "
        f"exactly: {figures.heard_right}; rejected or doubted (sent as typed): {figures.rejected}"
    )
    print(line("end of speech -> final transcript", figures.to_final))
    print(line("end of speech -> proposal at /api/events", figures.to_proposal, "p95 450 ms"))
    print(line("Send (POST /api/submit) -> first motion", figures.to_motion, "p99 30 ms"))
    print(line("STOP (POST /api/stop) -> zero velocity", figures.to_zero, "p99 50 ms"))
    print(
        f"{'baseline: raw Zenoh put -> subscriber':<44} p50 {1e6 * percentile(raw, 0.5):7.0f}  "
        f"p99 {1e6 * percentile(raw, 0.99):7.0f} µs  (n={len(raw)})"
    )
    print(
        f"speakers at once, {args.rounds} utterances each, {args.workers} decoding workers "
        "(target: 4 with p95 under 1 s)"
    )
    for count, latencies, cpu in crowd:
        print(line(f"  {count} speaking: end of speech -> final", latencies))
        print(f"{'':<46}recogniser CPU per second of audio, per speaker: {cpu:.3f} s")
    total = sum(len(t) for t in load.values())
    print(
        f"panel API: {args.clients} clients x {args.requests} requests: {total} answered, "
        f"{len(errors)} errors (target p99 100 ms, no error)"
    )
    for name, times in load.items():
        print(line(f"  {name}", times))
    every = [t for times in load.values() for t in times]
    print(line("  all", every, "p99 100 ms"))
    for problem in [*figures.lost, *errors][:20]:
        print(f"  ! {problem}")
    print(f"voicectl up exited with {up.returncode}")
    if figures.lost or errors or up.returncode != 0:
        sys.exit(1)


if __name__ == "__main__":
    main()
