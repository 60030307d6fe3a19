"""voicectl across two hosts (`netns.TwoHosts`): the stack split between a host and a
robot, and the robot's odometry watched from its side. Used by tests/test_cross_host.py
and bench/cross_host.py."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from pathlib import Path

from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Odometry, Ros2Codec

from .netns import LEASE, LEASE_MS, Side, TwoHosts

ROBOT = "r1"


def start_stack(rig: TwoHosts, db: Path) -> None:
    """Routers on both sides, the supervisor on the host; executor and simulator on the
    robot. Every process has the short lease."""
    rig.start_router("host")
    rig.start_router("robot")
    local = ("--connect", rig.local_router(), *LEASE)
    supervisor = ("--robot", ROBOT, "--db", str(db))
    rig.start("host", "voicectl.services.supervisor", *local, *supervisor, name="supervisor")
    rig.start("robot", "voicectl.services.sim", *local, name="sim")
    rig.start("robot", "voicectl.services.executor", *local, "--robot", ROBOT, name="executor")


def observer(rig: TwoHosts, side: Side) -> BusOptions:
    """How a process outside both namespaces joins `side`'s router."""
    return BusOptions(connect=[rig.socket(side)], lease_ms=LEASE_MS)


class RobotWatch:
    """The simulator's odometry as read on the robot's side, with the monotonic time each
    message arrived."""

    def __init__(self, bus: Bus) -> None:
        self.odometry: list[tuple[float, Odometry]] = []
        bus.subscribe(RobotNames().odom, Ros2Codec().read_odometry, self._on_odometry)

    def _on_odometry(self, _key: str, odometry: Odometry) -> None:
        self.odometry.append((time.monotonic(), odometry))

    @property
    def last(self) -> Odometry:
        return self.odometry[-1][1]

    @staticmethod
    async def wait(condition: Callable[[], object], timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")
            await asyncio.sleep(0.01)

    async def ready(self, timeout: float = 30.0) -> None:
        await self.wait(lambda: self.odometry, timeout, "odometry from the simulator")

    async def moving(self, timeout: float = 30.0) -> None:
        await self.wait(
            lambda: self.odometry and abs(self.last.linear_x) > 0.2, timeout, "the robot to drive"
        )

    def still_since(self, moment: float) -> float | None:
        """When odometry first showed the robot standing after `moment`, or None."""
        return next(
            (
                at
                for at, odom in self.odometry
                if at > moment and odom.linear_x == 0.0 and odom.angular_z == 0.0
            ),
            None,
        )

    async def stopped(self, moment: float, timeout: float) -> float:
        """Seconds from `moment` until odometry showed the robot standing."""
        await self.wait(lambda: self.still_since(moment), timeout, "the robot to stop")
        stood = self.still_since(moment)
        assert stood is not None
        return stood - moment
