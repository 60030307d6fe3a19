"""The always-on ear: pocketsphinx's keyphrase search, for the wake phrase and for "stop".

It runs on every frame of the robot's microphone, so it must be cheap: a keyphrase search
scores only the phrases' own phones against a phone loop (about 2 % of one core here), and
the heavier recognisers hear nothing until it fires. Each phrase has its own threshold: the
probability its phones must reach against the loop, lower for longer phrases.

Measured with `bench/wake.py` (docs/benchmarks.md): thresholds were chosen on the dev
voices and chatter, and reported on the test voices and on long speech that never says
the phrases.
"""

from __future__ import annotations

import math
import tempfile
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pocketsphinx

from voicectl.shared.errors import VoicectlError
from voicectl.shared.sound import Suppressor

SAMPLE_RATE = 16000
FRAME_SECONDS = 0.01
"""pocketsphinx's frame: the unit of the times it reports."""
RESTART_SECONDS = 30.0
"""The search restarts this often, so that its history stays small; the last
`OVERLAP_SECONDS` are heard again, so a phrase said across a restart is still found."""
OVERLAP_SECONDS = 2.0
WAKE_THRESHOLD = 1e-40
"""For a two-word wake phrase such as "hey robot" (chosen on the dev split)."""
QUIET_BEFORE = 0.3
LOUD = 6.0
"""dB above the room (the quietest tenth of the last 3 s) that make a 20 ms frame loud."""
LOUDNESS_FRAME = 0.02
"""Seconds of audio in each frame `Loudness` hears."""
WAKE_LOOP_PENALTY = 1e-6
"""pocketsphinx's phone-loop penalty (`kws_plp`, default 0.1) for the wake phrase: a
weaker rival lets more true phrases through (dev split, pink noise at 10 dB: 16 of 16
found where 0.1 found 11), and more false ones (2.9 a minute of speech where 0.1 gave
0.8), which the recogniser's neural ear then turns down (`CheckPhrase`)."""
STOP_LOOP_PENALTY = 0.1
SUPPRESSION = 2
"""WebRTC noise suppression before the search: on the dev split's voices in pink noise at
10 dB it found the wake phrase in 12 of 16 where the raw audio gave 8, and lost none clean;
level 3 found 10."""
STOP_THRESHOLD = 1e-10
"""For "stop" alone, one syllable: stricter than the wake phrase (chosen on the dev split)."""


class SpotterError(VoicectlError):
    """A phrase the spotter cannot listen for; the text says which and why."""


@dataclass(frozen=True)
class Phrase:
    text: str
    threshold: float


@dataclass(frozen=True)
class Spotted:
    """A phrase heard; times are seconds from the start of the stream."""

    phrase: str
    start: float
    end: float
    alone: bool = False
    """Nothing loud came in the `QUIET_BEFORE` seconds before it: said on its own, not
    inside a sentence ("... and then stop at the door")."""


class Loudness:
    """Which of the last 3 s of 20 ms frames were loud against the room: someone speaking."""

    def __init__(self) -> None:
        self._levels: deque[float] = deque(maxlen=150)
        self._loud: deque[tuple[float, bool, float]] = deque(maxlen=150)
        """(stream time, loud, level in dB) of the last 3 s of 20 ms frames."""

    @property
    def last_loud(self) -> float:
        """Stream time of the last loud frame heard, or -1."""
        return next((at for at, loud, _ in reversed(self._loud) if loud), -1.0)

    def hear(self, samples: npt.NDArray[np.int16], at: float) -> None:
        """One 20 ms frame of 16-bit samples, which starts at stream time `at`."""
        floats = samples.astype(np.float32)
        level = 10.0 * math.log10(float(np.mean(floats * floats)) + 1.0)
        self._levels.append(level)
        room = float(np.percentile(np.fromiter(self._levels, dtype=np.float32), 10))
        loud = len(self._levels) >= 10 and level > room + LOUD
        self._loud.append((at, loud, level))

    def last_loud_by(self, at: float) -> float:
        """Stream time of the last loud frame that began at or before `at`, or -1."""
        return next((t for t, loud, _ in reversed(self._loud) if loud and t <= at), -1.0)

    def level(self, start: float, end: float) -> float:
        """The median level in dB of the loud frames between `start` and `end` (a voice's
        own loudness), or infinity when none was loud."""
        levels = [level for at, loud, level in self._loud if loud and start <= at < end]
        return float(np.median(levels)) if levels else math.inf

    def quiet_run(self, after: float, seconds: float, below: float = -math.inf) -> float | None:
        """Stream time at which the first stretch of frames at least `seconds` long, each
        quiet against the room or at most `below` dB, that begins after `after` began;
        None while there is none."""
        begun: float | None = None
        for at, loud, level in self._loud:
            if at <= after or (loud and level > below):
                begun = None
            elif begun is None:
                begun = at
            if begun is not None and at + LOUDNESS_FRAME - begun >= seconds - 1e-6:
                return begun
        return None

    def speech_start(self, end: float, gap: float, earliest: float) -> float | None:
        """Where the speech that ends at `end` began: its first loud frame after a quiet
        stretch of `gap` seconds, no earlier than `earliest`; None when there is no such
        stretch since `earliest` (a room too loud for pauses to be heard in it)."""
        start, quiet = end, 0.0
        for at, loud, _ in reversed(self._loud):
            if at >= end:
                continue
            if at < earliest:
                return None
            if loud:
                start, quiet = at, 0.0
            else:
                quiet += LOUDNESS_FRAME
                if quiet >= gap - 1e-6:
                    return start
        return None

    def quiet_before(self, start: float) -> bool:
        """Nothing loud in the `QUIET_BEFORE` seconds before stream time `start`."""
        window = (start - QUIET_BEFORE, start - 0.05)
        return not any(loud for at, loud, _ in self._loud if window[0] <= at < window[1])


class Spotter:
    """Finds phrases in a stream of 16 kHz mono 16-bit audio, fed in pieces of any size."""

    def __init__(self, phrases: list[Phrase], loop_penalty: float = STOP_LOOP_PENALTY) -> None:
        if not phrases:
            raise SpotterError("no phrase to listen for")
        self._phrases = {phrase.text: phrase for phrase in phrases}
        with tempfile.TemporaryDirectory() as tmp:
            listing = Path(tmp) / "phrases.kws"
            listing.write_text(
                "".join(f"{p.text} /{p.threshold:.0e}/\n" for p in phrases), encoding="utf-8"
            )
            self._decoder: Any = pocketsphinx.Decoder(
                loglevel="FATAL", kws=str(listing), kws_plp=loop_penalty
            )
        for phrase in phrases:
            for word in phrase.text.split():
                if self._decoder.lookup_word(word) is None:
                    raise SpotterError(
                        f"phrase {phrase.text!r}: the word {word!r} is not in pocketsphinx's "
                        "English dictionary; choose words it knows"
                    )
        self._origin = 0.0
        """Seconds of the stream before the current search began."""
        self._fed = 0
        """Samples fed to the current search."""
        self._recent: deque[bytes] = deque()
        self._recent_bytes = 0
        self._heard_until = 0.0
        """Hits that end before this were found already (before a restart)."""
        self._suppressor = Suppressor(SUPPRESSION)
        self._loudness = Loudness()
        self._decoder.start_utt()

    @property
    def last_loud(self) -> float:
        """Stream time of the last loud frame heard (someone speaking), or -1."""
        return self._loudness.last_loud

    @property
    def clock(self) -> float:
        """Seconds of audio heard so far."""
        return self._origin + self._fed / SAMPLE_RATE

    def accept(self, pcm: bytes) -> list[Spotted]:
        """Hear `pcm` (whole samples); returns the phrases that ended in it."""
        found: list[Spotted] = []
        pcm = self._suppressor.process(pcm)
        for start in range(0, len(pcm), 640):
            piece = pcm[start : start + 640]
            self._loudness.hear(np.frombuffer(piece, dtype="<i2"), self.clock)
            self._remember(piece)
            self._decoder.process_raw(piece, False, False)
            self._fed += len(piece) // 2
            found += self._hits()
            if self._fed >= RESTART_SECONDS * SAMPLE_RATE:
                self._restart(keep=True)
        return found

    def skip(self, pcm_bytes: int) -> None:
        """Audio not heard (the microphone muted while the robot speaks): the clock runs
        on, and a phrase must start anew after it."""
        self._restart(keep=False)
        self._origin += pcm_bytes / 2 / SAMPLE_RATE

    def flush(self) -> list[Spotted]:
        """Phrases held back at the end of the stream: the search reports each at once."""
        return []

    def close(self) -> None:
        self._decoder.end_utt()

    def _hits(self) -> list[Spotted]:
        hypothesis = self._decoder.hyp()
        if hypothesis is None:
            return []
        found = []
        for segment in self._decoder.seg():
            start = self._origin + segment.start_frame * FRAME_SECONDS
            end = self._origin + (segment.end_frame + 1) * FRAME_SECONDS
            phrase = segment.word.strip()  # a keyphrase's segment ends with a space
            if phrase in self._phrases and end > self._heard_until:
                found.append(Spotted(phrase, start, end, self._loudness.quiet_before(start)))
                self._heard_until = end
        # A new search from here: the phrase's audio is not heard twice.
        self._decoder.end_utt()
        self._origin = self.clock
        self._fed = 0
        self._forget()
        self._decoder.start_utt()
        return found

    def _restart(self, keep: bool) -> None:
        self._decoder.end_utt()
        replay = b"".join(self._recent) if keep else b""
        self._origin = self.clock - len(replay) / 2 / SAMPLE_RATE
        self._fed = 0
        self._forget()
        self._decoder.start_utt()
        if replay:
            self._decoder.process_raw(replay, False, False)
            self._fed = len(replay) // 2
            self._remember(replay)
            # A hit in the replayed audio is reported by the next accept(), unless it was
            # reported before (it then ends before `_heard_until`).

    def _remember(self, piece: bytes) -> None:
        self._recent.append(piece)
        self._recent_bytes += len(piece)
        while self._recent_bytes - len(self._recent[0]) >= OVERLAP_SECONDS * SAMPLE_RATE * 2:
            self._recent_bytes -= len(self._recent.popleft())

    def _forget(self) -> None:
        self._recent.clear()
        self._recent_bytes = 0
