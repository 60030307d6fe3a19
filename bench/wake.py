"""The listener's ear: wake phrase and "stop" hits, false triggers per hour, delays.

    .venv/bin/python -m bench.wake [--split test] [--wake "hey robot"] [--model FILE]
        [--no-stop] [--trained-only] [--long-hours 2]

Hits: the phrase said alone and at the start of a command ("hey robot, turn right"), in
the split's voices (harness/speech_set.py: espeak-ng, Festival, Flite and Kokoro's
speakers), clean and in pink noise at 10 dB; "stop" said alone. Wrong wakes: the phrase's
near-misses (`NEAR`) said before a command in one breath. False triggers: long
speech that never says either phrase, heard as one stream, per hour. The long speech of
each split is half of Debian's Asterisk prompts (a person, Allison Smith: every other
file, 13 and 13 minutes) and the split's chatter; test adds the LibriVox readings and card
names of pocketsphinx's source (people).

With `--model` (default: the shipped services/listen/hey_robot.npz), the same run also
hears the trained spotter (`voicectl wake train`, wake_model.py) three ways: as the
listener runs it, Moonshine's check hearing only the phrases the spotter is not sure of
(`TrainedSpotter.sure`); alone; and with the check on every phrase (`--wake-check`). It
refuses a model trained or tuned on one of the test voices. Its wake hits are also heard
in babble (four other voices' chatter, 10 dB below), and `--long-hours` grows the long
speech with licence texts read sentence by sentence by the split's espeak-ng, Festival
and Flite voices in turn, over again until that many hours in all: on test GPL-1, GPL-2
and GPL-3, which no training or dev voice read; on dev `DEV_READING`, which training
never read. Each setting's CPU time per second of audio is its spotter's, on the long
speech.

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
import math
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from harness.speech_set import (
    ASTERISK_SOUNDS,
    DEV_CHATTER,
    DEV_KOKORO,
    DEV_VOICES,
    TEST_CHATTER,
    TEST_KOKORO,
    TEST_VOICES,
    Voice,
    in_babble,
    in_pink_noise,
    real_recordings,
    speak,
)
from voicectl.services.listen import spotter as shipped
from voicectl.services.listen.listener import CHECK_AFTER, CHECK_BEFORE
from voicectl.services.listen.spotter import Phrase, Spotted, Spotter
from voicectl.services.listen.wake_model import Embedder, TrainedSpotter, WakeModel
from voicectl.services.listen.wake_train import LICENCES, reading
from voicectl.services.stt.audio import read_wav
from voicectl.services.stt.engine import Engine, EngineOptions
from voicectl.services.stt.load import load_engine
from voicectl.shared.config import cache_dir

PIECE = 640
SHIPPED_MODEL = Path(__file__).parents[1] / "services" / "listen" / "hey_robot.npz"
TEST_READING = ("GPL-3", "GPL-2", "GPL-1")
DEV_READING = ("Apache-2.0", "BSD", "CC0-1.0", "MPL-1.1", "LGPL-3")
"""Read by the dev voices: neither the training's licence texts nor the test's."""
COMMANDS = {
    "dev": ["go to the kitchen", "turn left", "take a picture"],
    "test": ["reach the bathroom", "move back", "turn right then take a photo"],
}
NEAR = {"hey robot": ["hey robin", "hey rover", "hey ruby", "they rob it"]}
"""Near-misses said before a command in one breath: a hit there is a wrong wake, and the
command after it a wrong order (the shipped model was trained against these alone)."""
NEAR_COMMAND = "near-miss, command (wrong)"
Check = Callable[[bytes], bool]


@dataclass(frozen=True)
class Setting:
    name: str
    phrase: Phrase
    loop_penalty: float
    checked: bool = False
    model: WakeModel | None = None
    """A trained spotter instead of pocketsphinx's search (`phrase` names its phrase)."""
    doubtful: bool = False
    """Checked only when the trained spotter is not sure (`TrainedSpotter.sure`)."""

    def spotter(self, embedder: Embedder) -> Spotter | TrainedSpotter:
        if self.model is not None:
            return TrainedSpotter(self.model, embedder=embedder)
        return Spotter([self.phrase], self.loop_penalty)


@dataclass
class Score:
    said: int = 0
    hits: int = 0
    sure: int = 0
    """Hits a trained spotter was sure of (`TrainedSpotter.sure`)."""
    delays: list[float] = field(default_factory=list)

    def line(self, name: str) -> str:
        rate = 100 * self.hits / max(self.said, 1)
        text = f"  {name:<28} {self.hits:>4}/{self.said:<4} {rate:5.1f} %"
        if self.sure:
            text += f", {self.sure} sure"
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


def acted_on(
    found: list[Spotted], pcm: bytes, now: float, check: Check | None, trained: bool = False
) -> list[Spotted]:
    """The hits the listener acts on: "stop" only when said alone; the wake phrase, when
    checked, only when the check hears it (up to the hit, or a trained phrase's end)."""
    kept = []
    for hit in found:
        if hit.phrase == "stop":
            if hit.alone:
                kept.append(hit)
            continue
        start = max(0, int((hit.start - CHECK_BEFORE) * 16000)) * 2
        end = int((min(now, hit.end + CHECK_AFTER) if trained else now) * 16000) * 2
        if check is None or check(pcm[start:end]):
            kept.append(hit)
    return kept


@dataclass
class Heard:
    """What the listener acts on in one stream."""

    kept: list[Spotted]
    first: float
    """The clock when the first hit acted on was reported (-1: none)."""
    cpu: float
    """The spotter's CPU seconds per frame (a checked setting's, its checks' too)."""
    peaks: list[float]
    """A trained spotter's highest score of each hit acted on, by `SURE_AFTER` after it."""
    sure: int = 0
    """The hits acted on that the trained spotter was sure of (`TrainedSpotter.sure`)."""


def run(setting: Setting, pcm: bytes, check: Check | None, embedder: Embedder) -> Heard:
    """What the listener acts on in `pcm`. A trained spotter's hit waits, as the listener's
    does, until the spotter knows whether it is sure of it: a doubtful setting checks it
    only if not."""
    spotter = setting.spotter(embedder)
    checked, trained = check if setting.checked else None, setting.model is not None
    heard = Heard([], -1.0, 0.0, [])
    waiting: list[tuple[Spotted, float]] = []
    """Hits and when they were reported, until they are acted on or not."""

    def settle(ended: bool = False) -> None:
        nonlocal waiting
        sure = spotter.sure() if isinstance(spotter, TrainedSpotter) else False
        if not waiting or (sure is None and not ended):
            return
        for hit, reported in waiting:
            check_it = checked if not (setting.doubtful and sure) else None
            # The listener takes the phrase's audio for the check when the hit comes.
            acted = acted_on([hit], pcm, reported, check_it, trained)
            if acted and heard.first < 0:
                heard.first = reported
            heard.kept.extend(acted)
            if acted and isinstance(spotter, TrainedSpotter):
                heard.peaks.append(spotter.peak)
                heard.sure += bool(sure)
        waiting = []

    started = time.process_time()
    for at in range(0, len(pcm), PIECE):
        waiting += [(hit, spotter.clock) for hit in spotter.accept(pcm[at : at + PIECE])]
        settle()
    waiting += [(hit, spotter.clock) for hit in spotter.flush()]
    settle(ended=True)
    spotter.close()
    heard.cpu = (time.process_time() - started) / max(1, len(pcm) // PIECE)
    return heard


def said(split: str, phrase: str, with_commands: bool) -> list[tuple[str, bytes, float]]:
    """(condition, audio, phrase end or 0) for the phrase alone and before commands, and
    its near-misses before commands."""
    out, wrong = [], []
    directory = cache_dir() / "bench-wake" / split
    chatter = DEV_CHATTER if split == "dev" else TEST_CHATTER
    for number, voice in enumerate(voices(split)):
        alone = speak(phrase, voice, directory)
        pcm = read_wav(directory / alone.file)
        out.append(("clean", pcm, alone.speech_end))
        out.append(("pink10", in_pink_noise(pcm, 10.0, seed=len(out)), alone.speech_end))
        others = [v for v in voices(split) if v != voice][number % 3 :: 3][:4]
        talkers = [
            read_wav(directory / speak(chatter[(number + k) % len(chatter)], v, directory).file)
            for k, v in enumerate(others)
        ]
        out.append(("babble10", in_babble(pcm, talkers, 10.0), alone.speech_end))
        if with_commands:
            for command in COMMANDS[split]:
                utterance = speak(f"{phrase}, {command}", voice, directory)
                out.append(("command", read_wav(directory / utterance.file), 0.0))
            for turn, near in enumerate(NEAR.get(phrase, [])):
                command = COMMANDS[split][(number + turn) % len(COMMANDS[split])]
                utterance = speak(f"{near}, {command}", voice, directory)
                wrong.append((NEAR_COMMAND, read_wav(directory / utterance.file), 0.0))
    return out + wrong  # after the rest: the noise's seeds stay as they were


def long_speech(split: str, hours: float = 0.0, phrase: str = "hey robot") -> list[bytes]:
    """The split's long speech that never says the phrase; with `hours`, grown to that
    many hours with licence texts read aloud by the split's plain voices."""
    directory = cache_dir() / "bench-wake" / split
    half = 0 if split == "dev" else 1
    people = [read_wav(path) for path in sorted(ASTERISK_SOUNDS.rglob("*.wav"))[half::2]]
    chatter = [
        read_wav(directory / speak(text, voice, directory).file)
        for text in (DEV_CHATTER if split == "dev" else TEST_CHATTER)
        for voice in voices(split)[:4]
    ]
    if split == "dev":
        speech = people + chatter
    else:
        real_recordings(cache_dir() / "bench-wake" / "people")  # fetches pocketsphinx's source
        readings = sorted((cache_dir() / "bench-wake" / "people" / "pocketsphinx").rglob("*.wav"))
        speech = people + [read_wav(path) for path in readings] + chatter
    seconds = hours * 3600 - sum(map(len, speech)) / 32000
    return speech + read_aloud(directory, seconds, phrase, split)


def read_aloud(directory: Path, seconds: float, phrase: str, split: str) -> list[bytes]:
    """Licence texts read by the split's plain voices, a sentence each in turn, over again
    (the next voice first) until `seconds` of audio."""
    if seconds <= 0:
        return []
    if not LICENCES.is_dir():
        sys.exit(f"{LICENCES} is missing (Debian package base-files): no long reading")
    plain = DEV_VOICES if split == "dev" else TEST_VOICES
    sentences = reading(DEV_READING if split == "dev" else TEST_READING, phrase, 10**6)
    out: list[bytes] = []
    total = 0.0
    for turn in range(100):
        for number, text in enumerate(sentences):
            voice = plain[(number + turn) % len(plain)]
            utterance = speak(text, voice, directory / "reading")
            pcm = read_wav(directory / "reading" / utterance.file)
            out.append(pcm)
            total += len(pcm) / 32000
            if total >= seconds:
                return out
    return out


def held_out(model: WakeModel) -> None:
    """Exit unless the model was made without any of the test split's voices."""
    test = {v.name for v in TEST_VOICES} | set(TEST_KOKORO)
    used = [*model.made.get("training voices", []), *model.made.get("dev voices", [])]
    for label in used:
        name = label.partition(":")[2].partition("@")[0]
        parts = {name, name.partition("+")[0]} | {
            part.partition(":")[0] for part in name.split("+")
        }
        if parts & test:
            sys.exit(f"the model was made with {label}, a test voice: not held out")


def hits(setting: Setting, split: str, check: Check, embedder: Embedder) -> dict[str, Score]:
    scores: dict[str, Score] = {}
    commands = setting.phrase.text != "stop"
    for condition, pcm, end in said(split, setting.phrase.text, commands):
        heard = run(setting, pcm, check, embedder)
        score = scores.setdefault(condition, Score())
        score.said += 1
        score.hits += bool(heard.kept)
        score.sure += bool(heard.sure)
        if heard.kept and end:
            score.delays.append(max(0.0, heard.first - end) + heard.cpu)
    return scores


def false_triggers(
    setting: Setting, speech: list[bytes], check: Check, embedder: Embedder
) -> tuple[Heard, float]:
    """What the listener acts on in the long speech (false triggers), and its seconds."""
    stream = b"".join(speech)  # one stream, as a microphone hears it
    return run(setting, stream, check, embedder), len(stream) / 32000


def logit(score: float) -> float:
    score = min(max(score, 1e-12), 1 - 1e-12)
    return math.log(score / (1 - score))


def checker(engine: Engine, phrase: str) -> Check:
    def check(pcm: bytes) -> bool:
        return engine.check(pcm, phrase).heard

    return check


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("dev", "test"), default="test")
    parser.add_argument("--wake", default="hey robot")
    parser.add_argument("--model", type=Path, default=SHIPPED_MODEL, help="a trained phrase")
    parser.add_argument("--no-stop", action="store_true", help="the wake phrase only")
    parser.add_argument(
        "--trained-only", action="store_true", help="the trained spotter's settings only"
    )
    parser.add_argument(
        "--long-hours", type=float, default=0.0, help="grow the test split's long speech"
    )
    args = parser.parse_args()
    engine = load_engine(EngineOptions())
    embedder = Embedder()
    check = checker(engine, args.wake)
    speech = long_speech(args.split, args.long_hours, args.wake)
    wake, stop = Phrase(args.wake, shipped.WAKE_THRESHOLD), Phrase("stop", shipped.STOP_THRESHOLD)
    settings = []
    if args.model is not None and args.model.exists():
        model = WakeModel.load(args.model)
        if args.split == "test":
            held_out(model)
        trained = Phrase(model.phrase, model.threshold)
        settings += [
            Setting(
                "wake phrase, trained, checked when doubtful (shipped)",
                trained,
                0.0,
                checked=True,
                model=model,
                doubtful=True,
            ),
            Setting("wake phrase, trained alone", trained, 0.0, model=model),
            Setting("wake phrase, trained + check", trained, 0.0, checked=True, model=model),
        ]
    if not args.trained_only:
        settings += [
            Setting("wake phrase, shipped: spotter + check", wake, shipped.WAKE_LOOP_PENALTY, True),
            Setting("wake phrase, the spotter alone", wake, shipped.WAKE_LOOP_PENALTY),
            Setting("wake phrase, baseline", Phrase(args.wake, 1e-30), 0.1),
        ]
    if not args.no_stop and not args.trained_only:
        settings += [
            Setting("stop, shipped", stop, shipped.STOP_LOOP_PENALTY),
            Setting("stop, baseline", Phrase("stop", 1e-30), 0.1),
        ]
    print(f"{args.split} split; long speech {sum(map(len, speech)) / 32000 / 60:.1f} min")
    for setting in settings:
        phrase = setting.phrase
        print(
            f"== {setting.name} ({phrase.text!r}, {phrase.threshold:.3g}, "
            f"loop penalty {setting.loop_penalty:.0e})",
            flush=True,
        )
        for condition, score in hits(setting, args.split, check, embedder).items():
            print(score.line(f"said, {condition}"), flush=True)
        heard, seconds = false_triggers(setting, speech, check, embedder)
        found, cpu = len(heard.kept), heard.cpu / (PIECE / 32000)
        print(
            f"  false triggers: {found} in {seconds / 3600:.2f} h ({found * 3600 / seconds:.2f} "
            f"per hour); spotter CPU {100 * cpu:.2f} % of a core",
            flush=True,
        )
        if heard.peaks:
            print(f"  their highest score: a logit of {logit(max(heard.peaks)):.1f}", flush=True)
    engine.close()


if __name__ == "__main__":
    main()
