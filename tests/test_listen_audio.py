"""services/listen/audio_io.py: sound files, standard input, and a real sound device path
(PortAudio, ALSA's pulse plugin, a private PulseAudio whose null sink's monitor is the
microphone) carrying generated speech; the speaker; a sound server that goes and comes back."""

from __future__ import annotations

import contextlib
import ctypes.util
import io
import logging
import os
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import soundfile

from harness.pulse import PulseAudio, unavailable
from harness.wait import wait_until
from voicectl.services.listen.audio_io import (
    AudioError,
    AudioSource,
    list_devices,
    open_sink,
    open_source,
    rescan_devices,
)
from voicectl.shared.messages import FRAME_BYTES, SAMPLE_RATE

FRAME = FRAME_BYTES // 2
"""Samples in a 20 ms frame at 16 kHz."""


def _why_no_device() -> str | None:
    if ctypes.util.find_library("portaudio") is None:
        return "PortAudio is not installed (apt-get install libportaudio2)"
    return unavailable()


WHY_NO_DEVICE = _why_no_device()
# As the browser tests do: scripts/test installs the packages, so under CI a missing one fails.
needs_device = pytest.mark.skipif(
    WHY_NO_DEVICE is not None and not os.environ.get("CI"), reason=f"{WHY_NO_DEVICE}"
)


# --- audio to compare -------------------------------------------------------------------------


def envelope(samples: np.ndarray[Any, Any], rate: int) -> np.ndarray[Any, Any]:
    """The level of each 20 ms of mono samples."""
    size = rate // 50
    count = len(samples) // size
    blocks = samples[: count * size].astype(np.float64).reshape(count, size)
    return np.sqrt((blocks * blocks).mean(axis=1))


def pcm_envelope(pcm: bytes) -> np.ndarray[Any, Any]:
    return envelope(np.frombuffer(pcm, "<i2") / 32768.0, SAMPLE_RATE)


def file_envelope(path: Path) -> np.ndarray[Any, Any]:
    samples, rate = soundfile.read(str(path), always_2d=True)
    return envelope(samples.mean(axis=1), rate)


def best_match(reference: np.ndarray[Any, Any], heard: np.ndarray[Any, Any]) -> float:
    """The best correlation of `reference` with any stretch of `heard` as long: a device
    path delays the audio by an amount the test does not know."""
    heard = np.pad(heard, (0, max(0, len(reference) - len(heard))))
    ref = reference - reference.mean()

    def at(lag: int) -> float:
        part = heard[lag : lag + len(reference)]
        part = part - part.mean()
        return float(ref @ part / (np.linalg.norm(ref) * np.linalg.norm(part) + 1e-12))

    return max(at(lag) for lag in range(len(heard) - len(reference) + 1))


def read_all(source: AudioSource) -> bytes:
    chunks = []
    while (pcm := source.read()) is not None:
        assert pcm, "a read returned no frames"
        assert len(pcm) % FRAME_BYTES == 0, len(pcm)
        assert len(pcm) <= 50 * FRAME_BYTES
        chunks.append(pcm)
    return b"".join(chunks)


@pytest.fixture(scope="module")
def speech(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Generated speech as a microphone would not send it: 44.1 kHz stereo."""
    directory = tmp_path_factory.mktemp("listen")
    raw, wav = directory / "raw.wav", directory / "speech.wav"
    subprocess.run(
        ["espeak-ng", "-v", "en-us", "-s", "170", "-w", str(raw), "turn left and stop there"],
        check=True,
    )
    sox = ["sox", "-D", str(raw), "-r", "44100", "-c", "2", "-b", "16", str(wav)]
    subprocess.run([*sox, "pad", "0.3", "0.3"], check=True)
    return wav


def seconds_of(path: Path) -> float:
    info = soundfile.info(str(path))
    return float(info.frames / info.samplerate)


# --- files ------------------------------------------------------------------------------------


def test_a_file_comes_out_as_16khz_mono_frames(speech: Path) -> None:
    source = open_source(str(speech), realtime=False)
    pcm = read_all(source)
    source.close()
    assert abs(len(pcm) / FRAME_BYTES - seconds_of(speech) * 50) <= 1
    assert best_match(file_envelope(speech), pcm_envelope(pcm)) > 0.98


def test_a_file_is_paced_at_real_time(speech: Path) -> None:
    started = time.monotonic()
    source = open_source(str(speech))
    read_all(source)
    source.close()
    # A lower bound only: a busy machine makes it slower, never faster.
    assert time.monotonic() - started >= seconds_of(speech) - 0.1


def test_closing_wakes_a_paced_read(speech: Path) -> None:
    """A read waiting for its frame's time returns None once the source is closed, long
    before the file's end; at most the read under way when it closed still gives a frame."""
    source = open_source(str(speech))
    assert source.read() is not None
    closed = threading.Event()

    def close() -> None:
        closed.set()
        source.close()

    threading.Timer(0.05, close).start()
    frames, after_close = 1, 0
    while source.read() is not None:
        frames += 1
        after_close += closed.is_set()
    assert closed.is_set()
    assert after_close <= 1
    assert frames < seconds_of(speech) * 50 / 2, frames  # ended by the close, not the file
    source.close()  # again: idempotent


@pytest.mark.parametrize(
    ("name", "content", "says"),
    [
        ("missing.wav", None, "no such sound file"),
        ("notes.wav", b"turn left, then stop\n" * 20, "not a sound file"),
    ],
)
def test_an_unusable_file_is_one_line(
    tmp_path: Path, name: str, content: bytes | None, says: str
) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(AudioError) as raised:
        open_source(str(path))
    assert says in str(raised.value)
    assert name in str(raised.value)
    assert "\n" not in str(raised.value)


# --- standard input ---------------------------------------------------------------------------


@pytest.fixture
def stdin_pipe(monkeypatch: pytest.MonkeyPatch) -> Iterator[int]:
    """Standard input as a pipe; yields its writing end. A test may close that end; the
    teardown closes it only if the number still names this pipe (a closed number is soon
    another file's, maybe the next test's pipe)."""
    read_end, write_end = os.pipe()
    ours = os.fstat(write_end).st_ino
    reader = os.fdopen(read_end, "r")
    monkeypatch.setattr(sys, "stdin", reader)
    try:
        yield write_end
    finally:
        reader.close()  # a writer still blocked on the pipe gets EPIPE and ends
        with contextlib.suppress(OSError):
            if os.fstat(write_end).st_ino == ours:
                os.close(write_end)


def test_raw_pcm_on_standard_input_passes_unchanged(stdin_pipe: int) -> None:
    pcm = (np.sin(np.arange(16000 + 123) / 5.0) * 8000).astype("<i2").tobytes()

    def write() -> None:
        # In uneven pieces, as a pipe delivers them (odd bytes too).
        for start in range(0, len(pcm), 777):
            os.write(stdin_pipe, pcm[start : start + 777])
        os.close(stdin_pipe)

    writer = threading.Thread(target=write)
    writer.start()
    source = open_source("-")
    heard = read_all(source)
    writer.join()
    padded = pcm + bytes(-len(pcm) % FRAME_BYTES)
    assert heard == padded


@pytest.mark.parametrize("layout", [["-b", "16"], ["-b", "24"], ["-e", "floating-point"]])
def test_a_wav_stream_on_standard_input(stdin_pipe: int, speech: Path, layout: list[str]) -> None:
    """sox writing a WAV into a pipe, as `arecord -t wav` does: sizes unknown."""
    sox = subprocess.Popen(["sox", "-D", str(speech), *layout, "-t", "wav", "-"], stdout=stdin_pipe)
    os.close(stdin_pipe)
    source = open_source("-")
    heard = read_all(source)
    assert sox.wait(timeout=30) == 0
    assert abs(len(heard) / FRAME_BYTES - seconds_of(speech) * 50) <= 1
    assert best_match(file_envelope(speech), pcm_envelope(heard)) > 0.98


def test_closing_wakes_a_read_on_a_silent_pipe(stdin_pipe: int) -> None:
    source = open_source("-")
    threading.Timer(0.1, source.close).start()
    assert source.read() is None


def encoded(speech: Path, kind: str) -> bytes:
    """`speech` in a format standard input cannot decode (or not audio at all)."""
    match kind:
        case "random":
            return np.random.default_rng(7).integers(0, 256, 32000, dtype=np.uint8).tobytes()
        case "text":
            return ("voicectl listen - reads audio, and this is a sentence. " * 100).encode()
        case "mp3":  # libsndfile writes it without ID3 tags: a bare frame comes first
            out = io.BytesIO()
            soundfile.write(out, soundfile.read(str(speech))[0], SAMPLE_RATE, format="MP3")
            return out.getvalue()
    return subprocess.run(
        ["sox", "-D", str(speech), "-t", kind, "-"], capture_output=True, check=True
    ).stdout


def fed(stdin_pipe: int, data: bytes, close: bool = True) -> threading.Thread:
    """A writer of `data` into standard input (closed after it unless `close` is False).
    It writes through a descriptor of its own, so that, left blocked after its test, it
    can never write into a number the next test reuses."""
    own = os.dup(stdin_pipe)
    if close:  # the end of `data` is the end of the stream: only `own` keeps it open
        os.close(stdin_pipe)

    def write() -> None:
        # The reader may refuse the stream before it is all written: the pipe breaks.
        try:
            with contextlib.suppress(OSError):
                _write_all(own, data)
        finally:
            os.close(own)

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    return writer


def _write_all(fd: int, data: bytes) -> None:
    while data:
        data = data[os.write(fd, data) :]


@pytest.mark.parametrize(
    ("kind", "said"),
    [
        ("ogg", "an Ogg stream"),
        ("flac", "a FLAC stream"),
        ("mp3", "an MP3 stream"),
        ("aiff", "an AIFF stream"),
        ("au", "an AU stream"),
        ("random", "not audio"),
        ("text", "not audio"),
    ],
)
def test_what_standard_input_cannot_decode_is_named_and_refused(
    stdin_pipe: int, speech: Path, kind: str, said: str
) -> None:
    """Issue 43: Ogg, MP3, FLAC or random bytes on standard input were read as raw PCM,
    without a word. What a stream names itself is named; what is no microphone's is
    refused, in one line."""
    fed(stdin_pipe, encoded(speech, kind))
    source = open_source("-")
    with pytest.raises(AudioError) as raised:
        source.read()
    assert str(raised.value).startswith(f"standard input: {said}"), raised.value
    assert "\n" not in str(raised.value)


def test_raw_pcm_on_standard_input_is_said_to_be_taken_as_raw(
    stdin_pipe: int, speech: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Headerless speech, and the silence a muted microphone sends, are raw PCM: read,
    and the log says so."""
    raw = subprocess.run(
        ["sox", "-D", str(speech), "-t", "raw", "-"], capture_output=True, check=True
    ).stdout
    fed(stdin_pipe, bytes(3200) + raw)
    with caplog.at_level(logging.INFO):
        heard = read_all(open_source("-"))
    assert len(heard) >= len(raw)
    assert "standard input has no WAV header: read as raw" in caplog.text


def test_a_wav_chunk_that_declares_4_gb_is_refused_unread(stdin_pipe: int) -> None:
    """Issue 43: a chunk before the audio that declares 4 GB was read into memory. Chunks
    are read past, a piece at a time, and refused past 1 MiB before the audio."""
    header = b"RIFF" + struct.pack("<I", 0xFFFFFFFF) + b"WAVE"
    header += b"LIST" + struct.pack("<I", 0xFFFFFFF0)
    fed(stdin_pipe, header + bytes(32768), close=False)  # and the stream goes on
    source = open_source("-")
    outcome: list[BaseException | bytes | None] = []

    def read() -> None:
        try:
            outcome.append(source.read())
        except BaseException as exc:  # what the reader ended with
            outcome.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(30.0)
    source.close()
    assert outcome, "the reader is still reading the 4 GB chunk"
    (error,) = outcome
    assert isinstance(error, AudioError), error
    assert "'LIST' declares 4294967280 bytes" in str(error)


def test_a_broken_wav_on_standard_input_is_one_line_and_exit_2(tmp_path: Path, router: str) -> None:
    """Issue 43: a broken WAV header on standard input printed a traceback and exited 0;
    the same file named as the source said one line and exited 2. Both do now."""
    broken = b"RIFF" + struct.pack("<I", 100) + b"WAVEfmt " + struct.pack("<I", 16) + b"\x01\x00"
    (tmp_path / "broken.wav").write_bytes(broken)
    command = [sys.executable, "-m", "voicectl", "listen", "--connect", router]
    for source, given in ((str(tmp_path / "broken.wav"), b""), ("-", broken)):
        done = subprocess.run(
            [*command, source], input=given, capture_output=True, timeout=120, check=False
        )
        said = done.stderr.decode()
        assert done.returncode == 2, said
        (line,) = said.splitlines()
        assert line.startswith("voicectl listen: "), line


# --- a real sound device ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def pulse() -> Iterator[PulseAudio]:
    """A private PulseAudio for this module's tests (about 2 s to start)."""
    with PulseAudio() as daemon:
        yield daemon


@pytest.fixture
def device(pulse: PulseAudio, monkeypatch: pytest.MonkeyPatch) -> PulseAudio:
    """This process's PortAudio pointed at the private daemon."""
    for key, value in pulse.env.items():
        monkeypatch.setenv(key, value)
    rescan_devices()
    return pulse


class Capture:
    """A source read in a thread of its own, as the listener reads it."""

    def __init__(self, source: AudioSource) -> None:
        self.source = source
        self.chunks: list[bytes] = []
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while (pcm := self.source.read()) is not None:
            self.chunks.append(pcm)

    @property
    def heard(self) -> int:
        return sum(map(len, self.chunks))

    def more(self, seconds: float, timeout: float = 10.0) -> None:
        """Wait until `seconds` more audio has come."""
        want = self.heard + round(seconds * 50) * FRAME_BYTES
        wait_until(lambda: self.heard >= want, timeout, f"{seconds} s more audio")

    def stop(self) -> bytes:
        self.source.close()
        self._thread.join(timeout=5)
        assert not self._thread.is_alive(), "read did not return after close"
        return b"".join(self.chunks)


def hears(device: PulseAudio, capture: Capture, speech: Path) -> float:
    """Play `speech` into the sink; how well what `capture` heard since matches it."""
    capture.more(0.1)
    start = len(capture.chunks)
    device.play(speech)
    capture.more(0.3)
    return best_match(file_envelope(speech), pcm_envelope(b"".join(capture.chunks[start:])))


@needs_device
@pytest.mark.parametrize("rate", [None, 44100], ids=["16k", "44k1-resampled-here"])
def test_the_microphone_hears_what_the_sink_plays(
    device: PulseAudio, speech: Path, rate: int | None
) -> None:
    capture = Capture(open_source("mic", device_rate=rate))
    try:
        assert hears(device, capture, speech) > 0.8
    finally:
        pcm = capture.stop()
    assert len(pcm) % FRAME_BYTES == 0


@needs_device
def test_the_devices_are_listed(device: PulseAudio) -> None:
    devices = list_devices()
    default = [d for d in devices if d.is_default]
    assert [d.name for d in default] == ["default"], devices
    assert default[0].input_channels > 0
    assert default[0].host_api == "ALSA"
    assert "pulse" in {d.name for d in devices}


@needs_device
@pytest.mark.parametrize("name", ["nonexistent", "97"])
def test_a_missing_microphone_is_one_line(device: PulseAudio, name: str) -> None:
    with pytest.raises(AudioError) as raised:
        open_source(f"mic:{name}")
    text = str(raised.value)
    assert text.startswith(f"microphone '{name}' not found ("), text
    assert "--list-devices" in text
    assert "\n" not in text


@needs_device
def test_a_missing_speaker_is_one_line(device: PulseAudio) -> None:
    with pytest.raises(AudioError, match=r"^speaker 'nonexistent' not found \(.*--list-devices"):
        open_sink("speaker:nonexistent")


@needs_device
def test_the_speaker_plays_into_the_sink(device: PulseAudio) -> None:
    rate = 22050
    tone = (np.sin(2 * np.pi * 440 * np.arange(rate // 2) / rate) * 12000).astype("<i2")
    sink = open_sink("speaker")
    with device.recording() as recording:
        wait_until(lambda: recording.pcm, 5, "the capture to start")
        started = time.monotonic()
        sink.play(tone.tobytes(), rate)
        played_for = time.monotonic() - started
        after = len(recording.pcm) + SAMPLE_RATE // 5 * 2
        wait_until(lambda: len(recording.pcm) >= after, 5, "0.2 s of capture after the tone")
        heard = np.frombuffer(recording.pcm, "<i2") / 32768.0
    sink.close()
    assert played_for >= 0.45, "play returned before the tone was played"
    loud = envelope(heard, SAMPLE_RATE) > 0.1
    assert 0.4 <= loud.sum() / 50 <= 0.6, loud.sum()
    spectrum = np.abs(np.fft.rfft(heard))
    assert abs(np.argmax(spectrum) * SAMPLE_RATE / len(heard) - 440) < 5


@needs_device
def test_the_microphone_hears_on_after_the_speaker_played(device: PulseAudio, speech: Path) -> None:
    """As in `voicectl listen --speak`: one process reads the microphone while another thread
    plays its answers through the speaker (the same sink), and then someone else speaks
    into the sink. The microphone hears the answers and what comes after them."""
    samples, rate = soundfile.read(str(speech), dtype="int16", always_2d=True)
    answer = samples.mean(axis=1).astype("<i2").tobytes()
    capture = Capture(open_source("mic"))
    sink = open_sink("speaker")
    try:
        capture.more(0.1)
        start = len(capture.chunks)
        speaker = threading.Thread(target=lambda: [sink.play(answer, rate) for _ in range(2)])
        speaker.start()
        speaker.join(timeout=30)
        assert not speaker.is_alive(), "the speaker did not finish"
        capture.more(0.3)
        answers = pcm_envelope(b"".join(capture.chunks[start:]))
        assert best_match(file_envelope(speech), answers) > 0.8
        assert hears(device, capture, speech) > 0.8
    finally:
        sink.close()
        capture.stop()


def test_a_wav_sink_collects_every_utterance(tmp_path: Path) -> None:
    path = tmp_path / "said.wav"
    sink = open_sink(f"file:{path}")
    sink.play(bytes(2 * 16000), 16000)
    sink.play(bytes(2 * 22050), 22050)  # another rate: converted to the first one's
    sink.close()
    sink.close()
    info = soundfile.info(str(path))
    assert (info.samplerate, info.channels) == (16000, 1)
    assert abs(info.frames - 32000) <= 2


def test_an_unknown_sink_is_one_line() -> None:
    with pytest.raises(AudioError, match=r"^unknown sound output 'headphones'; outputs: "):
        open_sink("headphones")


# --- a device that goes and comes back --------------------------------------------------------


@needs_device
def test_the_microphone_comes_back_after_its_server_restarts(
    device: PulseAudio, speech: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="voicectl.services.listen.audio_io")
    capture = Capture(open_source("mic"))
    try:
        capture.more(0.2)
        device.stop()
        wait_until(lambda: "is gone" in caplog.text, 5, "the loss to be noticed")
        lost_at = capture.heard
        device.start()
        wait_until(lambda: "is back" in caplog.text, 10, "the microphone to be reopened")
        capture.more(0.2)
        assert capture.heard > lost_at
        assert hears(device, capture, speech) > 0.8
    finally:
        capture.stop()
        if not device.pactl_ok("info"):
            device.start()  # for the tests after this one
    assert caplog.text.count("is gone") == 1
    assert caplog.text.count("is back") == 1


@needs_device
def test_closing_wakes_a_read_waiting_for_a_gone_microphone(
    device: PulseAudio, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="voicectl.services.listen.audio_io")
    capture = Capture(open_source("mic"))
    try:
        capture.more(0.1)
        device.stop()
        wait_until(lambda: "is gone" in caplog.text, 5, "the loss to be noticed")
        started = time.monotonic()
        capture.stop()
        assert time.monotonic() - started < 2.0
    finally:
        device.start()
