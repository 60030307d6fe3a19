"""The person speaking, told from the room by loudness: the speaker is the loudest voice.

The endpointer (sphinx.py) ends an utterance when the sound falls back to the room's own
level, which it learns from the frames outside utterances (`Background`): in a room where
others talk on, the voice activity detector hears speech everywhere and the room's
quietest tenth lies far below the other voices, so without it an utterance never ended
while they talked. (Telling the speaker's words from others' by each word's loudness, with
Whisper's word times, was measured on the dev split and left out: docs/benchmarks.md.)
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

BACKGROUND_WINDOW = 100
"""Frames outside utterances remembered (3 s of 30 ms frames)."""
BACKGROUND_NEEDED = 10
"""Frames heard before the background is known; until then it holds nothing back."""
BACKGROUND_PERCENTILE = 50.0
BACKGROUND_MARGIN = 3.0
"""A frame of an utterance counts as speech only above this many dB over the median of
the background. Chosen on the dev split of harness/speech_set.py with the room going on
after the speech (docs/benchmarks.md): in four-talker babble 10 dB below the speaker,
utterances without it did not end while the babble went on; with it they ended 0.12 s
after the speech (p50; p95 0.31 s), and clean speech and pink noise were cut exactly as
before."""


def level(pcm: bytes) -> float:
    """A frame's energy in dB (of 16-bit samples; silence about 0, full scale about 90)."""
    samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32)
    if not len(samples):
        return 0.0
    return 10.0 * math.log10(float(np.mean(samples * samples)) + 1.0)


class Background:
    """The level of the room while nobody speaks to the recogniser: frames outside
    utterances, including other people's voices when they talk on."""

    def __init__(
        self,
        window: int = BACKGROUND_WINDOW,
        needed: int = BACKGROUND_NEEDED,
        percentile: float = BACKGROUND_PERCENTILE,
        margin: float = BACKGROUND_MARGIN,
    ) -> None:
        self._levels: deque[float] = deque(maxlen=window)
        self._needed = needed
        self._percentile = percentile
        self._margin = margin
        self._threshold = -math.inf

    def hear(self, frame_level: float) -> None:
        """A frame outside any utterance."""
        self._levels.append(frame_level)
        if len(self._levels) >= self._needed:
            room = float(np.percentile(np.fromiter(self._levels, np.float32), self._percentile))
            self._threshold = room + self._margin

    def above(self, frame_level: float) -> bool:
        """Whether a frame stands above the background (True while it is not yet known)."""
        return frame_level > self._threshold
