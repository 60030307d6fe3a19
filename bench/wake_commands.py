"""The command after the wake phrase: heard as well as the same command said alone?

    .venv/bin/python -m bench.wake_commands [--split test] [--model FILE] [--commands 4]

For each voice of the split (bench/wake.py's: espeak-ng, Festival, Flite and Kokoro's
speakers) and each of the split's first `--commands` commands (harness/speech_set.py's
commands of that split), three recordings:

- *alone*: the command by itself;
- *one breath*: "hey robot, <command>", synthesized as one sentence;
- *after a pause*: "hey robot", 0.4 s of silence, then the command.

The trained spotter (`--model`, default the shipped services/listen/hey_robot.npz) hears
each as the listener does, and the listener's cut is made: the room before the phrase, then
everything from where the spotter says the phrase ended (`Spotted.end`). That audio, or the
lone command's whole recording, is streamed in 20 ms frames through the shipped recogniser
(the grammar's ear, Moonshine and Whisper, `voicectl stt`'s default engine) with the
shipped orders, and its first utterance decided as the converter decides. A command is
right when that decision sends exactly the command's orders by itself; *asked* when it
asks first; *wrong* when it sends other orders; otherwise refused. A phrase the spotter
missed is counted apart (bench/wake.py measures those).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from collections import Counter
from pathlib import Path

from bench.languages import same_orders
from bench.wake import SHIPPED_MODEL, held_out, voices
from harness.processes import REPO
from harness.speech_set import DEV_COMMANDS, LEAD_SILENCE, TEST_COMMANDS, speak
from voicectl.services.converter.decide import SHIPPED, Decision, decide, readings
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.services.listen.listener import ROOM_BEFORE
from voicectl.services.listen.wake_model import Embedder, TrainedSpotter, WakeModel
from voicectl.services.stt.audio import BYTES_PER_SECOND, frames, read_wav
from voicectl.services.stt.engine import Engine, EngineOptions, Final
from voicectl.services.stt.load import load_engine
from voicectl.services.stt.service import transcript_of
from voicectl.shared.config import cache_dir
from voicectl.shared.messages import Order

PAUSE = 0.4
"""Seconds of silence between the phrase and the command, said after a pause."""
FORMS = ("alone", "one breath", "after a pause")


def recordings(split: str, phrase: str, count: int) -> list[tuple[str, str, str, bytes]]:
    """(voice, command, form, audio) for every voice, command and form."""
    directory = cache_dir() / "bench-wake" / split
    commands = [text for text, _ in (DEV_COMMANDS if split == "dev" else TEST_COMMANDS)]
    out = []
    for voice in voices(split):
        said = speak(phrase, voice, directory)
        alone_phrase = read_wav(directory / said.file)[: int(said.speech_end * 16000) * 2]
        for command in commands[:count]:
            lone = speak(command, voice, directory)
            pcm = read_wav(directory / lone.file)
            breath = read_wav(directory / speak(f"{phrase}, {command}", voice, directory).file)
            paused = (
                alone_phrase
                + bytes(int(PAUSE * 16000) * 2)
                + pcm[int(LEAD_SILENCE * BYTES_PER_SECOND) :]
            )
            label = f"{voice.source}:{voice.name}"
            out += [
                (label, command, "alone", pcm),
                (label, command, "one breath", breath),
                (label, command, "after a pause", paused),
            ]
    return out


def cut(model: WakeModel, embedder: Embedder, pcm: bytes) -> bytes | None:
    """What the listener sends the recogniser: the room before the phrase and what
    follows its end, as the trained spotter placed them; None when it missed the phrase."""
    spotter = TrainedSpotter(model, embedder=embedder)
    try:
        for at in range(0, len(pcm), 640):
            for hit in spotter.accept(pcm[at : at + 640]):
                start = int(max(0.0, hit.start - ROOM_BEFORE) * 16000) * 2
                return pcm[start : int(hit.start * 16000) * 2] + pcm[int(hit.end * 16000) * 2 :]
    finally:
        spotter.close()
    return None


def decided(engine: Engine, parser: Parser, pcm: bytes) -> Decision | None:
    """The first utterance heard in `pcm`, decided; None when nothing was heard."""
    recogniser = engine.recogniser(15.0, True, "en")
    try:
        events = [event for frame in frames(pcm) for event in recogniser.accept(frame)]
        events += recogniser.finish()
    finally:
        recogniser.close()
    for event in events:
        if isinstance(event, Final):
            return decide(*readings(transcript_of(event, language="en"), parser), rule=SHIPPED)
    return None


def verdict(decision: Decision | None, expected: list[Order]) -> str:
    if decision is None or decision.rejected or not decision.orders:
        return "refused"
    same = same_orders(decision.orders, expected)
    if decision.confirm or decision.doubts:
        return "asked" if same else "asked wrong"
    return "right" if same else "wrong"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("dev", "test"), default="test")
    parser.add_argument("--model", type=Path, default=SHIPPED_MODEL)
    parser.add_argument("--commands", type=int, default=4, help="commands per voice")
    args = parser.parse_args()
    model = WakeModel.load(args.model)
    if args.split == "test":
        held_out(model)
    orders = OrderSet.load(REPO / "orders")
    text = Parser(orders)
    embedder = Embedder()
    engine = load_engine(EngineOptions())
    load = os.getloadavg()[0]
    started = time.perf_counter()
    tally: dict[str, Counter[str]] = {form: Counter() for form in FORMS}
    try:
        engine.use_grammar(build_grammar(orders))
        for voice, command, form, pcm in recordings(args.split, model.phrase, args.commands):
            heard = pcm if form == "alone" else cut(model, embedder, pcm)
            if heard is None:
                outcome = "phrase missed"
            else:
                decision = decided(engine, text, heard)
                outcome = verdict(decision, text.parse(command).orders)
                if outcome != "right":
                    said = decision.text if decision is not None else ""
                    print(f"  {form:<14} {voice:<24} {command!r}: {outcome} ({said!r})")
            tally[form][outcome] += 1
    finally:
        engine.close()
    print(
        f"\n{args.split} split, model {args.model.name}; {platform.node()}, {os.cpu_count()} "
        f"cores, load {load:.1f} at start; {time.perf_counter() - started:.0f} s; "
        f"{time.strftime('%Y-%m-%d')}"
    )
    kinds = ("right", "asked", "wrong", "asked wrong", "refused", "phrase missed")
    print(f"  {'':<14}" + "".join(f"{kind:>15}" for kind in kinds))
    for form in FORMS:
        total = sum(tally[form].values())
        cells = "".join(f"{tally[form][kind]:>9}/{total:<5}" for kind in kinds)
        print(f"  {form:<14}{cells}")


if __name__ == "__main__":
    main()
