"""Spoken answers: text to speech behind one small seam, for the panel and the listener.

Every engine runs as a child process per phrase that writes a WAV on its stdout: a crash,
a hang or an engine's global state never reaches the service that asked, and a hang is
ended by killing it. The text goes in on stdin or as one argument, never through a shell.

    voice = load_voice("espeak-ng")          # TtsError if it is not installed
    wav = to_wav(voice.speak("stopped"))     # blocking: call it off the event loop
"""

from __future__ import annotations

import importlib.util
import io
import shutil
import struct
import subprocess
import sys
import threading
import unicodedata
import wave
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Protocol

from .errors import TtsError
from .hints import apt_get_install, pip_install

MAX_TEXT = 300
"""Characters one phrase may have: an answer is a sentence, not a page."""
TIMEOUT = 10.0
"""Seconds an engine may take for one phrase before it is killed."""
CACHED = 64
"""Phrases a voice keeps: the same answers come again and again ("stopped")."""
DEFAULT_WPM = 175
"""What espeak-ng and flite speak at when no rate is given, in words per minute."""


@dataclass(frozen=True)
class Speech:
    """A spoken phrase."""

    pcm: bytes
    """Mono signed 16-bit little-endian samples."""
    sample_rate: int

    @property
    def seconds(self) -> float:
        return len(self.pcm) / 2 / self.sample_rate


def to_wav(speech: Speech) -> bytes:
    """`speech` as a WAV file's bytes (PCM, what every browser and `aplay` play)."""
    out = io.BytesIO()
    with wave.open(out, "wb") as writer:
        writer.setnchannels(1)
        writer.setsampwidth(2)
        writer.setframerate(speech.sample_rate)
        writer.writeframes(speech.pcm)
    return out.getvalue()


def from_wav(data: bytes) -> Speech:
    """A mono 16-bit PCM WAV as Speech. Its size fields may be placeholders: espeak-ng
    writing to a pipe cannot seek back to fill them in, so its data runs to the end."""
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise ValueError("not a WAV file")
    at, sample_rate = 12, 0
    while at + 8 <= len(data):
        kind, size = data[at : at + 4], struct.unpack_from("<I", data, at + 4)[0]
        body = data[at + 8 : at + 8 + size]
        if kind == b"fmt ":
            sample_rate = _mono_16bit_rate(body)
        elif kind == b"data":
            if not sample_rate:
                raise ValueError("WAV data before its format")
            return Speech(body[: len(body) // 2 * 2], sample_rate)
        at += 8 + size + size % 2
    raise ValueError("WAV without data")


def _mono_16bit_rate(fmt: bytes) -> int:
    if len(fmt) < 16:
        raise ValueError("WAV format chunk too short")
    encoding, channels, rate, _, _, bits = struct.unpack_from("<HHIIHH", fmt)
    if (encoding, channels, bits) != (1, 1, 16) or rate <= 0:
        raise ValueError(f"WAV is not mono 16-bit PCM ({channels} ch, {bits} bit, {encoding=})")
    return int(rate)


def speakable(text: str) -> str:
    """`text` as an engine is given it: one line of printable characters, 1 to MAX_TEXT
    of them; ValueError saying what is allowed otherwise."""
    printable = "".join(c if unicodedata.category(c)[0] != "C" else " " for c in text)
    line = " ".join(printable.split())
    if not line:
        raise ValueError("nothing to say: the text is empty")
    if len(line) > MAX_TEXT:
        raise ValueError(f"text too long to speak: {len(line)} characters, at most {MAX_TEXT}")
    return line


class Voice(Protocol):
    """A speech engine, ready to speak."""

    name: str

    def speak(self, text: str) -> Speech:
        """`text` spoken; blocking (tens of milliseconds), so callers run it off their loop.
        ValueError for text `speakable` refuses, TtsError when the engine fails."""
        ...


Command = Callable[[str], tuple[list[str], bytes]]
"""From the text to say, the engine's command line and what to write on its stdin."""


class CommandVoice:
    """An engine run once per phrase as a child process that writes a WAV on its stdout."""

    def __init__(self, name: str, command: Command, install: str, timeout: float = TIMEOUT):
        self.name = name
        self._command = command
        self._install = install
        self._timeout = timeout

    def speak(self, text: str) -> Speech:
        argv, stdin = self._command(speakable(text))
        try:
            done = subprocess.run(argv, input=stdin, capture_output=True, timeout=self._timeout)
        except FileNotFoundError:
            raise TtsError(not_installed(self.name, self._install)) from None
        except subprocess.TimeoutExpired:  # run() has killed it
            raise TtsError(f"speech engine {self.name!r} took over {self._timeout:g} s") from None
        if done.returncode != 0:
            said = done.stderr.decode(errors="replace").strip().splitlines()
            why = said[-1] if said else f"exit code {done.returncode}"
            raise TtsError(f"speech engine {self.name!r} failed: {why}")
        try:
            return from_wav(done.stdout)
        except ValueError as exc:
            raise TtsError(f"speech engine {self.name!r} wrote no usable WAV: {exc}") from None


class CachedVoice:
    """`voice` remembering its last CACHED phrases; safe to call from several threads."""

    def __init__(self, voice: Voice) -> None:
        self.name = voice.name
        self._voice = voice
        self._spoken: OrderedDict[str, Speech] = OrderedDict()
        self._lock = threading.Lock()

    def speak(self, text: str) -> Speech:
        line = speakable(text)
        with self._lock:
            if line in self._spoken:
                self._spoken.move_to_end(line)
                return self._spoken[line]
        speech = self._voice.speak(line)
        with self._lock:
            self._spoken[line] = speech
            while len(self._spoken) > CACHED:
                self._spoken.popitem(last=False)
        return speech


def not_installed(engine: str, install: str) -> str:
    return f"speech engine {engine!r} is not installed ({install})"


def espeak_install() -> str:
    return f"{apt_get_install('espeak-ng')}, or {pip_install('speak')}"


def flite_install() -> str:
    return apt_get_install("flite")


def _espeak_ng(voice: str | None, rate: int | None) -> Voice:
    """Debian's espeak-ng if installed, else the library of PyPI's espeakng-loader run by
    shared/espeak_library.py: the same engine and voices either way."""
    options = [*(["-v", voice] if voice else []), *(["-s", str(rate)] if rate else [])]
    binary = shutil.which("espeak-ng")
    if binary is not None:
        # -b 1: the text is UTF-8 whatever the locale; --stdin: never mistaken for options.
        argv = [binary, "--stdout", "-b", "1", *options, "--stdin"]
    elif importlib.util.find_spec("espeakng_loader") is not None:
        library = [*(["--voice", voice] if voice else []), *(["--rate", str(rate)] if rate else [])]
        argv = [sys.executable, "-m", "voicectl.shared.espeak_library", *library]
    else:
        raise TtsError(not_installed("espeak-ng", espeak_install()))
    return CommandVoice("espeak-ng", lambda text: (argv, text.encode()), espeak_install())


def _flite(voice: str | None, rate: int | None) -> Voice:
    """CMU flite (voices kal, awb, rms, slt): more natural than espeak-ng, English only."""
    binary = shutil.which("flite")
    if binary is None:
        raise TtsError(not_installed("flite", flite_install()))
    options = ["-voice", voice] if voice else []
    if rate:  # flite has no rate: it stretches durations instead
        options += ["--setf", f"duration_stretch={DEFAULT_WPM / rate:.3f}"]
    argv = [binary, *options, "-o", "/dev/stdout", "-t"]
    return CommandVoice("flite", lambda text: ([*argv, text], b""), flite_install())


VOICES: Mapping[str, Callable[[str | None, int | None], Voice]] = MappingProxyType(
    {"espeak-ng": _espeak_ng, "flite": _flite}
)
"""Each engine by name: a factory of its voice from a voice name and a rate (words per
minute), None for the engine's own."""


def load_voice(
    name: str = "espeak-ng", *, voice: str | None = None, rate: int | None = None
) -> Voice:
    """The engine `name` ready to speak, remembering recent phrases; TtsError in one line
    when it is unknown or not installed, saying how to install it."""
    factory = VOICES.get(name)
    if factory is None:
        raise TtsError(f"unknown speech engine {name!r}; known: {', '.join(VOICES)}")
    if rate is not None and not 80 <= rate <= 450:
        raise TtsError(f"speech rate {rate} is out of range: 80 to 450 words per minute")
    return CachedVoice(factory(voice, rate))
