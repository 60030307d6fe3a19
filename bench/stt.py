"""Speech to text on speech it was not tuned on: wrong orders, rejection, speed, memory.

    .venv/bin/python -m bench.stt [--split test|dev] [--set DIR] [--every N]

The set is harness/speech_set.py's: people (pocketsphinx's own test recordings), espeak-ng,
Festival and Flite voices, clean, in noise, in babble and in a reverberant room; generated
into --set when missing. Thresholds were tuned on its dev split; numbers are reported on
its test split, which shares no voice and no sentence with dev.

Two passes per engine:

1. Offline, in this process, each file as one utterance: real-time factor (CPU seconds of
   decoding per second of audio) and accuracy, beside pocketsphinx with its own JSGF
   compiler on the same files (the baseline this engine replaces).
2. Through the service, over Zenoh on loopback: a router, the converter and `voicectl stt`
   as processes; each file is streamed as a session in 20 ms chunks at real-time pace, as
   a microphone sends it (`--paced S`: only the last S seconds of speech and the silence
   after it). Measured: commands that became
   exactly the right orders, doubts, wrong orders, non-commands rejected, end of speech
   to final transcript and to the converter's proposal, the service's CPU per second of
   audio, its start-up time and peak RSS, and a raw Zenoh put/subscribe beside them.

`--ceiling` instead: the most any judge could reach with pocketsphinx's model, every
grammar result taken as it is, on the original audio and after noise suppression.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import pocketsphinx

from harness.measure import cpu_seconds, percentile, raw_latency
from harness.ports import free_port
from harness.processes import REPO, rss_mb
from harness.speech_set import LEAD_SILENCE, Utterance, generate
from voicectl.services.converter.decide import (
    GRAMMAR,
    SHIPPED,
    Decision,
    Reading,
    Rule,
    decide,
    free_reading,
    grammar_reading,
)
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.stt import sphinx
from voicectl.services.stt.audio import NoiseFloor, Suppressor, frames, read_wav
from voicectl.services.stt.config import add_engine_arguments, engine_options
from voicectl.services.stt.ears import why_ask
from voicectl.services.stt.engine import Engine, EngineOptions, Final, finals
from voicectl.services.stt.judge import OFF
from voicectl.services.stt.load import load_engine
from voicectl.services.stt.service import transcript_of
from voicectl.services.stt.sphinx import SUPPRESSION, GrammarHeard, PocketsphinxEngine
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    AudioChunk,
    AudioStart,
    AudioStop,
    Doubt,
    Order,
    Proposal,
    SttStatus,
    Transcript,
)

KEYS = RobotKeys("robot")
BASELINE_EVERY = 8
"""The baseline is slow (its hypothesis alone can take seconds): it decodes every 8th file."""
CHUNK_FRAMES = 1
"""One 20 ms frame per message, as the panel's web service forwards them."""
PACED = math.inf
"""Seconds of speech before its end that are streamed at real-time pace, with the tail:
by default all of it, as a microphone sends it (`--paced` sends the rest at once, for a
quicker run whose latencies include the recogniser catching up)."""


@dataclass
class Outcome:
    """What became of one utterance."""

    utterance: Utterance
    text: str = ""
    orders: list[Order] = field(default_factory=list)
    rejected: bool = True
    to_final: float | None = None
    to_proposal: float | None = None
    doubts: list[Doubt] = field(default_factory=list)
    heard: str = ""


LENGTHS = [("up to 3 s", 0.0, 3.0), ("3 to 6 s", 3.0, 6.0), ("over 6 s", 6.0, math.inf)]
"""Commands by how long their speech lasts: the latency targets are per length."""


OUTCOMES = ("right", "doubt", "wrong", "rejected")
"""What became of a command: the right orders; a doubt whose choices hold the right
orders (one click); other orders, unasked (the worst); nothing."""


def judged(outcome: Outcome, parser: Parser) -> str:
    """'right', 'doubt', 'wrong' or 'rejected' for a command; 'accepted', 'doubt' or
    'rejected' for a non-command."""
    if outcome.rejected or not outcome.orders:
        return "rejected"
    if not outcome.utterance.command:
        return "doubt" if outcome.doubts else "accepted"
    expected = parser.parse(outcome.utterance.text).orders
    if outcome.doubts:
        return "doubt" if expected in choices(outcome, parser) else "rejected"
    return "right" if outcome.orders == expected else "wrong"


def choices(outcome: Outcome, parser: Parser) -> list[list[Order]]:
    """The orders of each choice a doubt offers (the transcript, then each alternative)."""
    found = [outcome.orders]
    words = outcome.text.split()
    for doubt in outcome.doubts:
        size = len(doubt.words.split())
        for alternative in doubt.alternatives:
            text = words[: doubt.position] + alternative.split() + words[doubt.position + size :]
            result = parser.parse(" ".join(text))
            if result.orders and not result.errors:
                found.append(result.orders)
    return found


def score(outcomes: list[Outcome], parser: Parser) -> dict[str, int]:
    counts = dict.fromkeys(
        ["commands", "right", "doubt", "wrong", "chatter", "chatter_refused", "chatter_doubt"], 0
    )
    for outcome in outcomes:
        verdict = judged(outcome, parser)
        if outcome.utterance.command:
            counts["commands"] += 1
            if verdict != "rejected":
                counts[verdict] += 1
        else:
            counts["chatter"] += 1
            counts["chatter_refused"] += verdict == "rejected"
            counts["chatter_doubt"] += verdict == "doubt"
    return counts


def report(title: str, outcomes: list[Outcome], parser: Parser) -> None:
    """One line per source and condition, then the whole split."""
    groups: dict[tuple[str, str], list[Outcome]] = {}
    for outcome in outcomes:
        key = (outcome.utterance.source, outcome.utterance.condition)
        groups.setdefault(key, []).append(outcome)
    print(f"{title}")
    print(
        f"  {'source':<9}{'condition':<10}{'commands right':>16}{'+ doubt':>9}{'wrong':>7}"
        f"{'non-commands rejected':>24}{'doubt':>7}"
    )
    for (source, condition), group in [*sorted(groups.items()), (("all", ""), outcomes)]:
        n = score(group, parser)
        commands, chatter = max(n["commands"], 1), max(n["chatter"], 1)
        print(
            f"  {source:<9}{condition:<10}"
            f"{n['right']:>4}/{n['commands']:<4}{100 * n['right'] / commands:5.1f} %"
            f"{n['doubt']:>6}  {n['wrong']:>5}"
            f"{n['chatter_refused']:>10}/{n['chatter']:<4}"
            f"{100 * n['chatter_refused'] / chatter:6.1f} %"
            f"{n['chatter_doubt']:>9}"
        )


def misses(outcomes: list[Outcome], parser: Parser) -> None:
    for outcome in outcomes:
        verdict = judged(outcome, parser)
        u = outcome.utterance
        if verdict == "wrong" or (not u.command and verdict != "rejected"):
            print(
                f"    {verdict:<8} {u.source}/{u.voice} {u.condition}: {u.text!r} -> "
                f"{outcome.text!r} (heard {outcome.heard!r})"
            )


# --- offline -----------------------------------------------------------------------------------


def offline(
    args: argparse.Namespace, orders: OrderSet, utterances: list[Utterance], directory: Path
) -> None:
    options = engine_options(args)
    parser = Parser(orders)
    if options.name not in ("moonshine", "whisper"):
        grammar_only(options, orders, utterances, directory)
        return
    if args.replay:
        records = {
            r.file: r
            for path in args.replay
            for r in msgspec.json.decode(path.read_bytes(), type=list[Record])
        }  # a later file's decode of a file replaces an earlier one's
        pairs = [(u, records[u.file]) for u in utterances if u.file in records]
        missing = len(utterances) - len(pairs)
        print(f"replayed {len(pairs)} decodes ({missing} utterances had none)")
    else:
        started = time.perf_counter()
        engine = load_engine(options)
        engine.use_grammar(build_grammar(orders))
        engine.recogniser(15.0).close()  # the first decoder is part of loading
        print(f"{options.name}: loaded in {time.perf_counter() - started:.2f} s")
        pairs = []
        for utterance in utterances:
            pcm = read_wav(directory / utterance.file)
            begin = time.process_time()  # every thread: Moonshine runs on its own
            heard = finals(engine, pcm)
            used = time.process_time() - begin
            pairs.append((utterance, Record(utterance.file, heard, used, len(pcm) / 32000)))
        engine.close()
        runs = getattr(engine, "runs", None)
        if runs is not None:
            print(
                f"Moonshine's runs: {runs.at_pause} started at a pause ({runs.dropped} dropped: "
                f"the speech went on), {runs.at_end} at the end of an utterance"
            )
        if args.record:
            args.record.write_bytes(msgspec.json.encode([r for _, r in pairs]))
    cpu = sum(r.cpu for _, r in pairs)
    audio = sum(r.audio for _, r in pairs)
    print(f"real-time factor, every ear: {cpu / max(audio, 1e-9):.3f} ({audio:.0f} s of audio)")
    grammar = build_grammar(orders)
    vocabulary = frozenset(grammar.words) - frozenset(grammar.skip_words)
    asked = [u for u, r in pairs if any(third_asked(f, vocabulary) for f in r.finals)]
    clean = [u for u, _ in pairs if u.condition == "clean"]
    print(
        f"the third ear asked for {len(asked)} of {len(pairs)} utterances "
        f"({sum(u.condition == 'clean' for u in asked)} of {len(clean)} clean)"
    )
    for title, ears in VIEWS:
        outcomes = [ears_view(u, r, parser, SHIPPED, ears, vocabulary) for u, r in pairs]
        report(f"{options.name}, offline: {title}", outcomes, parser)
        misses(outcomes, parser)
    if args.sweep:
        sweep(pairs, parser, vocabulary)


VIEWS = [
    ("the grammar's ear alone (its judge)", "g"),
    ("Moonshine's ear alone", "m"),
    ("Whisper's ear alone", "w"),
    ("the grammar and Moonshine (the two-ear decision)", "gm"),
    ("the grammar and Whisper", "gw"),
    ("Moonshine and Whisper", "mw"),
    ("the decision: three ears, Whisper when asked", "gm+w"),
]
"""Which ears each view hears with: g grammar, m Moonshine, w Whisper (every utterance
recorded with --whisper-when always), +w Whisper only where the recogniser asks it."""


def third_asked(final: Final, vocabulary: frozenset[str]) -> bool:
    """Whether the recogniser would have asked the third ear for this utterance."""
    if final.third is None or final.transcription is None:
        return False
    if not final.third.asked.startswith("always"):
        return True  # recorded as the recogniser asked it
    heard = GrammarHeard(final.text, final.rejection, bool(final.doubts), final.noisy, vocabulary)
    return bool(why_ask(heard, final.transcription))


def ears_view(
    utterance: Utterance,
    record: Record,
    parser: Parser,
    rule: Rule,
    ears: str,
    vocabulary: frozenset[str],
) -> Outcome:
    """What the file becomes when heard by `ears` (`VIEWS`): each utterance the recogniser
    found in it is decided on its own, as the service decides them, and the file's orders
    are those of every utterance that became orders (a command cut in two whose halves
    both make orders is as wrong as any other wrong order)."""
    outcomes = [
        _heard_as(utterance, final, parser, rule, ears, vocabulary) for final in record.finals
    ]
    taken = [outcome for outcome in outcomes if not outcome.rejected]
    if not taken:
        return Outcome(utterance, " / ".join(o.text for o in outcomes if o.text))
    if len(taken) == 1:
        return taken[0]
    joined = Outcome(utterance, " / ".join(o.text for o in taken), rejected=False)
    joined.orders = [order for outcome in taken for order in outcome.orders]
    joined.doubts = [doubt for outcome in taken for doubt in outcome.doubts]
    return joined


def _heard_as(
    utterance: Utterance,
    final: Final,
    parser: Parser,
    rule: Rule,
    ears: str,
    vocabulary: frozenset[str],
) -> Outcome:
    transcript = transcript_of(final)
    grammar = grammar_reading(transcript, parser) if "g" in ears else Reading(GRAMMAR, "")
    free = []
    if "m" in ears and final.transcription is not None:
        free.append(free_reading(final.transcription, parser))
    wanted = "w" in ears and (not ears.endswith("+w") or third_asked(final, vocabulary))
    if wanted and final.third is not None:
        free.append(free_reading(final.third, parser))
    if ears in ("m", "w"):
        if not free or not free[0].accepted:
            return Outcome(utterance, free[0].text if free else "", heard=final.heard)
        reading = free[0]
        return Outcome(utterance, reading.text, reading.orders, False, doubts=reading.doubts)
    return from_decision(utterance, decide(grammar, free, rule), final.heard)


class Record(msgspec.Struct):
    """One file's decode, kept so that decisions can be judged again without decoding."""

    file: str
    finals: list[Final]
    cpu: float
    audio: float


def from_decision(utterance: Utterance, decision: Decision, heard: str) -> Outcome:
    outcome = Outcome(utterance, decision.text, heard=heard)
    if not decision.rejected:
        outcome.orders, outcome.rejected, outcome.doubts = decision.orders, False, decision.doubts
    return outcome


def sweep(
    pairs: list[tuple[Utterance, Record]], parser: Parser, vocabulary: frozenset[str]
) -> None:
    """Every rule of a small grid, one line each: what the decision would have been."""
    print("rule sweep: commands right + doubt, wrong orders, non-commands accepted (+ doubt)")
    grid = itertools.product(
        (-0.5, -1.0, -1.5), (True, False), (True, False), ("unclaimed", "unheard")
    )
    for support, majority, ask, lone in grid:
        rule = Rule(support=support, majority=majority, ask=ask, lone=lone)
        n = score([ears_view(u, r, parser, rule, "gm+w", vocabulary) for u, r in pairs], parser)
        accepted = n["chatter"] - n["chatter_refused"] - n["chatter_doubt"]
        print(
            f"  support {support:5.1f} majority {majority!s:<5} ask {ask!s:<5} lone {lone:<9}: "
            f"{n['right']:>4} + {n['doubt']:<3} wrong {n['wrong']:<3} "
            f"non-commands accepted {accepted} (+ {n['chatter_doubt']})"
        )


def grammar_only(
    options: EngineOptions, orders: OrderSet, utterances: list[Utterance], directory: Path
) -> None:
    """An engine with one ear (pocketsphinx, Vosk): with its judge, and pocketsphinx's
    grammar with the judge off, beside pocketsphinx's own JSGF search."""
    parser = Parser(orders)
    grammar = build_grammar(orders)
    for second_opinion in (True, False):
        started = time.perf_counter()
        engine = load_engine(options)
        if not second_opinion and isinstance(engine, PocketsphinxEngine):
            engine.thresholds = OFF
        elif not second_opinion:
            continue
        engine.use_grammar(grammar)
        engine.recogniser(15.0).close()  # the first decoder is part of loading
        loaded = time.perf_counter() - started
        outcomes: list[Outcome] = []
        cpu, audio = 0.0, 0.0
        for utterance in utterances:
            pcm = read_wav(directory / utterance.file)
            begin = time.thread_time()
            outcomes.append(decoded(engine, parser, utterance, pcm))
            cpu += time.thread_time() - begin
            audio += len(pcm) / 32000
        what = "with the second opinion" if second_opinion else "grammar alone (judge off)"
        report(
            f"{options.name}, offline, {what}: loaded in {loaded:.2f} s, "
            f"real-time factor {cpu / audio:.3f} ({audio:.0f} s of audio)",
            outcomes,
            parser,
        )
        if second_opinion:
            misses(outcomes, parser)
    if options.name == "pocketsphinx":
        baseline(grammar.jsgf, parser, utterances, directory)


def decoded(engine: Engine, parser: Parser, utterance: Utterance, pcm: bytes) -> Outcome:
    """`pcm` streamed through a fresh recogniser in 20 ms frames: what became of it."""
    heard = finals(engine, pcm)
    text = " ".join(f.text for f in heard if f.text)
    result = parser.parse(text) if text else None
    whole = len(heard) == 1 and not heard[0].rejection
    outcome = Outcome(utterance, text, heard=" ".join(f.heard for f in heard))
    if result is not None and not result.errors and result.orders and whole:
        outcome.orders, outcome.rejected = result.orders, False
        outcome.doubts = heard[0].doubts
    return outcome


def ceiling(orders: OrderSet, utterances: list[Utterance], directory: Path) -> None:
    """The most any judge could reach with pocketsphinx's acoustic model: every grammar
    result accepted (judge off, no confidence floor), on the original audio and after
    WebRTC's noise suppression. Counts the commands whose grammar result holds exactly the
    right orders, and those it turned into other orders."""
    parser = Parser(orders)
    engine = PocketsphinxEngine(min_confidence=0.0, thresholds=OFF)
    engine.use_grammar(build_grammar(orders))
    verdicts: dict[str, list[tuple[str, str]]] = {}
    for utterance in (u for u in utterances if u.command):
        pcm = read_wav(directory / utterance.file)
        quieter = Suppressor(SUPPRESSION).process(pcm)
        original, suppressed = (
            accepted(engine, parser, utterance, audio) for audio in (pcm, quieter)
        )
        verdicts.setdefault(utterance.condition, []).append((original, suppressed))
    print("ceiling: every grammar result accepted; commands right (wrong orders)")
    print(f"  {'condition':<10}{'original':>16}{'suppressed':>16}{'either':>10}")
    for condition, pairs in sorted(verdicts.items()):
        right = [sum(v[k] == "right" for v in pairs) for k in (0, 1)]
        wrong = [sum(v[k] == "wrong" for v in pairs) for k in (0, 1)]
        either = sum("right" in v for v in pairs)
        print(
            f"  {condition:<10}{right[0]:>6}/{len(pairs):<3}({wrong[0]:>2}){right[1]:>8}/"
            f"{len(pairs):<3}({wrong[1]:>2}){either:>6}/{len(pairs)}"
        )


def accepted(engine: Engine, parser: Parser, utterance: Utterance, pcm: bytes) -> str:
    """How `pcm` is judged if its grammar result is taken as it is, doubts and all."""
    outcome = decoded(engine, parser, utterance, pcm)
    outcome.doubts = []
    return judged(outcome, parser)


def baseline(jsgf: str, parser: Parser, utterances: list[Utterance], directory: Path) -> None:
    """pocketsphinx searching the JSGF through its own compiler, batch cepstral mean, the same
    noise floor: what the engine would be without the word automaton."""
    decoder = pocketsphinx.Decoder(loglevel="FATAL", lm=None, cmn="batch")
    decoder.add_jsgf_string("own", jsgf)
    decoder.activate_search("own")
    outcomes, cpu, audio = [], 0.0, 0.0
    for utterance in utterances[::BASELINE_EVERY]:
        pcm = NoiseFloor().add(read_wav(directory / utterance.file))
        begin = time.thread_time()
        decoder.start_utt()
        decoder.process_raw(pcm, full_utt=True)
        decoder.end_utt()
        hypothesis = decoder.hyp()
        cpu += time.thread_time() - begin
        audio += len(pcm) / 32000
        text = hypothesis.hypstr if hypothesis is not None else ""
        result = parser.parse(text) if text else None
        ok = result is not None and not result.errors and bool(result.orders)
        outcomes.append(Outcome(utterance, text, result.orders if ok and result else [], not ok))
    report(
        f"baseline: stock pocketsphinx, its own JSGF compiler, no rejection, 1 file in "
        f"{BASELINE_EVERY}: real-time factor {cpu / audio:.3f}",
        outcomes,
        parser,
    )


# --- through the service -------------------------------------------------------------------------


def ears_heard(transcript: Transcript) -> str:
    """Each ear's words in a final, with the free ears' support for the grammar's: what a
    wrong order's line shows."""
    said = [f"grammar {transcript.text!r}"]
    for ear in (transcript.transcription, transcript.third):
        if ear is not None:
            support = "" if ear.support is None else f" ({ear.support:.2f})"
            said.append(f"{ear.engine} {ear.text!r}{support}")
    return ", ".join(said)


def print_threads(pid: int) -> None:
    """CPU of each live thread of `pid` (threads that ended are not listed)."""
    for task in sorted(Path(f"/proc/{pid}/task").iterdir()):
        name = (task / "comm").read_text().strip()
        fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        used = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        print(f"    thread {name:<16} {used:6.2f} s CPU")


async def through_service(
    args: argparse.Namespace, orders: OrderSet, utterances: list[Utterance], directory: Path
) -> None:
    parser = Parser(orders)
    router = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    logs = tempfile.TemporaryDirectory()
    started: list[subprocess.Popen[bytes]] = []

    def start(*argv: str) -> subprocess.Popen[bytes]:
        log = open(Path(logs.name) / f"{argv[0]}.log", "wb")  # noqa: SIM115 (closed at exit)
        process = subprocess.Popen(
            [sys.executable, "-m", *argv], cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT
        )
        started.append(process)
        return process

    engine = engine_options(args).argv()
    try:
        start("voicectl.services.router", "--listen", router)
        start("voicectl.services.converter", "--connect", router, "--orders", str(args.orders))
        loop = asyncio.get_running_loop()
        with Bus.open(BusOptions(connect=[router]), loop) as bus:
            finals: dict[str, tuple[float, Transcript]] = {}
            proposals: dict[str, tuple[float, Proposal]] = {}
            arrived: dict[str, asyncio.Event] = {}
            ready = asyncio.Event()

            def on_final(_key: str, transcript: Transcript) -> None:
                finals.setdefault(transcript.session, (time.monotonic(), transcript))

            def on_proposal(_key: str, proposal: Proposal) -> None:
                proposals.setdefault(proposal.session, (time.monotonic(), proposal))
                arrived.setdefault(proposal.session, asyncio.Event()).set()

            bus.subscribe(KEYS.transcript, json_decoder(Transcript), on_final)
            bus.subscribe(KEYS.proposal, json_decoder(Proposal), on_proposal)
            idle = asyncio.Event()

            def on_status(_key: str, status: SttStatus) -> None:
                if status.ready:
                    ready.set()
                (idle.set if status.sessions == 0 else idle.clear)()

            bus.subscribe(KEYS.stt_status, json_decoder(SttStatus), on_status, history=True)
            launched = time.monotonic()
            stt = start("voicectl.services.stt", "--connect", router, *engine)
            await asyncio.wait_for(ready.wait(), 120)
            print(
                f"{args.engine}: service start to grammar in use "
                f"{time.monotonic() - launched:.2f} s"
            )
            cpu_before = cpu_seconds(stt.pid)
            raw = await raw_latency(bus)
            outcomes, audio = [], 0.0
            for number, utterance in enumerate(utterances):
                session = f"u{number}"
                pcm = read_wav(directory / utterance.file)
                audio += len(pcm) / 32000
                spoken_end = await stream(
                    bus, session, pcm, utterance.speech_end, finals, args.paced
                )
                with contextlib.suppress(TimeoutError):
                    event = arrived.setdefault(session, asyncio.Event())
                    await asyncio.wait_for(event.wait(), 15)
                outcome = Outcome(utterance)
                if session in finals:
                    at, transcript = finals[session]
                    outcome.text = transcript.text
                    outcome.to_final = at - spoken_end
                    outcome.heard = ears_heard(transcript)
                # The converter's proposal is the verdict: it rejects speech that does
                # not make whole orders.
                if session in proposals:
                    at, proposal = proposals[session]
                    outcome.to_proposal = at - spoken_end
                    outcome.rejected, outcome.orders = proposal.rejected, proposal.orders
                    # The decision's words and questions, not the grammar's doubts alone:
                    # a question between ears is offered on the proposal.
                    outcome.text, outcome.doubts = proposal.transcript, proposal.doubts
                outcomes.append(outcome)
                # One person speaking: the next utterance starts once this session has
                # closed, as a panel's next press of Listen would (else two decoders are
                # alive for a moment and the peak memory measures that).
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(idle.wait(), 5)
            cpu = cpu_seconds(stt.pid) - cpu_before
            rss = rss_mb(stt.pid, "VmHWM")
            if args.threads:
                print_threads(stt.pid)
    finally:
        for process in reversed(started):
            process.terminate()
            process.wait(timeout=20)
        logs.cleanup()
    report(f"{args.engine}, through the service", outcomes, parser)
    to_final = [o.to_final for o in outcomes if o.to_final is not None]
    to_proposal = [o.to_proposal for o in outcomes if o.to_proposal is not None]
    print(
        f"{'':<46} end of speech -> final    p50 {1e3 * percentile(to_final, 0.5):4.0f} ms"
        f"   p95 {1e3 * percentile(to_final, 0.95):4.0f} ms   (n={len(to_final)}; includes "
        "the endpointer's silence wait)"
    )
    print(
        f"{'':<46} end of speech -> proposal p50 {1e3 * percentile(to_proposal, 0.5):4.0f} ms"
        f"   p95 {1e3 * percentile(to_proposal, 0.95):4.0f} ms"
    )
    for condition in sorted({o.utterance.condition for o in outcomes}):
        some = [o.to_final for o in outcomes if o.utterance.condition == condition]
        heard = [t for t in some if t is not None]
        if heard:
            print(
                f"{'':<46}   {condition:<8} end of speech -> final p50 "
                f"{1e3 * percentile(heard, 0.5):4.0f} ms   p95 {1e3 * percentile(heard, 0.95):4.0f}"
                f" ms   (n={len(heard)})"
            )
    for label, shortest, longest in LENGTHS:
        heard = [
            o.to_final
            for o in outcomes
            if o.to_final is not None
            and o.utterance.command
            and shortest < o.utterance.speech_end - LEAD_SILENCE <= longest
        ]
        if heard:
            print(
                f"{'':<46}   commands {label:<9} end of speech -> final p50 "
                f"{1e3 * percentile(heard, 0.5):4.0f} ms   p95 {1e3 * percentile(heard, 0.95):4.0f}"
                f" ms   (n={len(heard)})"
            )
    print(
        f"{'':<46} baseline: raw Zenoh put -> subscriber p50 {1e6 * statistics.median(raw):.0f} us"
    )
    print(f"{'':<46} service CPU per second of audio {cpu / audio:.4f}   peak RSS {rss:.0f} MB")
    misses(outcomes, parser)


async def stream(
    bus: Bus,
    session: str,
    pcm: bytes,
    speech_end: float,
    finals: dict[str, object],
    paced: float = PACED,
) -> float:
    """Send one utterance; returns the wall time at which its speech ended."""
    split = frames(pcm)
    chunks = [b"".join(split[i : i + CHUNK_FRAMES]) for i in range(0, len(split), CHUNK_FRAMES)]
    seconds_per_chunk = CHUNK_FRAMES * 0.02
    paced_from = max(0, int((speech_end - min(paced, speech_end)) / seconds_per_chunk))
    sender = bus.stream(KEYS.stt_audio(session))
    await sender.matched(10)
    sender.send(AudioStart())
    for seq, chunk in enumerate(chunks[:paced_from]):
        sender.send(AudioChunk(seq=seq, pcm=chunk))
    began = time.monotonic()
    spoken_end = began + speech_end - paced_from * seconds_per_chunk
    for seq in range(paced_from, len(chunks)):
        # A microphone sends a frame once it has been heard: at the end of its audio.
        delay = began + (seq - paced_from + 1) * seconds_per_chunk - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        sender.send(AudioChunk(seq=seq, pcm=chunks[seq]))
    # A microphone goes on sending silence; the endpointer may still be waiting for it.
    silence = b"\x00" * len(chunks[0])
    extra = len(chunks)
    while session not in finals and time.monotonic() < spoken_end + 2.0:
        sender.send(AudioChunk(seq=extra, pcm=silence))
        extra += 1
        await asyncio.sleep(seconds_per_chunk)
    sender.send(AudioStop())
    sender.close()
    return spoken_end


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", type=Path, default=Path(tempfile.gettempdir()) / "voicectl-speech")
    parser.add_argument("--orders", type=Path, default=REPO / "orders")
    add_engine_arguments(parser)
    parser.add_argument("--offline-only", action="store_true")
    parser.add_argument("--service-only", action="store_true")
    parser.add_argument(
        "--ceiling",
        action="store_true",
        help="only the most any judge could reach: every grammar result accepted",
    )
    parser.add_argument("--threads", action="store_true", help="CPU of each service thread")
    parser.add_argument("--record", type=Path, help="offline: keep every decode in this file")
    parser.add_argument(
        "--replay", type=Path, nargs="+", help="offline: judge the decodes of --record again"
    )
    parser.add_argument("--sweep", action="store_true", help="offline: the decision's rules, swept")
    parser.add_argument("--conditions", help="only these conditions (clean,pink5,...)")
    parser.add_argument("--sources", help="only these sources (real,kokoro,...)")
    parser.add_argument(
        "--room",
        type=float,
        help="offline: dB a frame must stand above the room to be speech (sphinx.ROOM_MARGIN)",
    )
    parser.add_argument("--every", type=int, default=1, help="only every Nth utterance")
    parser.add_argument("--quick", action="store_true", help="every 20th utterance")
    parser.add_argument(
        "--paced",
        type=float,
        default=PACED,
        help="seconds before the end of speech streamed at real-time pace (default: all)",
    )
    parser.add_argument(
        "--split",
        choices=["dev", "test"],
        default="test",
        help="test (reported) or dev (where the thresholds were tuned)",
    )
    args = parser.parse_args()
    if args.quick:
        args.every = 20
    utterances = [u for u in generate(args.set) if u.split == args.split][:: args.every]
    if args.conditions:
        utterances = [u for u in utterances if u.condition in args.conditions.split(",")]
    if args.sources:
        utterances = [u for u in utterances if u.source in args.sources.split(",")]
    if args.room is not None:
        sphinx.ROOM_MARGIN = args.room
    orders = OrderSet.load(args.orders)
    machine = platform.processor() or platform.machine()
    print(
        f"{len(utterances)} utterances of the {args.split} split from {args.set}; {machine}, "
        f"{os.cpu_count()} cores, "
        f"Python {platform.python_version()}, pocketsphinx {version('pocketsphinx')}"
    )
    if args.ceiling:
        ceiling(orders, utterances, args.set)
        return
    if not args.service_only:
        offline(args, orders, utterances, args.set)
    if not args.offline_only:
        asyncio.run(through_service(args, orders, utterances, args.set))


def version(package: str) -> str:
    from importlib.metadata import version as found

    return found(package)


if __name__ == "__main__":
    main()
