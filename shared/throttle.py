"""Warnings that anyone on the bus can cause by the thousand (a malformed message on every
key, a flood of made-up robot names), said at most once per interval and kind."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

EVERY = 10.0
"""Seconds between two warnings of one kind."""


class Throttled:
    """Log a warning of a kind at most once every `every` seconds; the next one says how
    many of that kind were held back meanwhile. Kinds are few and fixed by the caller (a
    subscription's key expression, not a sample's key). Safe from any thread."""

    def __init__(
        self,
        logger: logging.Logger,
        every: float = EVERY,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._logger = logger
        self._every = every
        self._clock = clock
        self._lock = threading.Lock()
        self._said: dict[str, tuple[float, int]] = {}
        """Per kind: when it was last said, and how many were held back since."""

    def warning(self, kind: str, message: str, *args: object) -> None:
        now = self._clock()
        with self._lock:
            said, held = self._said.get(kind, (-self._every, 0))
            if now - said < self._every:
                self._said[kind] = (said, held + 1)
                return
            self._said[kind] = (now, 0)
        if held:
            message += f" ({held} more like it in the last {self._every:g} s not logged)"
        self._logger.warning(message, *args)
