"""Sound helpers that more than one service needs (the recogniser and the listener)."""

from __future__ import annotations

from collections.abc import Iterator

from .messages import FRAME_BYTES


class Suppressor:
    """WebRTC's noise suppression over a stream (PyPI `webrtc-noise-gain`), in 10 ms steps:
    it follows the noise as the stream goes, so it hears every frame, speech or not."""

    STEP = FRAME_BYTES // 2

    def __init__(self, level: int) -> None:
        from webrtc_noise_gain import AudioProcessor

        self._processor = AudioProcessor(0, level)  # 0: no automatic gain
        self._pending = bytearray()

    def process(self, pcm: bytes) -> bytes:
        """The same audio with less noise, as many bytes as whole 10 ms steps make; what
        is left comes out with the next call."""
        self._pending += pcm
        steps = whole(self._pending, self.STEP)
        return b"".join(self._processor.Process10ms(step).audio for step in steps)


def whole(pending: bytearray, size: int) -> Iterator[bytes]:
    """Take every whole `size`-byte piece off the front of `pending`, in order."""
    while len(pending) >= size:
        piece = bytes(pending[:size])
        del pending[:size]
        yield piece
