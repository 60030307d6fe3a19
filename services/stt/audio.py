"""Audio as the recognisers want it: 16 kHz mono 16-bit PCM, from the bus or from files.

Two corrections happen before any engine sees the audio:

- A faint noise floor is added. Exact digital silence (a muted or finished fake microphone,
  padding added by sox) is not what an acoustic model was trained on: on generated speech
  padded with zeros, pocketsphinx's grammar search often ended early with a cut transcript
  ("reach" for "reach base"). About -60 dBFS of noise, far below any microphone's own
  noise, fixed it; the noise is seeded, so the same audio always decodes the same way.
- Files of any sample rate, sample format and channel count are converted: channels are
  averaged, the rate is changed by a windowed-sinc low-pass and linear interpolation.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from voicectl.shared.errors import AudioError
from voicectl.shared.messages import FRAME_BYTES, SAMPLE_RATE
from voicectl.shared.sound import Suppressor as Suppressor  # re-exported: moved to shared/
from voicectl.shared.sound import whole as whole

NOISE_FLOOR = 30.0
"""Standard deviation of the added noise, in 16-bit sample units (about -60 dBFS)."""
BYTES_PER_SECOND = SAMPLE_RATE * 2


class NoiseFloor:
    """Adds the same faint noise to every stream that starts from the same seed."""

    def __init__(self, seed: int = 0) -> None:
        self._random = np.random.default_rng(seed)

    def add(self, pcm: bytes) -> bytes:
        samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32)
        samples += self._random.normal(0.0, NOISE_FLOOR, samples.shape).astype(np.float32)
        return bytes(np.clip(np.rint(samples), -32768, 32767).astype("<i2").tobytes())


class Loudness:
    """Whether a frame stands out from the room: louder by `margin` dB than the quietest
    tenth of the last `window` frames. A voice activity detector calls steady noise and
    babble speech; what is no louder than the room around it is not the person."""

    def __init__(self, margin: float, window: int, needed: int) -> None:
        self._margin = margin
        self._levels: deque[float] = deque(maxlen=window)
        self._needed = needed
        """Frames heard before the room's level is known; until then nothing stands out."""

    def spread(self) -> float:
        """dB between the loudest and the quietest tenth of the window: about 40 in a quiet
        room with someone speaking, under 20 with noise 10 to 15 dB below the voice."""
        if len(self._levels) < self._needed:
            return math.inf
        levels = np.fromiter(self._levels, dtype=np.float32)
        return float(np.percentile(levels, 90) - np.percentile(levels, 10))

    def stands_out(self, pcm: bytes) -> bool:
        samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32)
        level = 10.0 * math.log10(float(np.mean(samples * samples)) + 1.0)
        self._levels.append(level)
        if len(self._levels) < self._needed:
            return False
        room = float(np.percentile(np.fromiter(self._levels, dtype=np.float32), 10))
        return level > room + self._margin


def seconds(pcm_bytes: int) -> float:
    return pcm_bytes / BYTES_PER_SECOND


def frames(pcm: bytes) -> list[bytes]:
    """`pcm` cut into 20 ms frames (the last one zero-padded), as a microphone sends them."""
    padded = pcm + b"\0" * (-len(pcm) % FRAME_BYTES)
    return [padded[i : i + FRAME_BYTES] for i in range(0, len(padded), FRAME_BYTES)]


def read_wav(path: Path) -> bytes:
    """A sound file's audio as 16 kHz mono 16-bit PCM; raises AudioError saying why not.

    libsndfile (through `soundfile`) reads every WAV flavour (8 to 32-bit, float,
    extensible headers) and FLAC or Ogg too; the standard `wave` module reads only plain
    integer PCM.
    """
    import soundfile

    try:
        samples, rate = soundfile.read(str(path), dtype="float64", always_2d=True)
    except (OSError, RuntimeError, soundfile.LibsndfileError) as exc:
        raise AudioError(f"{path}: cannot read as audio: {exc}") from exc
    mono = samples.mean(axis=1)
    if rate != SAMPLE_RATE:
        mono = resample(mono, rate, SAMPLE_RATE)
    return bytes(np.clip(np.rint(mono * 32768.0), -32768, 32767).astype("<i2").tobytes())


def read_blocks(path: Path, seconds: float = 1.0) -> Iterator[bytes]:
    """A sound file's audio as 16 kHz mono 16-bit PCM, `seconds` at a time, so that a file
    of any length is heard in bounded memory; AudioError saying why not. Resampled by
    soxr's streaming resampler when the file has another rate."""
    import soundfile

    try:
        sound = soundfile.SoundFile(str(path))
    except (OSError, RuntimeError, soundfile.LibsndfileError) as exc:
        raise AudioError(f"{path}: cannot read as audio: {exc}") from exc
    with sound:
        resampler: Any = None
        if sound.samplerate != SAMPLE_RATE:
            import soxr

            resampler = soxr.ResampleStream(sound.samplerate, SAMPLE_RATE, 1, "float32")
        size = max(1, int(seconds * sound.samplerate))
        try:
            while len(block := sound.read(size, dtype="float32", always_2d=True)):
                last = len(block) < size
                mono = np.ascontiguousarray(block.mean(axis=1, dtype=np.float32))
                if resampler is not None:
                    mono = resampler.resample_chunk(mono, last=last)
                yield bytes(np.clip(np.rint(mono * 32768.0), -32768, 32767).astype("<i2").tobytes())
                if last:
                    return
            if resampler is not None:
                tail = resampler.resample_chunk(np.zeros(0, np.float32), last=True)
                yield bytes(np.clip(np.rint(tail * 32768.0), -32768, 32767).astype("<i2").tobytes())
        except (RuntimeError, soundfile.LibsndfileError) as exc:
            raise AudioError(f"{path}: cannot read as audio: {exc}") from exc


def resample(samples: np.ndarray, rate: int, target: int) -> np.ndarray:
    """Change the sample rate; going down, a low-pass at 0.45 of the new rate comes first."""
    if len(samples) == 0:
        return samples
    if target < rate:
        cutoff = 0.45 * target / rate  # in cycles per input sample
        taps = np.arange(-32, 33)
        kernel = 2 * cutoff * np.sinc(2 * cutoff * taps) * np.hamming(len(taps))
        samples = np.convolve(samples, kernel / kernel.sum(), mode="same")
    duration = len(samples) / rate
    times = np.arange(int(duration * target)) / target
    result: np.ndarray = np.interp(times, np.arange(len(samples)) / rate, samples)
    return result
