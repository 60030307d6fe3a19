"""Stopping a robot: the one implementation of "stop the robot", on any transport.

Zero velocity on cmd_vel, then a cancel of every navigation goal, and what navigation
answered. The executor stops its robot with it, the supervisor on STOP and when the
executor is lost, and `voicectl stop` and the panel when no supervisor answers: whoever
is left alive can stop the robot the same way, through the bridge or on rmw_zenoh.

`zero_velocity` is a plain put: it may be called from any thread (a Zenoh callback, the
executor's watchdog), never waits for an event loop, and goes out at once.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from dataclasses import dataclass

from ..bus import Bus
from ..errors import BusError
from ..keys import RobotNames
from ..messages import ExecutorInfo
from ..ros2 import (
    CANCEL_ALL,
    CANCEL_GOAL,
    CancelCode,
    CdrError,
    CmdVelType,
    Ros2Codec,
    RosDistro,
    type_hash,
)
from . import open_transport
from .kinds import TransportKind
from .transport import RobotTransport

_LOGGER = logging.getLogger(__name__)

STOP_REPEAT = 3
"""Zero velocity is sent this many times: one lost sample must not leave the robot moving."""
CANCEL_TIMEOUT = 2.0
"""How long navigation has to answer a cancel."""
NODE = "voicectl_stop"
"""The ROS node a process that only stops a robot appears as, where nodes are seen."""


@functools.cache
def stop_codec(distro: RosDistro) -> Ros2Codec:
    """The codec that stops robots of `distro`, shared, with its stop messages encoded
    once: building a distribution's types and their encoders costs about 0.1 s, which
    the first STOP of a process paid before anything went out (bench/e2e.py)."""
    codec = Ros2Codec(distro)
    for kind in CmdVelType:
        codec.velocity(kind, 0.0, 0.0, 0.0)
    codec.cancel_goal_request(CANCEL_ALL)
    return codec


_BUILDING: set[asyncio.Future[None]] = set()
"""Builds under way: the loop keeps only weak references to them."""


def prepare(info: ExecutorInfo) -> asyncio.Future[None]:
    """Build what will stop the robot `info` announces (its codec; on rmw_zenoh the type
    hashes in its keys), off the event loop, as soon as its executor announces it: not
    when someone presses STOP. Nobody has to keep or await the future."""

    def build() -> None:
        stop_codec(info.distro)
        if info.transport is TransportKind.RMW_ZENOH:
            type_hash(info.distro, info.cmd_vel_type.ros_type)
            type_hash(info.distro, CANCEL_GOAL)

    building = asyncio.ensure_future(asyncio.to_thread(build))
    _BUILDING.add(building)
    building.add_done_callback(_BUILDING.discard)
    return building


@dataclass(frozen=True)
class RobotStop:
    """How to stop one robot: its transport and names, its distribution, what cmd_vel takes."""

    transport: RobotTransport
    names: RobotNames
    codec: Ros2Codec
    cmd_vel_type: CmdVelType

    @classmethod
    def of(cls, info: ExecutorInfo, bus: Bus, node: str = NODE) -> RobotStop:
        """From what the executor announced; names that make no sense fall back to the
        defaults (with a warning), since a stop on the usual names beats no stop."""
        try:
            names = RobotNames(
                info.namespace, cmd_vel_name=info.cmd_vel, navigate_name=info.navigate
            )
        except ValueError as exc:
            _LOGGER.warning("unusable executor info (%s); stopping on default names", exc)
            names = RobotNames()
        transport = open_transport(
            bus, info.transport, node, names.namespace, info.domain_id, info.distro
        )
        return cls(transport, names, stop_codec(info.distro), info.cmd_vel_type)

    def zero_velocity(self) -> str:
        """Send zero velocity, first and at once; says where."""
        payload = self.codec.velocity(self.cmd_vel_type, 0.0, 0.0, time.time())
        for _ in range(STOP_REPEAT):
            self.transport.publish(
                self.names.cmd_vel, self.cmd_vel_type.ros_type, payload, urgent=True
            )
        return f"sent zero velocity on '{self.names.cmd_vel}'"

    async def cancel_goals(
        self, goal_id: bytes | None = None, timeout: float = CANCEL_TIMEOUT
    ) -> Cancelled:
        """Cancel one navigation goal, or every goal; what navigation answered."""
        what = f"goal {goal_id.hex()[:8]}" if goal_id is not None else "every goal"
        request = self.codec.cancel_goal_request(goal_id or CANCEL_ALL)
        try:
            raw = await self.transport.call(
                self.names.navigate("cancel_goal"), CANCEL_GOAL, request, timeout, urgent=True
            )
        except BusError as exc:
            return Cancelled(
                False, False, f"navigation did not answer the cancel of {what} ({exc})"
            )
        try:
            code = self.codec.read_cancel_goal_response(raw).return_code
        except CdrError as exc:
            return Cancelled(
                True, False, f"navigation's answer to the cancel does not decode: {exc}"
            )
        match code:
            case CancelCode.REJECTED:
                return Cancelled(True, False, f"navigation refused to cancel {what}")
            case CancelCode.UNKNOWN_GOAL_ID:
                return Cancelled(True, True, "navigation had no goal to cancel")
            case CancelCode.GOAL_TERMINATED:
                return Cancelled(True, True, "navigation's goals had already ended")
            case _:
                return Cancelled(True, True, f"navigation cancelled {what}")

    def cancel_goals_now(self) -> None:
        """Ask navigation to cancel every goal without waiting for its answer; from any
        thread (one whose event loop is stalled)."""
        self.transport.call_and_forget(
            self.names.navigate("cancel_goal"),
            CANCEL_GOAL,
            self.codec.cancel_goal_request(),
            CANCEL_TIMEOUT,
        )

    async def halt(self) -> Cancelled:
        """Zero velocity now, then every goal cancelled; the cancel's outcome, its detail
        prefixed with where the zero velocity went."""
        sent = self.zero_velocity()
        cancelled = await self.cancel_goals()
        return Cancelled(cancelled.answered, cancelled.confirmed, f"{sent}; {cancelled.detail}")


@dataclass(frozen=True)
class Cancelled:
    """What navigation said to a cancel."""

    answered: bool
    """Navigation answered at all (a robot without Nav2 never does)."""
    confirmed: bool
    """Nothing it was asked to cancel goes on: cancelled, unknown or already ended."""
    detail: str
    """In one line, for a person."""
