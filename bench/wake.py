"""The listener's ear: wake phrase and "stop" hits, false triggers per hour, delays.

    .venv/bin/python -m bench.wake [--split test] [--wake "hey robot"]

Hits: the phrase said alone and at the start of a command ("hey robot, turn right"), in
the split's voices (harness/speech_set.py: espeak-ng, Festival, Flite and Kokoro's
speakers), clean and in pink noise at 10 dB; "stop" said alone. False triggers: long
speech that never says either phrase, heard as one stream, per hour. The long speech of
each split is half of Debian's Asterisk prompts (a person, Allison Smith: every other
file, 13 and 13 minutes) and the split's chatter; test adds the LibriVox readings and card
names of pocketsphinx's source (people).

For the wake phrase, each hit is checked as the listener has it checked: Moonshine, the
recogniser's neural ear, on the phrase's audio (`CheckPhrase`). Reported beside it, in the
same run: the spotter alone as shipped, and pocketsphinx's keyphrase search with its own
defaults (threshold 1e-30, phone-loop penalty 0.1), the baseline.

Delays: from the end of the phrase in the audio to the end of the 20 ms frame in which
the spotter reports it, plus the spotter's CPU time per frame. The listener opens the
session at that moment (the check runs beside the streaming, and gates only what is
submitted); a stop is sent at that moment.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from harness.speech_set import (
    ASTERISK_SOUNDS,
    DEV_CHATTER,
    DEV_KOKORO,
    DEV_VOICES,
    TEST_CHATTER,
    TEST_KOKORO,
    TEST_VOICES,
    Voice,
    in_pink_noise,
    real_recordings,
    speak,
)
from voicectl.services.listen import spotter as shipped
from voicectl.services.listen.listener import CHECK_BEFORE
from voicectl.services.listen.spotter import Phrase, Spotted, Spotter
from voicectl.services.stt.audio import read_wav
from voicectl.services.stt.engine import Engine, EngineOptions
from voicectl.services.stt.load import load_engine
from voicectl.shared.config import cache_dir

PIECE = 640
COMMANDS = {
    "dev": ["go to the kitchen", "turn left", "take a picture"],
    "test": ["reach the bathroom", "move back", "turn right then take a photo"],
}
Check = Callable[[bytes], bool]


@dataclass(frozen=True)
class Setting:
    name: str
    phrase: Phrase
    loop_penalty: float
    checked: bool = False


@dataclass
class Score:
    said: int = 0
    hits: int = 0
    delays: list[float] = field(default_factory=list)

    def line(self, name: str) -> str:
        rate = 100 * self.hits / max(self.said, 1)
        text = f"  {name:<28} {self.hits:>4}/{self.said:<4} {rate:5.1f} %"
        if self.delays:
            delays = sorted(self.delays)
            p95 = delays[min(len(delays) - 1, int(0.95 * len(delays)))]
            p50 = statistics.median(delays)
            text += f"   delay p50 {1000 * p50:4.0f} ms p95 {1000 * p95:4.0f} ms"
        return text


def voices(split: str) -> list[Voice]:
    plain = DEV_VOICES if split == "dev" else TEST_VOICES
    kokoro = DEV_KOKORO if split == "dev" else TEST_KOKORO
    return [*plain, *(Voice("kokoro", name) for name in kokoro)]


def acted_on(found: list[Spotted], pcm: bytes, now: float, check: Check | None) -> list[Spotted]:
    """The hits the listener acts on: "stop" only when said alone; the wake phrase, when
    checked, only when the check hears it."""
    kept = []
    for hit in found:
        if hit.phrase == "stop":
            if hit.alone:
                kept.append(hit)
            continue
        start = max(0, int((hit.start - CHECK_BEFORE) * 16000)) * 2
        if check is None or check(pcm[start : int(now * 16000) * 2]):
            kept.append(hit)
    return kept


def run(setting: Setting, pcm: bytes, check: Check | None) -> tuple[list[Spotted], float, float]:
    """What the listener acts on in `pcm`, the clock when the first hit was reported, and
    the spotter's CPU seconds per frame."""
    spotter = Spotter([setting.phrase], setting.loop_penalty)
    kept: list[Spotted] = []
    first = -1.0
    started = time.process_time()
    for at in range(0, len(pcm), PIECE):
        found = spotter.accept(pcm[at : at + PIECE])
        if found:
            acted = acted_on(found, pcm, spotter.clock, check if setting.checked else None)
            if acted and first < 0:
                first = spotter.clock
            kept += acted
    spotter.close()
    return kept, first, (time.process_time() - started) / max(1, len(pcm) // PIECE)


def said(split: str, phrase: str, with_commands: bool) -> list[tuple[str, bytes, float]]:
    """(condition, audio, phrase end or 0) for the phrase alone and before commands."""
    out = []
    directory = cache_dir() / "bench-wake" / split
    for voice in voices(split):
        alone = speak(phrase, voice, directory)
        pcm = read_wav(directory / alone.file)
        out.append(("clean", pcm, alone.speech_end))
        out.append(("pink10", in_pink_noise(pcm, 10.0, seed=len(out)), alone.speech_end))
        if with_commands:
            for command in COMMANDS[split]:
                utterance = speak(f"{phrase}, {command}", voice, directory)
                out.append(("command", read_wav(directory / utterance.file), 0.0))
    return out


def long_speech(split: str) -> list[bytes]:
    directory = cache_dir() / "bench-wake" / split
    half = 0 if split == "dev" else 1
    people = [read_wav(path) for path in sorted(ASTERISK_SOUNDS.rglob("*.wav"))[half::2]]
    chatter = [
        read_wav(directory / speak(text, voice, directory).file)
        for text in (DEV_CHATTER if split == "dev" else TEST_CHATTER)
        for voice in voices(split)[:4]
    ]
    if split == "dev":
        return people + chatter
    real_recordings(cache_dir() / "bench-wake" / "people")  # fetches pocketsphinx's source
    readings = sorted((cache_dir() / "bench-wake" / "people" / "pocketsphinx").rglob("*.wav"))
    return people + [read_wav(path) for path in readings] + chatter


def hits(setting: Setting, split: str, check: Check) -> dict[str, Score]:
    scores: dict[str, Score] = {}
    commands = setting.phrase.text != "stop"
    for condition, pcm, end in said(split, setting.phrase.text, commands):
        kept, first, cpu = run(setting, pcm, check)
        score = scores.setdefault(condition, Score())
        score.said += 1
        score.hits += bool(kept)
        if kept and end:
            score.delays.append(max(0.0, first - end) + cpu)
    return scores


def false_triggers(setting: Setting, speech: list[bytes], check: Check) -> tuple[int, float]:
    stream = b"".join(speech)  # one stream, as a microphone hears it
    kept, _, _ = run(setting, stream, check)
    return len(kept), len(stream) / 32000


def checker(engine: Engine, phrase: str) -> Check:
    def check(pcm: bytes) -> bool:
        return engine.check(pcm, phrase).heard

    return check


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("dev", "test"), default="test")
    parser.add_argument("--wake", default="hey robot")
    args = parser.parse_args()
    engine = load_engine(EngineOptions())
    check = checker(engine, args.wake)
    speech = long_speech(args.split)
    wake, stop = Phrase(args.wake, shipped.WAKE_THRESHOLD), Phrase("stop", shipped.STOP_THRESHOLD)
    settings = [
        Setting("wake phrase, shipped: spotter + check", wake, shipped.WAKE_LOOP_PENALTY, True),
        Setting("wake phrase, the spotter alone", wake, shipped.WAKE_LOOP_PENALTY),
        Setting("wake phrase, baseline", Phrase(args.wake, 1e-30), 0.1),
        Setting("stop, shipped", stop, shipped.STOP_LOOP_PENALTY),
        Setting("stop, baseline", Phrase("stop", 1e-30), 0.1),
    ]
    print(f"{args.split} split; long speech {sum(map(len, speech)) / 32000 / 60:.1f} min")
    for setting in settings:
        phrase = setting.phrase
        print(
            f"== {setting.name} ({phrase.text!r}, {phrase.threshold:.0e}, "
            f"loop penalty {setting.loop_penalty:.0e})"
        )
        for condition, score in hits(setting, args.split, check).items():
            print(score.line(f"said, {condition}"))
        found, seconds = false_triggers(setting, speech, check)
        print(f"  false triggers: {found} ({found * 3600 / seconds:.1f} per hour)")
    engine.close()


if __name__ == "__main__":
    main()
