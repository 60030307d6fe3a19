"""Generated speech for the recogniser's tests and benchmark: commands and non-commands.

Every command sentence comes from the shipped orders (``orders/``) with the orders it must
become, written by hand as ``order/case`` names; every non-command must become no order.
Each sentence is spoken by espeak-ng in several voices (American and British English, male
and female variants) and speeds, resampled by sox to 16 kHz mono with silence before and
after, as a microphone would deliver it.

    python bench/speech_set.py DIR      # writes DIR/*.wav and DIR/index.json

Files are cached: a second run with the same set writes nothing.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path

VOICES = [
    ("en-us", 160),
    ("en-gb+f3", 150),
    ("en-gb-x-rp", 175),
    ("en-us+f2", 140),
    ("en-gb", 185),
    ("en-us+m3", 170),
]
"""(espeak-ng voice, words per minute); '+f3' is a female variant, '+m3' a male one."""

LEAD_SILENCE = 0.5
TAIL_SILENCE = 0.6

# The sentences below are this project's own; each command lists the orders it must make.
COMMANDS: list[tuple[str, list[str]]] = [
    ("turn left", ["rotation/left"]),
    ("turn right", ["rotation/right"]),
    ("turn to the left", ["rotation/left"]),
    ("turn back", ["rotation/back"]),
    ("reach the kitchen", ["goal/kitchen"]),
    ("reach the bathroom", ["goal/bathroom"]),
    ("reach base", ["goal/base"]),
    ("reach the dumpster", ["goal/dumpster"]),
    ("go to the kitchen", ["goal/kitchen"]),
    ("move forward", ["local_goal/forward"]),
    ("move back", ["local_goal/back"]),
    ("move forward two meters", ["drive/forward"]),
    ("go forward two point five meters", ["drive/forward"]),
    ("drive back one meter", ["drive/back"]),
    ("turn left forty five degrees", ["turn_by/left"]),
    ("rotate right ninety degrees", ["turn_by/right"]),
    ("wait three seconds", ["wait"]),
    ("wait ten seconds", ["wait"]),
    ("take a picture", ["take_photo"]),
    ("take a photo", ["take_photo"]),
    ("turn left then reach the kitchen", ["rotation/left", "goal/kitchen"]),
    ("please turn right then move forward", ["rotation/right", "local_goal/forward"]),
    ("please turn left then go to the kitchen now", ["rotation/left", "goal/kitchen"]),
    ("reach the bathroom then take a picture", ["goal/bathroom", "take_photo"]),
    ("multiply primes", ["multiply/primes"]),
]
NON_COMMANDS = [
    "what is the weather like",
    "hello robot how are you",
    "tell me a joke",
    "play some music",
    "what time is it",
    "I am going to the shop",
    "the kitchen is dirty",
    "can you hear me",
    "good morning everyone",
    "where did I leave my keys",
    "let us have lunch",
    "this is only a test",
    "open the window please",
    "call my mother",
    "how far is the station",
    "I like turnips",
    "the left door is broken",
    "I will take the bus",
    "it is raining again",
    "thank you very much",
    "set an alarm for seven",
    "turn on the lights",
]
VOICES_PER_COMMAND = 3
VOICES_PER_NON_COMMAND = 2


@dataclass(frozen=True)
class Utterance:
    """One generated recording and what it must become."""

    file: str
    """File name inside the set's directory."""
    text: str
    orders: list[str]
    """Expected 'order/case' names in spoken order; empty for a non-command."""
    voice: str
    speed: int
    speech_end: float
    """Seconds from the start of the file to the end of the speech (before the tail)."""

    @property
    def command(self) -> bool:
        return bool(self.orders)


def plan() -> list[tuple[str, list[str], str, int]]:
    """Every (text, orders, voice, speed) of the set, voices rotating through `VOICES`."""
    planned = []
    turn = 0
    for texts, per in (
        (COMMANDS, VOICES_PER_COMMAND),
        ([(text, []) for text in NON_COMMANDS], VOICES_PER_NON_COMMAND),
    ):
        for text, orders in texts:
            for _ in range(per):
                voice, speed = VOICES[turn % len(VOICES)]
                turn += 1
                planned.append((text, orders, voice, speed))
    return planned


def generate(directory: Path) -> list[Utterance]:
    """Write the whole set into `directory` (cached) and its index.json."""
    utterances = [
        speak(text, voice, speed, directory, orders) for text, orders, voice, speed in plan()
    ]
    (directory / "index.json").write_text(json.dumps([asdict(u) for u in utterances], indent=1))
    return utterances


def speak(
    text: str, voice: str, speed: int, directory: Path, orders: list[str] | None = None
) -> Utterance:
    """One recording of `text` in `directory`, made unless it is there already."""
    for tool in ("espeak-ng", "sox"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} is not installed (Debian package {tool})")
    directory.mkdir(parents=True, exist_ok=True)
    digest = hashlib.sha1(f"{text}|{voice}|{speed}|{LEAD_SILENCE}|{TAIL_SILENCE}".encode())
    name = f"{'_'.join(text.lower().split())[:40]}-{voice}-{speed}-{digest.hexdigest()[:6]}"
    wav = directory / f"{name}.wav"
    meta = directory / f"{name}.json"
    if not (wav.exists() and meta.exists()):
        speech = _speak(text, voice, speed, wav)
        meta.write_text(json.dumps({"speech": speech}))
    speech = json.loads(meta.read_text())["speech"]
    return Utterance(wav.name, text, orders or [], voice, speed, round(LEAD_SILENCE + speech, 3))


def _speak(text: str, voice: str, speed: int, out: Path) -> float:
    """Write `text` spoken by espeak-ng to `out`; return the speech's duration in seconds."""
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "raw.wav"
        trimmed = Path(tmp) / "trimmed.wav"
        subprocess.run(
            ["espeak-ng", "-v", voice, "-s", str(speed), "-w", str(raw), text], check=True
        )
        # espeak ends with some silence of its own: cut it so that the speech's end is known.
        subprocess.run(
            [
                *("sox", "-D", str(raw), "-r", "16000", "-c", "1", "-b", "16", str(trimmed)),
                *("reverse", "silence", "1", "0.02", "0.1%", "reverse"),
            ],
            check=True,
        )
        duration = float(
            subprocess.run(
                ["soxi", "-D", str(trimmed)], check=True, capture_output=True, text=True
            ).stdout
        )
        subprocess.run(
            ["sox", "-D", str(trimmed), str(out), "pad", str(LEAD_SILENCE), str(TAIL_SILENCE)],
            check=True,
        )
    return duration


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory", type=Path)
    args = parser.parse_args(argv)
    utterances = generate(args.directory)
    commands = sum(u.command for u in utterances)
    print(
        f"{len(utterances)} utterances in {args.directory}: {commands} commands, "
        f"{len(utterances) - commands} non-commands",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
