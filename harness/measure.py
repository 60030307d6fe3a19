"""What the benchmarks measure with: percentiles and their report line, a process's CPU
time, the raw Zenoh put to subscriber time a figure is compared with, and a stopwatch at the
simulator (`Robot`). A process's memory is harness/processes.py's `rss_mb`."""

from __future__ import annotations

import asyncio
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from voicectl.shared.bus import Bus
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Ros2Codec

MOTION_WAIT = 5.0
"""Seconds an order may take to reach the simulator before it counts as lost."""


def percentile(values: list[float], share: float) -> float:
    """The sample `share` of the way up `values` (index int(share * n) of the sorted, the
    same in every benchmark); NaN when there are none."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(share * len(ordered)))] if ordered else float("nan")


def line(name: str, seconds: list[float], target: str = "") -> str:
    ms = [1e3 * s for s in seconds]
    return (
        f"{name:<44} p50 {percentile(ms, 0.5):7.1f}  p95 {percentile(ms, 0.95):7.1f}  "
        f"p99 {percentile(ms, 0.99):7.1f} ms  (n={len(ms)}){'  target ' + target if target else ''}"
    )


def cpu_seconds(pid: int) -> float:
    """CPU time (user and system) a process has used so far, from /proc (Linux)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def raw_latency(bus: Bus) -> list[float]:
    """Plain Zenoh put to subscriber through the same router: the transport's share."""
    loop = asyncio.get_running_loop()
    got: asyncio.Queue[float] = asyncio.Queue()

    def on_sample(_sample: object) -> None:  # on Zenoh's thread
        loop.call_soon_threadsafe(got.put_nowait, time.monotonic())

    subscriber = bus.session.declare_subscriber("bench/raw", on_sample)
    publisher = bus.session.declare_publisher("bench/raw")
    await asyncio.sleep(0.5)
    times = []
    for _ in range(200):
        sent = time.monotonic()
        publisher.put(b"x" * 900)
        times.append(await got.get() - sent)
    publisher.undeclare()
    subscriber.undeclare()
    return times


@dataclass
class Robot:
    """What the simulator was told, with the monotonic time it arrived (Zenoh's thread)."""

    moved: list[float] = field(default_factory=list)
    """Non-zero cmd_vel, and navigation status publications (a goal accepted or ended)."""
    zero: list[float] = field(default_factory=list)
    """Zero cmd_vel."""

    def listen(self, bus: Bus, keys: RobotNames | None = None) -> None:
        """Watch the robot of `keys` (the bridge's default namespace when none)."""
        codec, keys = Ros2Codec(), keys or RobotNames()

        def on_twist(_key: str, twist: tuple[float, float]) -> None:
            (self.zero if twist == (0.0, 0.0) else self.moved).append(time.monotonic())

        bus.subscribe(keys.cmd_vel, codec.read_twist, on_twist, on_loop=False)
        bus.subscribe(
            keys.navigate("status"),
            bytes,
            lambda _key, _raw: self.moved.append(time.monotonic()),
            on_loop=False,
        )

    @staticmethod
    async def first(times: list[float], after: float, timeout: float = MOTION_WAIT) -> float | None:
        """The first of `times` after `after`, waiting up to `timeout` for one."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = [t for t in times if t > after]
            if found:
                return min(found)
            await asyncio.sleep(0.001)
        return None
