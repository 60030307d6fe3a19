"""Phrase checks (`CheckPhrase`) in turn, and only for askers still waiting.

A check runs the neural ear on up to four seconds of audio: a fraction of a second of
CPU, on cores the open sessions need. Checks run one at a time, off the event loop; a
few more may wait their turn, and past those the asker hears at once that the recogniser
is busy. A check whose asker has stopped waiting (`CheckPhrase.wait`), or would have by
the time it ran, is dropped before it runs: 300 checks asked at once with a 5 s timeout
used to keep the recogniser busy 12 s after the last asker had gone.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

from voicectl.shared.messages import CheckPhrase, Failed, Message, PhraseCheck
from voicectl.shared.throttle import Throttled

from .engine import EngineError

_LOGGER = logging.getLogger(__name__)

MAX_WAITING = 4
"""Checks that may wait for their turn; one more is told the recogniser is busy."""


class PhraseChecks:
    """Runs `check(pcm, phrase)` (an engine's, blocking) for one request at a time."""

    def __init__(
        self, check: Callable[[bytes, str], PhraseCheck], max_waiting: int = MAX_WAITING
    ) -> None:
        self._check = check
        self._max_waiting = max_waiting
        self._waiting = 0
        self._turn = asyncio.Lock()
        self._took = 0.0
        """Seconds the last check took: one with less time left than that is not begun."""
        self._noise = Throttled(_LOGGER)

    async def ask(self, request: CheckPhrase) -> Message:
        """The answer to `request`, or `Failed` saying why it was not checked."""
        if self._waiting >= self._max_waiting:
            self._noise.warning("busy", "phrase check refused: %d wait already", self._waiting)
            return Failed(
                reason=f"speech recognition is busy ({self._waiting} phrase checks wait): try again"
            )
        deadline = time.monotonic() + request.wait
        self._waiting += 1
        try:
            async with asyncio.timeout(request.wait):
                await self._turn.acquire()
        except TimeoutError:
            return self._dropped(request)
        finally:
            self._waiting -= 1
        try:
            if time.monotonic() + self._took > deadline:
                return self._dropped(request)
            started = time.monotonic()
            try:
                return await asyncio.to_thread(self._check, request.pcm, request.phrase)
            except EngineError as exc:
                return Failed(reason=str(exc))
            finally:
                self._took = time.monotonic() - started
                _LOGGER.debug("phrase check took %.2f s", self._took)
        finally:
            self._turn.release()

    def _dropped(self, request: CheckPhrase) -> Failed:
        """A check whose asker stops waiting before it could run: never run."""
        self._noise.warning(
            "gone",
            "phrase check dropped: its asker waits %g s, and its turn came too late",
            request.wait,
        )
        return Failed(reason=f"not checked: no turn within the {request.wait:g} s the asker waits")
