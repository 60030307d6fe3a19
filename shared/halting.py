"""Stopping a robot on its bridge keys: the one implementation of "stop the robot".

Zero velocity on cmd_vel, then a cancel of every navigation goal, and what navigation
answered. The executor stops its robot with it, the supervisor on STOP and when the
executor is lost, and `voicectl stop` and the panel when no supervisor answers: whoever
is left alive can stop the robot the same way.

`zero_velocity` is a plain put: it may be called from any thread (a Zenoh callback, the
executor's watchdog), never waits for an event loop, and goes out at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import time
from dataclasses import dataclass

from .bus import Bus
from .errors import BusError
from .keys import BridgeKeys
from .messages import ExecutorInfo
from .ros2 import CANCEL_ALL, CancelCode, CdrError, CmdVelType, Ros2Codec, RosDistro

_LOGGER = logging.getLogger(__name__)

STOP_REPEAT = 3
"""Zero velocity is sent this many times: one lost sample must not leave the robot moving."""
CANCEL_TIMEOUT = 2.0
"""How long navigation has to answer a cancel."""


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
    """Build the codec that will stop the robot `info` announces, off the event loop, as
    soon as its executor announces it: not when someone presses STOP. Nobody has to
    keep or await the future."""

    def build() -> None:
        with contextlib.suppress(ValueError):  # RobotStop.of says what was wrong, later
            stop_codec(RosDistro(info.distro))

    building = asyncio.ensure_future(asyncio.to_thread(build))
    _BUILDING.add(building)
    building.add_done_callback(_BUILDING.discard)
    return building


@dataclass(frozen=True)
class RobotStop:
    """How to stop one robot: its bridge keys, its distribution, what cmd_vel takes."""

    keys: BridgeKeys
    codec: Ros2Codec
    cmd_vel_type: CmdVelType

    @classmethod
    def of(cls, info: ExecutorInfo, robot: str = "") -> RobotStop:
        """From what the executor announced; the defaults (with a warning) when it makes
        no sense, since a stop on the usual keys beats no stop."""
        try:
            keys = BridgeKeys(
                info.namespace, cmd_vel_name=info.cmd_vel, navigate_name=info.navigate
            )
            codec = stop_codec(RosDistro(info.distro))
            return cls(keys, codec, CmdVelType(info.cmd_vel_type))
        except ValueError as exc:
            _LOGGER.warning("%s: unusable executor info (%s); stopping on default keys", robot, exc)
            return cls(BridgeKeys(), stop_codec(RosDistro.JAZZY), CmdVelType.TWIST)

    def zero_velocity(self, bus: Bus) -> str:
        """Send zero velocity, first and at once; says where."""
        payload = self.codec.velocity(self.cmd_vel_type, 0.0, 0.0, time.time())
        for _ in range(STOP_REPEAT):
            bus.publish_bytes(self.keys.cmd_vel, payload, urgent=True)
        return f"sent zero velocity on '{self.keys.cmd_vel}'"

    async def cancel_goals(
        self, bus: Bus, goal_id: bytes | None = None, timeout: float = CANCEL_TIMEOUT
    ) -> Cancelled:
        """Cancel one navigation goal, or every goal; what navigation answered."""
        what = f"goal {goal_id.hex()[:8]}" if goal_id is not None else "every goal"
        request = self.codec.cancel_goal_request(goal_id or CANCEL_ALL)
        try:
            raw = await bus.request_bytes(
                self.keys.navigate("cancel_goal"), request, timeout, urgent=True
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

    def cancel_goals_now(self, bus: Bus) -> None:
        """Ask navigation to cancel every goal without waiting for its answer; from any
        thread (one whose event loop is stalled)."""
        bus.query_and_forget(
            self.keys.navigate("cancel_goal"), self.codec.cancel_goal_request(), CANCEL_TIMEOUT
        )

    async def halt(self, bus: Bus) -> Cancelled:
        """Zero velocity now, then every goal cancelled; the cancel's outcome, its detail
        prefixed with where the zero velocity went."""
        sent = self.zero_velocity(bus)
        cancelled = await self.cancel_goals(bus)
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
