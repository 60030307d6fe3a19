"""Waiting for a condition with a bound, instead of sleeping and hoping: polled until it
holds, an AssertionError naming what was awaited once the bound has passed."""

from __future__ import annotations

import asyncio
import inspect
import time
from collections.abc import Callable


def wait_until(condition: Callable[[], object], timeout: float, what: str) -> None:
    """Poll `condition` until truthy; fail naming `what` after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


async def async_wait_until(condition: Callable[[], object], timeout: float, what: str) -> None:
    """Poll `condition` (a function, or a coroutine function, whose result is truthy once
    it holds) until it holds; AssertionError naming `what` after `timeout` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        held = condition()
        if inspect.isawaitable(held):
            held = await held
        if held:
            return
        await asyncio.sleep(0.02)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
