"""Notices an executor process whose event loop has stalled.

A user's `execute` that blocks (`time.sleep` where `await asyncio.sleep` belonged, a
blocking HTTP call) stalls every order, cancel and result of the process with it. A thread
of its own asks the loop for a heartbeat every `BEAT` seconds; when none has come for
`limit` seconds, it calls `on_stall` from that thread, once per stall, and `on_recover`
on the loop when the loop runs again.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable

_LOGGER = logging.getLogger(__name__)

BEAT = 0.05
"""Seconds between two heartbeats asked of the loop."""


class LoopWatchdog:
    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        limit: float,
        on_stall: Callable[[float], None],
        on_recover: Callable[[float], None],
    ) -> None:
        self._loop = loop
        self._limit = limit
        self._on_stall = on_stall
        self._on_recover = on_recover
        self._last_beat = time.monotonic()
        self._stalled_since: float | None = None
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._watch, name="loop-watchdog", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stopping.set()
        self._thread.join()

    def _beat(self) -> None:  # on the loop
        now = time.monotonic()
        self._last_beat = now
        stalled = self._stalled_since
        if stalled is not None:
            self._stalled_since = None
            self._on_recover(now - stalled)

    def _watch(self) -> None:
        while not self._stopping.wait(BEAT):
            try:
                self._loop.call_soon_threadsafe(self._beat)
            except RuntimeError:  # the loop has closed: nothing left to watch
                return
            silent = time.monotonic() - self._last_beat
            if silent > self._limit and self._stalled_since is None:
                self._stalled_since = self._last_beat
                try:
                    self._on_stall(silent)
                except Exception:
                    _LOGGER.exception("the stall handler failed")
