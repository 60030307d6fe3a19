"""A voice that answers: text to speech behind one seam (espeak-ng, flite).

Stand-in until the helper branch issue-34-voice lands; same API.
"""

from __future__ import annotations

import io
import shutil
import subprocess
import wave
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from .errors import VoicectlError

MAX_TEXT = 300
TIMEOUT = 10.0


class TtsError(VoicectlError):
    """A voice that cannot speak; the text says why and how to fix it."""


@dataclass(frozen=True)
class Speech:
    pcm: bytes
    """Mono signed 16-bit little-endian."""
    sample_rate: int


class Voice(Protocol):
    name: str

    def speak(self, text: str) -> Speech: ...


class _Command:
    """An engine run as a program that writes a WAV file to standard output."""

    def __init__(self, name: str, argv: Callable[[str], list[str]], package: str) -> None:
        if shutil.which(name) is None:
            raise TtsError(f"speech engine '{name}' is not installed (apt-get install {package})")
        self.name = name
        self._argv = argv

    def speak(self, text: str) -> Speech:
        text = " ".join(text.split())
        if not text or len(text) > MAX_TEXT:
            raise TtsError(f"text to speak must be 1 to {MAX_TEXT} characters")
        try:
            done = subprocess.run(
                self._argv(text), capture_output=True, timeout=TIMEOUT, check=False
            )
        except subprocess.TimeoutExpired as exc:
            raise TtsError(f"{self.name} did not finish within {TIMEOUT:g} s") from exc
        if done.returncode != 0:
            raise TtsError(f"{self.name} failed: {done.stderr.decode(errors='replace').strip()}")
        return read_wav(done.stdout)


def read_wav(data: bytes) -> Speech:
    with wave.open(io.BytesIO(data)) as wav:
        if wav.getsampwidth() != 2:
            raise TtsError("the engine's audio is not 16-bit")
        frames = wav.readframes(wav.getnframes())
        channels = wav.getnchannels()
        if channels != 1:
            frames = b"".join(
                frames[i : i + 2] for i in range(0, len(frames), 2 * channels)
            )
        return Speech(frames, wav.getframerate())


def to_wav(speech: Speech) -> bytes:
    out = io.BytesIO()
    with wave.open(out, "wb") as wav:
        wav.setnchannels(1)
        wav.setsampwidth(2)
        wav.setframerate(speech.sample_rate)
        wav.writeframes(speech.pcm)
    return out.getvalue()


VOICES: dict[str, Callable[[], Voice]] = {
    "espeak-ng": lambda: _Command(
        "espeak-ng", lambda text: ["espeak-ng", "--stdout", "--", text], "espeak-ng"
    ),
    "flite": lambda: _Command(
        "flite", lambda text: ["flite", "-t", text, "-o", "/dev/stdout"], "flite"
    ),
}


def load_voice(name: str = "espeak-ng") -> Voice:
    factory = VOICES.get(name)
    if factory is None:
        raise TtsError(f"unknown speech engine '{name}'; known: {', '.join(VOICES)}")
    return factory()
