"""The listener's spotter: wake phrase and "stop" hits, false triggers per hour, delay.

    .venv/bin/python bench/wake.py [--split test] [--wake "hey robot"] [--sweep]

Hits: the phrase said alone and at the start of a command, in the split's voices
(harness/speech_set.py: espeak-ng, Festival, Flite and Kokoro's speakers), clean and in
pink noise at 10 dB. False triggers: long speech that never says the phrases, per hour.
The test split's long speech is people: every prompt of Debian's Asterisk sounds (Allison
Smith, about 25 minutes) and the LibriVox readings of pocketsphinx's source; dev's is the
speech set's own chatter. Delay: from the end of the phrase in the audio to the end of the
20 ms frame in which the spotter reports it, plus the CPU time it took.

The baseline, measured in the same run, is the phrase's hits with pocketsphinx's default
keyphrase threshold (1e-30 in pocketsphinx 5).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from harness.speech_set import (  # noqa: E402
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
from services.listen.spotter import (  # noqa: E402
    STOP_THRESHOLD,
    WAKE_THRESHOLD,
    Phrase,
    Spotted,
    Spotter,
)
from services.stt.audio import read_wav  # noqa: E402
from shared.config import cache_dir  # noqa: E402

PIECE = 640
COMMANDS = {
    "dev": ["go to the kitchen", "turn left", "take a picture"],
    "test": ["reach the bathroom", "move back", "turn right then take a photo"],
}


@dataclass
class Score:
    said: int = 0
    hits: int = 0
    delays: list[float] | None = None

    def line(self, name: str) -> str:
        rate = 100 * self.hits / max(self.said, 1)
        text = f"{name:<34} {self.hits:>4}/{self.said:<4} {rate:5.1f} %"
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


def acted_on(found: list[Spotted]) -> list[Spotted]:
    """The hits the listener acts on: "stop" only when said alone."""
    return [hit for hit in found if hit.phrase != "stop" or hit.alone]


def spot(phrase: Phrase, pcm: bytes) -> tuple[int, float | None, float]:
    """Hits of `phrase` in `pcm`, the clock when the first was reported, and CPU seconds."""
    spotter = Spotter([phrase])
    hits, first = 0, None
    started = time.process_time()
    for at in range(0, len(pcm), PIECE):
        found = acted_on(spotter.accept(pcm[at : at + PIECE]))
        if found and first is None:
            first = spotter.clock
        hits += len(found)
    spotter.close()
    return hits, first, time.process_time() - started


def said(split: str, phrase: str, with_commands: bool) -> list[tuple[str, bytes, float]]:
    """(condition, audio, phrase end) for the phrase alone and before commands."""
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
    if split == "dev":
        chatter = DEV_CHATTER
        return [
            read_wav(directory / speak(text, voice, directory).file)
            for text in chatter
            for voice in voices(split)[:4]
        ]
    people = [read_wav(path) for path in sorted(ASTERISK_SOUNDS.rglob("*.wav"))]
    real_recordings(cache_dir() / "bench-wake" / "people")  # fetches pocketsphinx's source
    readings = sorted((cache_dir() / "bench-wake" / "people" / "pocketsphinx").rglob("*.wav"))
    chatter = [
        read_wav(directory / speak(text, voice, directory).file)
        for text in TEST_CHATTER
        for voice in voices(split)[:4]
    ]
    return people + [read_wav(path) for path in readings] + chatter


def hits(phrase: str, threshold: float, split: str, commands: bool) -> dict[str, Score]:
    scores: dict[str, Score] = {}
    for condition, pcm, end in said(split, phrase, commands):
        found, first, cpu = spot(Phrase(phrase, threshold), pcm)
        score = scores.setdefault(condition, Score(delays=[]))
        score.said += 1
        score.hits += found > 0
        if first is not None and end and score.delays is not None:
            score.delays.append(max(0.0, first - end) + cpu / (len(pcm) / PIECE))
    return scores


def false_per_hour(phrase: str, threshold: float, speech: list[bytes]) -> tuple[int, int, float]:
    """Hits the listener would act on, all hits, and the seconds of speech."""
    total = sum(len(pcm) for pcm in speech) / 32000
    acted = found = 0
    spotter = Spotter([Phrase(phrase, threshold)])
    for pcm in speech:  # one stream, as a microphone would hear it
        for at in range(0, len(pcm), PIECE):
            hits = spotter.accept(pcm[at : at + PIECE])
            found += len(hits)
            acted += len(acted_on(hits))
    return acted, found, total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", choices=("dev", "test"), default="test")
    parser.add_argument("--wake", default="hey robot")
    parser.add_argument("--sweep", action="store_true", help="several thresholds per phrase")
    args = parser.parse_args()
    speech = long_speech(args.split)
    wake = [1e-10, 1e-20, WAKE_THRESHOLD, 1e-30, 1e-40] if args.sweep else [WAKE_THRESHOLD]
    stop = [1e-5, STOP_THRESHOLD, 1e-15, 1e-20] if args.sweep else [STOP_THRESHOLD]
    for phrase, thresholds, commands in ((args.wake, wake, True), ("stop", stop, False)):
        for threshold in dict.fromkeys([*thresholds, 1e-30]):
            shipped = threshold == (WAKE_THRESHOLD if phrase != "stop" else STOP_THRESHOLD)
            tag = "shipped" if shipped else "baseline" if threshold == 1e-30 else "sweep"
            print(f"== {phrase!r} at {threshold:.0e} ({tag}), {args.split} split")
            for condition, score in hits(phrase, threshold, args.split, commands).items():
                print(score.line(f"  said, {condition}"))
            acted, found, seconds = false_per_hour(phrase, threshold, speech)
            print(
                f"  false triggers: {acted} in {seconds / 60:.1f} min of speech "
                f"({acted * 3600 / seconds:.1f} per hour; {found} before the 'alone' rule)"
            )


if __name__ == "__main__":
    main()
