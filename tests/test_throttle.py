"""Warnings said at most once per interval and kind."""

from __future__ import annotations

import logging

import pytest

from voicectl.shared.throttle import Throttled


def test_a_kind_is_said_once_per_interval_then_with_how_many_were_held_back(
    caplog: pytest.LogCaptureFixture,
) -> None:
    now = [100.0]
    throttled = Throttled(logging.getLogger("test.throttle"), every=10.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="test.throttle"):
        for n in range(1000):
            throttled.warning("junk", "dropped %d", n)
        throttled.warning("other", "another kind")
        now[0] += 10.0
        throttled.warning("junk", "dropped %d", 1000)
    assert [r.getMessage() for r in caplog.records] == [
        "dropped 0",
        "another kind",
        "dropped 1000 (999 more like it in the last 10 s not logged)",
    ]
