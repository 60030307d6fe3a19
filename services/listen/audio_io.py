"""Sound in and out for `voicectl listen`: a local source as the bus's 16 kHz mono 16-bit
20 ms frames, and the voice's answers out to a speaker.

Every call here blocks (PortAudio, libsndfile, pipes): the listener runs them in threads of
its own, never on the event loop.

Sources, `open_source(spec)`, one string:

- ``-``: standard input, read as it arrives. A stream that starts with a RIFF header is a WAV
  (integer PCM of 8 to 32 bits or float, any rate and channels; its sizes are ignored, so a
  pipe of unknown length works); a stream without a header is raw 16 kHz mono signed
  16-bit little-endian PCM (said in the log). Both ``arecord -f S16_LE -r 16000 -c 1 |
  voicectl listen -`` and ``arecord -f S16_LE -r 16000 -c 1 -t wav | voicectl listen -``
  work. Other formats a pipe cannot be decoded from (Ogg, FLAC, MP3, AIFF, AU) are named
  and refused, and so is a stream whose first 0.1 s, read as raw PCM, is noise near full
  scale (random bytes, text, compressed audio): no microphone sends that.
- ``mic``, ``mic:NAME``, ``mic:INDEX``: the default input device, the input device whose
  name holds NAME (space-separated pieces, in order, any case, as sounddevice matches), or
  the one with that index in ``voicectl listen --list-devices``. Through PortAudio
  (`sounddevice`, the ``mic`` extra, and Debian's ``libportaudio2``).
- anything else: a sound file libsndfile reads (WAV of any rate, width and channels, FLAC,
  Ogg), paced at real time unless ``realtime=False``. A file named ``mic`` is ``./mic``.

Sinks, `open_sink(spec)`: ``speaker``, ``speaker:NAME``, ``speaker:INDEX`` (output devices,
matched as above); ``file:PATH`` or any path ending in ``.wav``: a WAV that collects every
utterance played (for tests).

Whatever a source's rate and channels, the channels are averaged and the rate changed with
soxr's streaming resampler; what does not fill a frame waits for the next read.

A microphone that goes away (a USB microphone unplugged, its sound server restarted) is
reopened by name about every second while `read` waits. PortAudio lists devices only when
it starts, so each attempt restarts it (`rescan_devices`); that ends every PortAudio stream
of the process, so the speaker and the rescans take turns on one lock.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any, Protocol

import numpy as np
import soundfile
import soxr

from voicectl.shared.errors import AudioError
from voicectl.shared.hints import apt_get_install, pip_install, voicectl_command
from voicectl.shared.messages import FRAME_BYTES, SAMPLE_RATE

__all__ = [
    "AudioError",
    "AudioSink",
    "AudioSource",
    "DeviceInfo",
    "list_devices",
    "open_sink",
    "open_source",
    "rescan_devices",
]

_LOGGER = logging.getLogger(__name__)

MAX_READ = 50 * FRAME_BYTES
"""The most one `read` returns: one second."""
RETRY = 1.0
"""Seconds between attempts to reopen a microphone that went away."""
STALL = 3.0
"""Seconds without audio from an open microphone after which it counts as gone. A sound
server's idle sink delivers its first block up to 2 s late (PulseAudio's null sink)."""
BACKLOG = 2.0
"""Seconds of microphone audio kept for a reader that falls behind; older audio is dropped."""
FRAME_SECONDS = FRAME_BYTES / 2 / SAMPLE_RATE

# PortAudio is one per process and so is this lock: a rescan (which closes every stream)
# must not happen while the speaker plays, nor two rescans at once.
_PORTAUDIO = threading.Lock()


class AudioSource(Protocol):
    """Where the listener's audio comes from."""

    name: str
    """What error and log messages call it ('microphone 'USB Audio'', 'speech.wav')."""

    def ready(self) -> None:
        """Block until the source's format is known (a stream's first bytes read); raise
        AudioError, one line, if it is not audio it can read. At once for a file or a
        microphone (open already); returns without a word once closed."""

    def read(self) -> bytes | None:
        """Block until one or more whole 20 ms frames of 16 kHz mono s16le are here (at most
        one second of them); None at the end of the stream or once closed."""

    def close(self) -> None:
        """Stop; idempotent. A `read` blocked in another thread wakes and returns None."""


class AudioSink(Protocol):
    """Where the voice's answers go."""

    def play(self, pcm: bytes, sample_rate: int) -> None:
        """Play mono s16le `pcm` at `sample_rate`, returning when it has been heard."""

    def close(self) -> None:
        """Stop; idempotent. A `play` in another thread stops early."""


@dataclass(frozen=True)
class DeviceInfo:
    """A sound device as PortAudio lists it."""

    index: int
    """PortAudio's number for it (`mic:INDEX`); it changes when devices come and go."""
    name: str
    input_channels: int
    output_channels: int
    default_rate: float
    """The rate the device runs at natively, in Hz."""
    host_api: str
    """PortAudio's way to it: 'ALSA', 'JACK Audio Connection Kit', 'OSS'."""
    is_default: bool
    """The default input device (`mic`)."""
    is_default_output: bool
    """The default output device (`speaker`)."""


# --- conversion ------------------------------------------------------------------------------


class _Framer:
    """Samples at any rate and channel count in, whole 20 ms frames of 16 kHz mono out."""

    def __init__(self, rate: int, channels: int) -> None:
        self.rate, self.channels = rate, channels
        self._resampler: Any = (
            None if rate == SAMPLE_RATE else soxr.ResampleStream(rate, SAMPLE_RATE, 1, "float32")
        )
        self._pending = bytearray()

    def add(self, samples: np.ndarray[Any, np.dtype[np.float32]], last: bool = False) -> None:
        """Add float samples shaped (n, channels); `last` flushes and pads the final frame."""
        mono = samples.mean(axis=1, dtype=np.float32) if samples.shape[1] > 1 else samples[:, 0]
        if self._resampler is not None:
            mono = self._resampler.resample_chunk(np.ascontiguousarray(mono), last=last)
        self._pending += np.clip(np.rint(mono * 32768.0), -32768, 32767).astype("<i2").tobytes()
        if last:
            self._pending += bytes(-len(self._pending) % FRAME_BYTES)

    def take(self) -> bytes:
        """The whole frames ready, at most a second of them; b"" if none."""
        size = min(len(self._pending) // FRAME_BYTES * FRAME_BYTES, MAX_READ)
        pcm = bytes(self._pending[:size])
        del self._pending[:size]
        return pcm


def _from_int16(pcm: bytes, channels: int) -> np.ndarray[Any, np.dtype[np.float32]]:
    samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32) / 32768.0
    return samples.reshape(-1, channels)


# --- files ------------------------------------------------------------------------------------


class _FileSource:
    """A sound file, at real time (as a microphone would deliver it) or as fast as read."""

    def __init__(self, path: Path, realtime: bool) -> None:
        self.name = str(path)
        if not path.is_file():
            raise AudioError(f"{path}: no such sound file")
        try:
            self._file = soundfile.SoundFile(str(path))
        except (soundfile.LibsndfileError, RuntimeError) as exc:
            raise AudioError(f"{path}: not a sound file ({_first_line(exc)})") from exc
        self._framer = _Framer(self._file.samplerate, self._file.channels)
        self._realtime = realtime
        # Real time: 100 ms per read, as a microphone trickles; otherwise a second at once.
        self._block = self._file.samplerate // (10 if realtime else 1)
        self._closed = threading.Event()
        self._lock = threading.Lock()
        """Held while the file is read, so that close() never closes it under a read."""
        self._ended = False
        self._start: float | None = None
        self._sent = 0

    def ready(self) -> None:
        """Open already: libsndfile read its header."""

    def read(self) -> bytes | None:
        pcm = self._next()
        if pcm is None:
            return None
        if self._realtime:
            self._start = self._start if self._start is not None else time.monotonic()
            self._sent += len(pcm)
            due = self._start + self._sent / 2 / SAMPLE_RATE
            self._closed.wait(max(0.0, due - time.monotonic()))
        return None if self._closed.is_set() else pcm

    def _next(self) -> bytes | None:
        with self._lock:
            while not self._closed.is_set():
                pcm = self._framer.take()
                if pcm or self._ended:
                    return pcm or None
                block = self._file.read(self._block, dtype="float32", always_2d=True)
                self._ended = len(block) < self._block
                self._framer.add(block, last=self._ended)
            return None

    def close(self) -> None:
        self._closed.set()
        with self._lock:
            self._file.close()


# --- standard input ---------------------------------------------------------------------------


@dataclass(frozen=True)
class _Format:
    """How a stream's samples are laid out."""

    rate: int
    channels: int
    decode: Callable[[bytes], np.ndarray[Any, np.dtype[np.float32]]]
    """Bytes of whole sample frames to floats in [-1, 1], channels interleaved."""
    width: int
    """Bytes per sample of one channel."""


RAW = _Format(SAMPLE_RATE, 1, lambda b: np.frombuffer(b, "<i2").astype(np.float32) / 32768.0, 2)
REFUSED = (
    (b"OggS", "an Ogg stream"),
    (b"fLaC", "a FLAC stream"),
    (b"ID3", "an MP3 stream"),
    (b"FORM", "an AIFF stream"),
    (b".snd", "an AU stream"),
    (b"RIFX", "a big-endian WAV"),
    (b"RF64", "an RF64 WAV"),
)
"""Formats a stream starts by saying, which standard input does not decode: (magic, name)."""
RAW_CHECK = 3200
"""Bytes (0.1 s) of a headerless stream looked at before it is taken for raw PCM."""
RAW_NOISE = 0.35
"""The mean level, of full scale, above which a headerless start is not a microphone's:
speech averages under a tenth; random bytes a half, text more."""
MAX_HEADER = 1 << 20
"""Bytes of a WAV stream's chunks before its audio that are read past, at most."""
MAX_FMT = 256
"""Bytes of a WAV's 'fmt ' chunk, at most (40 with every extension)."""
MAX_CHANNELS = 64
MAX_RATE = 384000


def _mpeg_frame(head: bytes) -> bool:
    """Whether `head` is an MPEG audio frame's header (an MP3 without ID3 tags): its sync
    bits, and a version, layer, bitrate and rate that exist. Raw PCM starting with the
    samples -1 or 0 (FF FF, 00 00) is none."""
    if len(head) < 3 or head[0] != 0xFF or head[1] & 0xE0 != 0xE0:
        return False
    version, layer = head[1] >> 3 & 3, head[1] >> 1 & 3
    bitrate, rate = head[2] >> 4, head[2] >> 2 & 3
    return version != 1 and layer != 0 and bitrate not in (0, 15) and rate != 3


def _decoder(tag: int, bits: int) -> Callable[[bytes], np.ndarray[Any, np.dtype[np.float32]]]:
    """How to turn a WAV's sample bytes into floats; AudioError for a layout not handled."""
    match tag, bits:
        case 1, 8:
            return lambda b: (np.frombuffer(b, np.uint8).astype(np.float32) - 128.0) / 128.0
        case 1, 16:
            return RAW.decode
        case 1, 24:
            return _decode_24
        case 1, 32:
            return lambda b: np.frombuffer(b, "<i4").astype(np.float32) / 2.0**31
        case 3, 32:
            return lambda b: np.frombuffer(b, "<f4").astype(np.float32)
        case 3, 64:
            return lambda b: np.frombuffer(b, "<f8").astype(np.float32)
    raise AudioError(f"standard input: a WAV of format {tag:#x} with {bits}-bit samples")


def _decode_24(data: bytes) -> np.ndarray[Any, np.dtype[np.float32]]:
    triples = np.frombuffer(data, np.uint8).reshape(-1, 3).astype(np.int32)
    value = triples[:, 0] | triples[:, 1] << 8 | triples[:, 2] << 16
    value = (value << 8) >> 8  # sign-extend from 24 bits
    return value.astype(np.float32) / 2.0**23


class _PipeSource:
    """Audio from a file descriptor (standard input), as it arrives. Reads wait in
    `select` with a short timeout, so that close() from another thread is seen."""

    POLL = 0.1

    def __init__(self, fd: int, name: str) -> None:
        self.name = name
        self._fd = fd
        self._closed = threading.Event()
        self._ended = False
        self._format: _Format | None = None
        self._framer: _Framer | None = None
        self._carry = b""

    def ready(self) -> None:
        if self._framer is None:
            try:
                self._start()
            except AudioError:
                if not self._closed.is_set():
                    raise

    def read(self) -> bytes | None:
        while not self._closed.is_set():
            if self._framer is None:
                try:
                    self._start()
                except AudioError:
                    if self._closed.is_set():
                        return None
                    raise
                continue
            pcm = self._framer.take()
            if pcm or self._ended:
                return pcm or None
            self._feed(self._receive(65536))
        return None

    def _start(self) -> None:
        """Tell a WAV from raw PCM by its first bytes, and read the WAV's header; refuse
        what is neither."""
        head = self._gather(4)
        if head == b"RIFF":
            self._format = self._wav_header()
        else:
            named = next((name for magic, name in REFUSED if head.startswith(magic)), None)
            if named is None and _mpeg_frame(head):
                named = "an MP3 stream"
            if named:
                raise AudioError(
                    f"{self.name}: {named}, which cannot be decoded from a pipe; give the "
                    "file's name instead (voicectl listen FILE), or pipe WAV or raw PCM"
                )
            head += self._gather(RAW_CHECK - len(head))
            self._check_raw(head)
            _LOGGER.info(
                "%s has no WAV header: read as raw 16 kHz mono signed 16-bit PCM", self.name
            )
            self._format = RAW
            self._carry = head
        self._framer = _Framer(self._format.rate, self._format.channels)

    def _check_raw(self, head: bytes) -> None:
        """Refuse a headerless stream that is no microphone's: read as 16-bit samples, its
        start is noise near full scale (random bytes, text, compressed audio)."""
        samples = np.frombuffer(head[: len(head) - len(head) % 2], "<i2")
        if len(samples) < RAW_CHECK // 4:
            return  # too short to judge
        level = float(np.mean(np.abs(samples.astype(np.float32)))) / 32768.0
        if level > RAW_NOISE:
            raise AudioError(
                f"{self.name}: not audio this can read: no WAV header, and as raw 16-bit PCM "
                f"its start is noise at {level:.0%} of full scale (random bytes, text or a "
                "compressed format?); pipe WAV or raw 16 kHz mono 16-bit PCM"
            )

    def _wav_header(self) -> _Format:
        """The format of a WAV stream, read up to the start of its samples (RIFF chunks:
        'fmt ' gives the layout, 'data' is the audio; others are skipped, unread into
        memory, up to `MAX_HEADER` bytes in all)."""
        if self._exactly(8)[4:] != b"WAVE":
            raise AudioError(f"{self.name}: starts with RIFF but is not a WAV")
        found: _Format | None = None
        skipped = 0
        while True:
            chunk, size = struct.unpack("<4sI", self._exactly(8))
            if chunk == b"data":
                if found is None:
                    raise AudioError(f"{self.name}: a WAV without a 'fmt ' chunk")
                return found
            size += size % 2
            skipped += size + 8
            if skipped > MAX_HEADER:
                raise AudioError(
                    f"{self.name}: a WAV whose chunk {chunk!r} declares {size} bytes before "
                    f"the audio; at most {MAX_HEADER} are read"
                )
            if chunk != b"fmt ":
                self._skip(size)
                continue
            if not 16 <= size <= MAX_FMT:
                raise AudioError(f"{self.name}: a WAV whose 'fmt ' chunk is {size} bytes")
            found = self._layout(self._exactly(size))

    def _layout(self, body: bytes) -> _Format:
        """A 'fmt ' chunk's layout; AudioError for one no microphone or file has."""
        tag, channels, rate, _, _, bits = struct.unpack_from("<HHIIHH", body)
        if tag == 0xFFFE and len(body) >= 26:  # WAVE_FORMAT_EXTENSIBLE: the real tag
            (tag,) = struct.unpack_from("<H", body, 24)
        if not 1 <= channels <= MAX_CHANNELS or not 1000 <= rate <= MAX_RATE:
            raise AudioError(
                f"{self.name}: a WAV of {channels} channels at {rate} Hz; 1 to "
                f"{MAX_CHANNELS} channels at 1000 to {MAX_RATE} Hz are read"
            )
        return _Format(rate, channels, _decoder(tag, bits), bits // 8)

    def _skip(self, size: int) -> None:
        """Read past `size` bytes of the stream, a piece at a time."""
        while size > 0:
            data = self._exactly(min(size, 65536))
            size -= len(data)

    def _feed(self, data: bytes) -> None:
        assert self._format is not None
        assert self._framer is not None
        data = self._carry + data
        step = self._format.width * self._format.channels
        whole = len(data) - len(data) % step
        self._carry = data[whole:]
        samples = self._format.decode(data[:whole]).reshape(-1, self._format.channels)
        self._framer.add(samples, last=self._ended)

    def _gather(self, size: int) -> bytes:
        """`size` bytes, or fewer if the stream ends (or is closed) first."""
        data = b""
        while len(data) < size and not self._ended:
            data += self._receive(size - len(data))
        return data

    def _exactly(self, size: int) -> bytes:
        data = self._gather(size)
        if len(data) < size:
            raise AudioError(f"{self.name}: the stream ended inside a WAV header")
        return data

    def _receive(self, size: int) -> bytes:
        """Up to `size` bytes once some are there; b"" (and `_ended`) at the end or on close."""
        while not self._closed.is_set():
            ready, _, _ = select.select([self._fd], [], [], self.POLL)
            if ready:
                data = os.read(self._fd, size)
                self._ended = not data
                return data
        self._ended = True
        return b""

    def close(self) -> None:
        self._closed.set()


# --- PortAudio --------------------------------------------------------------------------------


def list_hint() -> str:
    return f"{voicectl_command('listen', '--list-devices')} shows the devices"


def _portaudio() -> ModuleType:
    """`sounddevice`, imported now; AudioError with the install hint if it cannot be."""
    try:
        import sounddevice
    except ImportError as exc:
        raise AudioError(
            f"no sound device: sounddevice is not installed ({pip_install('mic')}; {exc})"
        ) from exc
    except OSError as exc:  # sounddevice's import raises this when libportaudio is missing
        raise AudioError(
            f"no sound device: PortAudio is not installed ({apt_get_install('libportaudio2')})"
        ) from exc
    module: ModuleType = sounddevice  # untyped: its attributes are Any
    return module


def list_devices() -> list[DeviceInfo]:
    """Every device PortAudio saw when it started (`rescan_devices` to look again)."""
    sd = _portaudio()
    default_in, default_out = sd.default.device
    apis = [api["name"] for api in sd.query_hostapis()]
    return [
        DeviceInfo(
            index=index,
            name=device["name"],
            input_channels=device["max_input_channels"],
            output_channels=device["max_output_channels"],
            default_rate=device["default_samplerate"],
            host_api=apis[device["hostapi"]],
            is_default=index == default_in,
            is_default_output=index == default_out,
        )
        for index, device in enumerate(sd.query_devices())
    ]


def rescan_devices() -> None:
    """Start PortAudio again, so that it sees devices plugged in since (and a changed
    PULSE_SERVER or ALSA configuration). Every PortAudio stream of the process ends."""
    sd = _portaudio()
    with _PORTAUDIO:
        # sounddevice's own pair (private): PortAudio has no call to list devices again.
        sd._terminate()
        sd._initialize()


@dataclass(frozen=True)
class _Device:
    """A device as the user chose it, and as PortAudio named it when found."""

    kind: str
    """'input' or 'output'."""
    spec: str
    """What the user wrote after 'mic:' or 'speaker:' ('' for the default)."""
    name: str
    host_api: str

    @property
    def what(self) -> str:
        return f"{'microphone' if self.kind == 'input' else 'speaker'} {self.name!r}"

    def index(self) -> int | None:
        """Its index now, found by name: indices change when devices come and go."""
        for device in list_devices():
            channels = device.input_channels if self.kind == "input" else device.output_channels
            if device.name == self.name and device.host_api == self.host_api and channels > 0:
                return device.index
        return None


def _find_device(kind: str, spec: str) -> _Device:
    """The device `spec` names ('', a name's pieces or an index); AudioError if none."""
    sd = _portaudio()
    what = "microphone" if kind == "input" else "speaker"
    query: int | str | None = int(spec) if spec.isdigit() else (spec or None)
    try:
        info = sd.query_devices(query, kind=kind)
    except ValueError as exc:
        several = str(exc).startswith("Multiple")
        why = "matches several devices" if several else "not found"
        raise AudioError(f"{what} {spec!r} {why} ({list_hint()})") from exc
    except sd.PortAudioError as exc:  # an index out of range, or no default device
        raise AudioError(f"{what} {spec or 'default'!r} not found ({list_hint()})") from exc
    if info[f"max_{kind}_channels"] < 1:
        raise AudioError(f"{what} {spec!r}: device {info['name']!r} has no {kind} ({list_hint()})")
    host_api = sd.query_hostapis(info["hostapi"])["name"]
    return _Device(kind, spec, info["name"], host_api)


def _layout(sd: ModuleType, index: int, kind: str, rate: int) -> tuple[int, int]:
    """A rate and channel count the device takes: `rate` and mono if it can (a sound
    server converts anything), else its own rate, in mono or in as few channels as it
    allows (a bare ALSA device takes only what its hardware does)."""
    check = sd.check_input_settings if kind == "input" else sd.check_output_settings
    info = sd.query_devices(index)
    own, most = round(info["default_samplerate"]), info[f"max_{kind}_channels"]
    for candidate in dict.fromkeys((rate, own)):
        for channels in dict.fromkeys((1, min(most, 2), most)):
            with contextlib.suppress(sd.PortAudioError):
                check(device=index, samplerate=candidate, channels=channels, dtype="int16")
                return candidate, channels
    return own, most


def _open_error(device: _Device, exc: Exception) -> AudioError:
    """A PortAudio refusal as one line: busy devices said so plainly."""
    text = _first_line(exc)
    if "Device unavailable" in text or "busy" in text.lower():
        return AudioError(f"{device.what} is busy")
    return AudioError(f"{device.what} cannot be opened: {text}")


class _Blocks:
    """What the PortAudio callback hands the reader: a bounded queue that drops the oldest
    blocks (saying so once per episode) when the reader falls behind."""

    def __init__(self, capacity: int, what: str) -> None:
        self._blocks: deque[bytes] = deque(maxlen=capacity)
        self._what = what
        self._dropping = False
        self.changed = threading.Condition()
        """Notified when a block arrives or the stream's state changes."""

    def put(self, block: bytes) -> None:
        with self.changed:
            if len(self._blocks) == self._blocks.maxlen and not self._dropping:
                self._dropping = True
                _LOGGER.warning("%s: the listener fell behind; dropping old audio", self._what)
            self._blocks.append(block)
            self.changed.notify_all()

    def take(self) -> bytes:
        """Everything queued, joined (b"" if nothing); call holding `changed`."""
        blocks = b"".join(self._blocks)
        self._blocks.clear()
        self._dropping = False
        return blocks

    def clear(self) -> None:
        with self.changed:
            self._blocks.clear()


class _Microphone:
    """A PortAudio input device that is reopened by name when it goes away."""

    def __init__(self, device: _Device, rate: int | None) -> None:
        self._device = device
        self.name = device.what
        self._wanted_rate = rate
        self._stream: Any = None
        self._generation = 0
        """Which stream is current: a finished callback from an older one is ignored."""
        self._lost = False
        self._closed = False
        self._blocks = _Blocks(round(BACKLOG / FRAME_SECONDS), self.name)
        self._framer: _Framer | None = None
        self._stream_lock = threading.Lock()
        index = device.index()
        if index is None:
            raise AudioError(f"{self.name} not found ({list_hint()})")
        self._open(index)

    def ready(self) -> None:
        """Open already: PortAudio started the device."""

    def read(self) -> bytes | None:
        while True:
            if self._framer is not None and (pcm := self._framer.take()):
                return pcm
            block = self._wait()
            if block is None:
                return None
            if block and self._framer is not None:
                self._framer.add(_from_int16(block, self._framer.channels))

    def _wait(self) -> bytes | None:
        """Audio from the device (b"" after a reconnection), or None once closed."""
        changed = self._blocks.changed
        with changed:
            while not self._closed and not self._lost:
                if block := self._blocks.take():
                    return block
                if not changed.wait(STALL) and not self._closed:
                    _LOGGER.warning("%s: no audio for %g s", self.name, STALL)
                    self._lost = True
            if self._closed:
                return None
        self._reconnect()
        return b""

    def _reconnect(self) -> None:
        """Reopen the device by name, every RETRY seconds until it is back or closed."""
        _LOGGER.warning("%s is gone; trying to open it again every %g s", self.name, RETRY)
        while True:
            self._close_stream()
            try:
                rescan_devices()
                index = self._device.index()
                if index is not None:
                    self._open(index)
                    _LOGGER.warning("%s is back", self.name)
                    return
            except AudioError as exc:
                _LOGGER.debug("%s: not yet: %s", self.name, exc)
            with self._blocks.changed:
                if self._closed or self._blocks.changed.wait_for(lambda: self._closed, RETRY):
                    return

    def _open(self, index: int) -> None:
        """Open and start the device at `index`: 16 kHz mono when it takes that (a sound
        server converts), else its own rate and channels, converted here."""
        sd = _portaudio()
        rate, channels = _layout(sd, index, "input", self._wanted_rate or SAMPLE_RATE)
        with self._stream_lock, _PORTAUDIO:
            if self._closed:
                return
            self._generation += 1
            generation = self._generation
            try:
                stream = sd.RawInputStream(
                    device=index,
                    samplerate=rate,
                    channels=channels,
                    dtype="int16",
                    blocksize=round(rate * FRAME_SECONDS),
                    callback=lambda data, _frames, _time, _status: self._blocks.put(bytes(data)),
                    finished_callback=lambda: self._finished(generation),
                )
                stream.start()
            except sd.PortAudioError as exc:
                raise _open_error(self._device, exc) from exc
            self._stream = stream
            self._framer = _Framer(rate, channels)
            with self._blocks.changed:
                self._lost = False

    def _finished(self, generation: int) -> None:
        """PortAudio's word that a stream stopped: an error, or the device went away."""
        with self._blocks.changed:
            if generation == self._generation and not self._closed:
                self._lost = True
                self._blocks.changed.notify_all()

    def _close_stream(self) -> None:
        with self._stream_lock:
            stream, self._stream = self._stream, None
            self._generation += 1
        if stream is not None:
            with contextlib.suppress(Exception):  # a stream whose device is gone may refuse
                stream.close(ignore_errors=True)
        self._blocks.clear()

    def close(self) -> None:
        with self._blocks.changed:
            self._closed = True
            self._blocks.changed.notify_all()
        self._close_stream()


class _Speaker:
    """A PortAudio output device, opened for each utterance and found by name each time."""

    CHUNK = 0.1
    """Seconds written at a time, so that close() stops a long answer soon."""

    def __init__(self, device: _Device) -> None:
        self._device = device
        self.name = device.what
        self._closed = threading.Event()

    def play(self, pcm: bytes, sample_rate: int) -> None:
        sd = _portaudio()
        with _PORTAUDIO:
            index = self._device.index()
            if index is None:
                raise AudioError(f"{self.name} is gone ({list_hint()})")
            rate, channels = _layout(sd, index, "output", sample_rate)
            samples = np.frombuffer(pcm, "<i2")
            if rate != sample_rate:
                samples = soxr.resample(samples, sample_rate, rate)
            try:
                self._write(sd, index, rate, np.repeat(samples[:, None], channels, axis=1))
            except sd.PortAudioError as exc:
                raise _open_error(self._device, exc) from exc

    def _write(
        self, sd: ModuleType, index: int, rate: int, samples: np.ndarray[Any, np.dtype[np.int16]]
    ) -> None:
        """Play (n, channels) samples, a chunk at a time; return once heard, or closed."""
        channels = samples.shape[1]
        step = round(rate * self.CHUNK)
        with sd.RawOutputStream(
            device=index, samplerate=rate, channels=channels, dtype="int16"
        ) as stream:
            for start in range(0, len(samples), step):
                if self._closed.is_set():
                    stream.abort()
                    return
                stream.write(samples[start : start + step].tobytes())
            stream.stop()  # returns once the buffers have played

    def close(self) -> None:
        self._closed.set()


class _WavSink:
    """A WAV file that collects every utterance played, at the first one's rate."""

    def __init__(self, path: Path) -> None:
        if not path.parent.is_dir():
            raise AudioError(f"{path}: no such directory {str(path.parent)!r}")
        self._path = path
        self._file: Any = None

    def play(self, pcm: bytes, sample_rate: int) -> None:
        if self._file is None:
            self._file = soundfile.SoundFile(
                str(self._path), "w", samplerate=sample_rate, channels=1, subtype="PCM_16"
            )
        samples = np.frombuffer(pcm, "<i2")
        if sample_rate != self._file.samplerate:
            samples = soxr.resample(samples, sample_rate, self._file.samplerate)
        self._file.write(samples)
        self._file.flush()  # the header's sizes, so that a reader sees every utterance

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


# --- opening ----------------------------------------------------------------------------------


def open_source(spec: str, *, realtime: bool = True, device_rate: int | None = None) -> AudioSource:
    """The source `spec` names (module docstring); AudioError, one line, if it cannot be
    opened. `realtime` paces files as if spoken; `device_rate` opens a microphone at that
    rate instead of 16 kHz (or its own rate when it refuses 16 kHz)."""
    if spec == "-":
        return _PipeSource(sys.stdin.fileno(), "standard input")
    kind, _, name = spec.partition(":")
    if kind == "mic":
        return _Microphone(_find_device("input", name), device_rate)
    return _FileSource(Path(spec), realtime)


def open_sink(spec: str) -> AudioSink:
    """The sink `spec` names (module docstring); AudioError, one line, if it cannot be."""
    kind, _, name = spec.partition(":")
    if kind == "speaker":
        return _Speaker(_find_device("output", name))
    if kind == "file":
        return _WavSink(Path(name))
    if spec.lower().endswith(".wav"):
        return _WavSink(Path(spec))
    raise AudioError(f"unknown sound output {spec!r}; outputs: speaker[:NAME], file:PATH, X.wav")


def _first_line(exc: BaseException) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
