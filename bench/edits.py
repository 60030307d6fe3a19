"""Talking to the robot about its work, measured: edits of the queue, questions and
corrections spoken to the whole local stack, each with a queue made ready for it.

    .venv/bin/python -m bench.edits [--split dev|test|both] [--conditions clean,pink10]
                                    [--sample N] [--log]

Starts `voicectl up` (the simulator ten times faster than life; the shipped orders, with
orders/queue.yaml) and, for each utterance, makes the queue ready (typed, through the
client: paused with three places queued, or a long wait running, or a drive queued, or an
edit just made for "undo"), then speaks it into an audio session of its own on the bus at
real-time pace, as `voicectl listen` streams its microphone: harness/speech_set.py's
voices of the split (espeak-ng, Festival, Flite), clean and in pink noise at 10 dB
(`in_pink_noise`). The converter's proposal is acted on as the listener acts on it (a
whole and certain one is sent with `VoicectlClient.send`; "clear the queue" is sent
without its spoken "yes", as the panel's send-at-once does) and scored against what the
same words make typed:

- right: the proposal is exactly the typed words' orders (target: >= 95 % of commands,
  clean);
- wrong: a whole, certain proposal of other orders, sent; a wrong edit is one of those
  that changed the queue (target: 0);
- asked: a question back (a doubt, or ears that disagree), nothing sent; refused: nothing.

Non-commands (the split's chatter, two voices each) are spoken to the same ready queue:
none may change it (target: none). Latency, from the end of the speech: to the
supervisor's answer, i.e. the edit applied (target p95 <= 500 ms), and to the first sound
of the spoken answer: the answer, plus the time espeak-ng takes to make it, measured here
on the same words (target p95 <= 1 s). Beside them, as the baseline measured in the same
run, the same words typed: parse and send, no ear in the way.

`--sample N` runs N utterances spread over the cases, voices and conditions, to check
that the benchmark works; the figures that count come from a full run.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import itertools
import os
import random
import time
import uuid
import zlib
from collections import Counter
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path

from harness.measure import line, percentile
from harness.processes import REPO
from harness.speech_set import (
    DEV_CHATTER,
    DEV_VOICES,
    TEST_CHATTER,
    TEST_VOICES,
    VOICES_PER_CHATTER,
    Utterance,
    Voice,
    in_pink_noise,
    speak,
)
from harness.stack import stack_up
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt.audio import read_wav
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.client import VoicectlClient
from voicectl.shared.config import cache_dir
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    AudioChunk,
    AudioStart,
    AudioStop,
    CancelAll,
    GetState,
    Proposal,
    Resume,
    State,
    StateReply,
)
from voicectl.shared.tts import load_voice

ROBOT = "robot"
CHUNK = 3200
"""100 ms of 16 kHz 16-bit audio: what goes out at a time, at real-time pace."""
TAIL = 3.0
"""Seconds of room after the speech, at most, while the proposal is awaited."""
PARSER = Parser(OrderSet.load(REPO / "orders"))
CONDITIONS = ("clean", "pink10")

# The queue each utterance is spoken to, made ready with typed words.
QUEUED = ("pause", "reach the kitchen then reach the bathroom then reach base")
RUNNING = ("wait sixty seconds", "pause", "reach the kitchen then reach the bathroom")
EDITED = (*QUEUED, "cancel the kitchen")
DRIVE = ("pause", "move forward two meters")

# (said, as typed, the queue it is said to). The two splits share no phrasing.
DEV_CASES: list[tuple[str, str, tuple[str, ...]]] = [
    ("cancel the last one", "cancel the last one", QUEUED),
    ("cancel the kitchen", "cancel the kitchen", QUEUED),
    ("clear the queue", "clear the queue", QUEUED),
    ("do the bathroom first", "do the bathroom first", QUEUED),
    ("after that, go to base", "after that go to base", QUEUED),
    ("skip this one", "skip this one", RUNNING),
    ("pause", "pause", RUNNING),
    ("go on", "go on", QUEUED),
    ("undo", "undo", EDITED),
    ("what are you doing?", "what are you doing", RUNNING),
    ("where are you going?", "where are you going", RUNNING),
    ("what's next?", "what is next", QUEUED),
    ("how many are left?", "how many are left", QUEUED),
    ("how far is it?", "how far is it", RUNNING),
    ("where are you?", "where are you", QUEUED),
    ("why did that fail?", "why did that fail", QUEUED),
    ("go forward two meters, no, three", "go forward two meters no three", QUEUED),
    ("not the kitchen, the bathroom", "not the kitchen the bathroom", QUEUED),
    ("no, cancel that", "no cancel that", QUEUED),
    ("no, three meters", "no three meters", DRIVE),
]
TEST_CASES: list[tuple[str, str, tuple[str, ...]]] = [
    ("remove the last one", "remove the last one", QUEUED),
    ("drop the bathroom", "drop the bathroom", QUEUED),
    ("cancel everything", "cancel everything", QUEUED),
    ("do the kitchen first", "do the kitchen first", EDITED),
    ("after this, turn left", "after this turn left", QUEUED),
    ("skip it", "skip it", RUNNING),
    ("hold on", "hold on", RUNNING),
    ("carry on", "carry on", QUEUED),
    ("undo that", "undo that", EDITED),
    ("what are you doing", "what are you doing", QUEUED),
    ("where are you going", "where are you going", QUEUED),
    ("what comes next?", "what comes next", QUEUED),
    ("how many more?", "how many more", RUNNING),
    ("how far is it", "how far is it", QUEUED),
    ("where are you", "where are you", RUNNING),
    ("why did it fail?", "why did it fail", QUEUED),
    ("move back one meter, no, two", "move back one meter no two", QUEUED),
    ("no, not the bathroom but the dumpster", "no not the bathroom but the dumpster", QUEUED),
    ("take that back", "take that back", QUEUED),
    ("no, the base", "no the base", QUEUED),
]
SPLITS = {
    "dev": (DEV_CASES, DEV_VOICES, DEV_CHATTER),
    "test": (TEST_CASES, TEST_VOICES, TEST_CHATTER),
}


@dataclass(frozen=True)
class Case:
    said: str
    typed: str
    ready: tuple[str, ...]
    recording: Utterance
    condition: str

    @property
    def command(self) -> bool:
        return bool(self.typed)


@dataclass
class Figures:
    outcomes: Counter[str] = field(default_factory=Counter)
    wrong: list[str] = field(default_factory=list)
    """Whole, certain proposals of other orders than said, and what they did."""
    edited: list[str] = field(default_factory=list)
    """Non-commands that changed the queue."""
    applied: list[float] = field(default_factory=list)
    answered: list[str] = field(default_factory=list)
    answer_at: list[float] = field(default_factory=list)
    """Seconds from the end of the speech to the answer, for those with one."""


def cases(split: str, conditions: tuple[str, ...], directory: Path) -> list[Case]:
    """Every utterance of `split`: each case in each voice, each chatter in two voices,
    each in each condition."""
    commands, voices, chatter = SPLITS[split]
    made = []
    for said, typed, ready in commands:
        for voice in voices:
            recording = speak(said, voice, directory / split, split=split)
            made += [Case(said, typed, ready, recording, c) for c in conditions]
    rng = random.Random(split)
    for said in chatter:
        chosen: list[Voice] = rng.sample(voices, VOICES_PER_CHATTER)
        for voice in chosen:
            recording = speak(said, voice, directory / split, split=split)
            made += [Case(said, "", QUEUED, recording, c) for c in conditions]
    return made


def sampled(every: list[Case], count: int) -> list[Case]:
    """`count` utterances spread over the list (cases, voices and conditions mixed)."""
    if count <= 0 or count >= len(every):
        return every
    shuffled = every[:]
    random.Random(count).shuffle(shuffled)
    return shuffled[:count]


class Heard:
    """The converter's proposals for the benchmark's sessions, with when each came."""

    def __init__(self, bus: Bus) -> None:
        self.proposals: dict[str, tuple[float, Proposal]] = {}
        self._came = asyncio.Event()
        bus.subscribe(RobotKeys(ROBOT).proposal, json_decoder(Proposal), self._on)

    def _on(self, _key: str, proposal: Proposal) -> None:
        self.proposals.setdefault(proposal.session, (time.monotonic(), proposal))
        self._came.set()

    async def wait_for(self, session: str, timeout: float) -> None:
        """Until the proposal for `session` has come, or `timeout` seconds have passed."""
        deadline = time.monotonic() + timeout
        while session not in self.proposals and time.monotonic() < deadline:
            self._came.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._came.wait(), deadline - time.monotonic())


async def state(client: VoicectlClient) -> State:
    reply = await client.ask(ROBOT, GetState())
    assert isinstance(reply, StateReply)
    return reply.state


async def until(check: Callable[[], Awaitable[bool]], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not await check():
        if time.monotonic() > deadline:
            raise SystemExit(f"timed out waiting for {what}")
        await asyncio.sleep(0.05)


async def make_ready(client: VoicectlClient, ready: tuple[str, ...]) -> State:
    """The robot idle, its queue running, then made as `ready` says (typed words)."""
    await client.ask(ROBOT, CancelAll())

    async def idle() -> bool:
        known = await state(client)
        return known.current is None and not known.queue

    await until(idle, 30.0, "the robot to be idle")
    await client.ask(ROBOT, Resume())
    for text in ready:
        said = await client.say(ROBOT, text)
        assert said.order_ids or said.answers, (text, said)
        if text.startswith("wait"):

            async def running() -> bool:
                return (await state(client)).current is not None

            await until(running, 10.0, "the wait to run")
    return await state(client)


def layout(known: State) -> tuple[object, ...]:
    """What an edit changes: the open orders (ids and words, in order) and the pause."""
    running = known.current.id if known.current is not None else None
    return (running, [(r.id, r.order.description) for r in known.queue], bool(known.paused))


async def speak_to(bus: Bus, pcm: bytes, speech_end: float, heard: Heard) -> tuple[str, float]:
    """`pcm` into an audio session of its own at real-time pace, then the room until the
    proposal comes; the session and the monotonic time its speech ended."""
    session = uuid.uuid4().hex[:16]
    stream = bus.stream(RobotKeys(ROBOT).stt_audio(session))
    try:
        stream.send(AudioStart())
        began = time.monotonic()
        seq = 0
        quiet = bytes(CHUNK)
        pieces = itertools.chain(
            (pcm[at : at + CHUNK] for at in range(0, len(pcm) - len(pcm) % 640, CHUNK)),
            itertools.repeat(quiet),
        )
        sent = 0
        for piece in pieces:
            piece = piece[: len(piece) - len(piece) % 640]
            if not piece:
                continue
            stream.send(AudioChunk(seq=seq, pcm=piece))
            seq += 1
            sent += len(piece)
            done = sent >= len(pcm)
            late = time.monotonic() > began + speech_end + TAIL
            if done and (session in heard.proposals or late):
                break
            await asyncio.sleep(max(0.0, began + sent / 32000 - time.monotonic()))
        stream.send(AudioStop())
    finally:
        stream.close()
    await heard.wait_for(session, 10.0)
    return session, began + speech_end


async def one(
    bus: Bus, client: VoicectlClient, heard: Heard, case: Case, directory: Path, figures: Figures
) -> str:
    """Speak `case` to a queue made ready for it and score what came of it; what was
    heard, for the log."""
    before = await make_ready(client, case.ready)
    pcm = read_wav(directory / case.recording.file)
    if case.condition == "pink10":
        seed = zlib.crc32(case.recording.file.encode()) % 1000
        pcm = in_pink_noise(pcm, 10.0, seed=seed, tail=TAIL)
    session, ended = await speak_to(bus, pcm, case.recording.speech_end, heard)
    if session not in heard.proposals:
        figures.outcomes["lost" if case.command else "non-command lost"] += 1
        return "no proposal"
    _, proposal = heard.proposals[session]
    await score(client, case, proposal, before, ended, figures)
    return f"{proposal.transcript!r}: {proposal.decision}"


async def score(
    client: VoicectlClient,
    case: Case,
    proposal: Proposal,
    before: State,
    ended: float,
    figures: Figures,
) -> None:
    certain = proposal.orders and not (proposal.errors or proposal.doubts or proposal.rejected)
    expected = PARSER.parse(case.typed).orders if case.command else []
    kind = "" if case.command else "non-command "
    if proposal.rejected or not proposal.orders:
        figures.outcomes[f"{kind}refused"] += 1
        return
    if not certain:
        figures.outcomes[f"{kind}asked"] += 1
        return
    sent = await client.send(ROBOT, proposal.orders, proposal.transcript)
    at = time.monotonic()
    after = await state(client)
    changed = layout(after) != layout(before)
    if not case.command:
        figures.outcomes["non-command sent"] += 1
        if changed:
            heard = f"{case.said!r} ({case.recording.voice}) -> {proposal.transcript!r}"
            figures.edited.append(heard)
        return
    if proposal.orders == expected:
        figures.outcomes["right"] += 1
        figures.applied.append(at - ended)
        if sent.answers:
            figures.answered.append(sent.answers[-1].answer)
            figures.answer_at.append(at - ended)
        return
    figures.outcomes["wrong"] += 1
    what = "changed the queue" if changed else "changed nothing"
    figures.wrong.append(
        f"{case.said!r} ({case.recording.voice}, {case.condition}) -> "
        f"{proposal.transcript!r}: {what}"
    )


async def typed(client: VoicectlClient, every: list[Case]) -> list[float]:
    """The baseline: the same words typed, parsed and sent, from a ready queue."""
    seconds = []
    for case in every:
        if not case.command:
            continue
        await make_ready(client, case.ready)
        started = time.monotonic()
        result = await client.parse(case.typed)
        await client.send(ROBOT, result.orders, case.typed)
        seconds.append(time.monotonic() - started)
    return seconds


def first_sound(answers: list[str]) -> list[float]:
    """How long espeak-ng takes to make each answer: before it, nothing sounds."""
    voice = load_voice("espeak-ng")
    made = []
    for answer in answers:
        started = time.perf_counter()
        voice.speak(answer)
        made.append(time.perf_counter() - started)
    return made


def report(split: str, condition: str, figures: Figures, baseline: list[float]) -> None:
    total = sum(figures.outcomes[k] for k in ("right", "wrong", "asked", "refused", "lost"))
    right = figures.outcomes["right"]
    share = f"{100 * right / total:.1f} %" if total else "n/a"
    print(f"--- {split}, {condition}")
    print(
        f"commands: {total}; right {right} ({share}); wrong {figures.outcomes['wrong']} "
        f"(changed the queue: {sum('changed the queue' in w for w in figures.wrong)}); "
        f"asked {figures.outcomes['asked']}; refused {figures.outcomes['refused']}; "
        f"lost {figures.outcomes['lost']}  (targets: 0 wrong edits, >= 95 % right clean)"
    )
    said = figures.outcomes
    chatter = sum(said[f"non-command {k}"] for k in ("refused", "asked", "sent"))
    print(
        f"non-commands: {chatter}; refused {said['non-command refused']}, asked "
        f"{said['non-command asked']}, sent {said['non-command sent']}; changed the queue: "
        f"{len(figures.edited)}  (target: 0)"
    )
    for wrong in figures.wrong:
        print(f"  wrong: {wrong}")
    for edited in figures.edited:
        print(f"  non-command edited: {edited}")
    print(line("speech end -> edit applied (answer)", figures.applied, "<= 500 ms p95"))
    synth = first_sound(figures.answered)
    sound = [a + s for a, s in zip(figures.answer_at, synth, strict=True)]
    print(line("speech end -> answer's first sound", sound, "<= 1000 ms p95"))
    print(line("baseline: typed -> edit applied", baseline))
    if synth:
        print(f"espeak-ng makes an answer: p95 {1e3 * percentile(synth, 0.95):.1f} ms")


async def main_async(args: argparse.Namespace, router: str, directory: Path) -> None:
    loop = asyncio.get_running_loop()
    with Bus.open(BusOptions(connect=[router]), loop) as bus:
        client = VoicectlClient(bus)
        heard = Heard(bus)

        async def converter() -> bool:
            try:
                return bool((await client.parse("pause")).orders)
            except Exception:
                return False

        await until(converter, 60.0, "the converter")
        splits = ["dev", "test"] if args.split == "both" else [args.split]
        for split in splits:
            every = sampled(cases(split, tuple(args.conditions), directory), args.sample)
            by_condition: dict[str, Figures] = {c: Figures() for c in args.conditions}
            for number, case in enumerate(every, 1):
                what = await one(bus, client, heard, case, directory, by_condition[case.condition])
                if args.log:
                    where = f"{number}/{len(every)} {case.condition} {case.recording.voice}"
                    print(f"{where}: {case.said!r} -> {what}", flush=True)
            baseline = await typed(client, [c for c in every if c.condition == "clean"])
            for condition, figures in by_condition.items():
                report(split, condition, figures, baseline)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=["dev", "test", "both"], default="both")
    parser.add_argument(
        "--conditions",
        type=lambda text: [c for c in text.split(",") if c],
        default=list(CONDITIONS),
        help="clean, pink10 (comma separated)",
    )
    parser.add_argument("--sample", type=int, default=0, help="run only N utterances")
    parser.add_argument("--log", action="store_true", help="print each utterance as it goes")
    args = parser.parse_args()
    unknown = set(args.conditions) - set(CONDITIONS)
    if unknown:
        parser.error(f"unknown condition(s) {', '.join(sorted(unknown))}; known: clean, pink10")
    directory = cache_dir() / "bench-edits"
    load = os.getloadavg()[0]
    print(
        f"bench.edits {datetime.date.today()} on {os.cpu_count()} cores, load {load:.1f}; "
        f"split {args.split}, conditions {', '.join(args.conditions)}"
        + (f", a sample of {args.sample}" if args.sample else "")
    )
    with stack_up("voicectl-bench-edits-", "--no-web", "--time-scale", "10") as (*_, router):
        asyncio.run(main_async(args, router, directory))


if __name__ == "__main__":
    main()
