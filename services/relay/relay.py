"""`voicectl relay`: the STOP relay of a robot on DDS, beside its executor.

A robot whose ROS 2 graph is on DDS (`voicectl executor --transport ros2`) is out of reach
of the processes that have Zenoh alone: the supervisor, the panel, `voicectl stop`. Their
stops go to the relay, a ROS 2 node of its own beside the executor, which serves the
robot's cmd_vel and its navigation's cancel_goal in zenoh-bridge-ros2dds' layout and
forwards to DDS what stops the robot and nothing else: a zero velocity (in every type the
robot's cmd_vel subscribers take), a cancel. A velocity that is not zero is dropped, so
the relay never becomes a way to drive the robot. It shares nothing with the executor:
the robot can be stopped while the executor is dead or its loop blocked. Nor does a stop
wait for the relay's own event loop: a zero velocity and a cancel go from Zenoh's thread
straight to DDS, and the cancel's answer comes back from rclpy's.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

from voicectl.shared.bus import Bus
from voicectl.shared.errors import BusError
from voicectl.shared.process import Service, forever
from voicectl.shared.robot import TransportKind, open_transport
from voicectl.shared.robot.action import CANCEL_TIMEOUT
from voicectl.shared.robot.bridge import BridgeTransport
from voicectl.shared.robot.dds import Ros2Transport
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import CANCEL_GOAL, CdrError, CmdVelType, Ros2Codec
from voicectl.shared.throttle import Throttled

_LOGGER = logging.getLogger(__name__)

NODE = "voicectl_stop_relay"
"""The ROS node the relay appears as on the robot's graph."""
READY_WAIT = 30.0
"""Seconds the relay waits for the robot before it says it reaches none."""
NAVIGATION_WAIT = 5.0
"""Seconds the relay waits, once cmd_vel is matched, for navigation's cancel service to
show before it says the robot has none (a robot without Nav2)."""
_TWIST_SIZE = 52
"""Bytes of a Twist's CDR: anything longer on cmd_vel is a TwistStamped."""


class StopRelay(Service):
    """Zero velocity and cancels from Zenoh (the bridge's keys) to the robot's DDS graph."""

    def __init__(self, bus: Bus, names: RobotNames, domain_id: int) -> None:
        self._bus = bus
        self._names = names
        self._domain_id = domain_id
        self._codec = Ros2Codec()
        self._noise = Throttled(_LOGGER)
        self._dds: Ros2Transport | None = None

    async def start(self) -> None:
        names = self._names
        dds = open_transport(self._bus, TransportKind.ROS2, NODE, names.namespace, self._domain_id)
        assert isinstance(dds, Ros2Transport)
        self._dds = dds
        # Made now, not at the first STOP: DDS delivers only once it has matched them.
        dds.client(names.navigate("cancel_goal"), CANCEL_GOAL)
        dds.discover(self._on_interface)
        # Both on Zenoh's thread, straight to DDS: a stop never waits for this loop.
        zenoh = open_transport(self._bus, TransportKind.BRIDGE, NODE)
        assert isinstance(zenoh, BridgeTransport)
        zenoh.subscribe_now(names.cmd_vel, bytes, self._on_velocity)
        zenoh.serve_now(names.navigate("cancel_goal"), self._on_cancel)

    async def run(self) -> None:
        """Say the relay is ready once DDS has matched it with the robot's cmd_vel
        subscribers and navigation's cancel service, or with cmd_vel alone where the robot
        shows no navigation within `NAVIGATION_WAIT` of that (stops relayed before go out
        all the same, but may reach no one)."""
        dds, names = self._dds, self._names
        assert dds is not None
        cancel = dds.client(names.navigate("cancel_goal"), CANCEL_GOAL)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + READY_WAIT
        while not self._matched():
            if loop.time() > deadline:
                _LOGGER.warning(
                    "after %g s the robot has no cmd_vel subscriber that this relay reaches "
                    "on DDS: is it up, in domain %d?",
                    READY_WAIT,
                    self._domain_id,
                )
                await forever()
            await asyncio.sleep(0.05)
        deadline = min(deadline, loop.time() + NAVIGATION_WAIT)
        while not cancel.service_is_ready():
            if loop.time() > deadline:
                break
            await asyncio.sleep(0.05)
        if cancel.service_is_ready():
            _LOGGER.info(
                "STOP relay ready: zero velocity to '%s', cancels to '%s'",
                names.cmd_vel,
                names.navigate("cancel_goal"),
            )
        else:
            _LOGGER.info(
                "STOP relay ready: zero velocity to '%s'; the robot shows no navigation to "
                "cancel ('%s' has no server; cancels go to it if one comes)",
                names.cmd_vel,
                names.navigate("cancel_goal"),
            )
        await forever()

    def _matched(self) -> bool:
        dds = self._dds
        assert dds is not None
        taken = [t for t in dds.subscriber_types(self._names.cmd_vel) if CmdVelType.of(t)]
        return bool(taken) and all(dds.matched(self._names.cmd_vel, t) for t in taken)

    async def stop(self) -> None:
        pass  # the transports close with the bus

    def _on_interface(self, interface: object, present: bool) -> None:
        """A cmd_vel subscriber of the robot: its publisher made before any STOP needs it."""
        dds = self._dds
        assert dds is not None
        for ros_type in dds.subscriber_types(self._names.cmd_vel):
            if CmdVelType.of(ros_type) is not None:
                dds.publisher(self._names.cmd_vel, ros_type)

    def _on_velocity(self, raw: bytes) -> None:
        kind = CmdVelType.TWIST if len(raw) == _TWIST_SIZE else CmdVelType.STAMPED
        try:
            velocity = self._codec.read_velocity(kind, raw)
        except CdrError as exc:
            self._noise.warning("unreadable", "dropped a velocity that does not decode: %s", exc)
            return
        if velocity != (0.0, 0.0):
            self._noise.warning("moving", "dropped a velocity that is not a stop: %s", velocity)
            return
        dds = self._dds
        assert dds is not None
        taken = [CmdVelType.of(t) for t in dds.subscriber_types(self._names.cmd_vel)]
        for wanted in [t for t in taken if t is not None] or [kind]:
            payload = self._codec.velocity(wanted, 0.0, 0.0)
            dds.publish(self._names.cmd_vel, wanted.ros_type, payload, urgent=True)
        _LOGGER.debug("zero velocity relayed at %.6f (monotonic)", time.monotonic())

    def _on_cancel(self, raw: bytes, reply: Callable[[bytes | None], None]) -> None:
        """On Zenoh's thread: the cancel goes to DDS at once; its answer goes back from
        rclpy's thread, or none if the robot gives none in time."""
        dds = self._dds
        assert dds is not None
        name = self._names.navigate("cancel_goal")
        _LOGGER.debug("cancel relayed at %.6f (monotonic)", time.monotonic())

        def answered(answer: bytes | None) -> None:
            if answer is None:
                self._noise.warning("cancel", "the robot did not answer a cancel in time")
            reply(answer)

        try:
            dds.call_now(name, CANCEL_GOAL, raw, CANCEL_TIMEOUT, answered)
        except BusError as exc:  # a request that does not decode
            self._noise.warning("cancel", "dropped a cancel: %s", exc)
            reply(None)
