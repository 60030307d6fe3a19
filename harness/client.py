"""The tests' and the benchmarks' side of a robot: the supervisor protocol through
voicectl's own client, plus waits (`Client`), and the keys of the robot's graph a test's
own publisher or subscriber uses (`robot_key`)."""

from __future__ import annotations

import uuid
from collections.abc import Callable

from harness.wait import async_wait_until
from voicectl.shared.bus import Bus
from voicectl.shared.client import VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    GetHistory,
    GetState,
    HistoryPage,
    Message,
    Order,
    OrderRecord,
    State,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
)
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot.keys import RmwZenohKeys
from voicectl.shared.ros2 import RosDistro, dds_type_name, type_hash

STARTING = 45.0
"""Seconds a service started by a test has to come up: a bound, not a wait (a few on an
idle machine, twenty and more with two suites on two cores)."""


def robot_key(transport: TransportKind, name: str, ros_type: str, any_hash: bool = False) -> str:
    """The key a robot's graph on `transport` uses for topic `name` of `ros_type`, as a
    Jazzy robot announces it (or, `any_hash`, whatever its type hash): for a test's own
    publisher or subscriber."""
    match transport:
        case TransportKind.BRIDGE:
            return name
        case TransportKind.RMW_ZENOH:
            keys, dds = RmwZenohKeys(0), dds_type_name(ros_type)
            if any_hash:
                return keys.data_any_hash(name, dds)
            return keys.data(name, dds, type_hash(RosDistro.JAZZY, ros_type))
        case TransportKind.ROS2:
            # A plain ROS 2 robot speaks DDS, not Zenoh: its topics have no key.
            raise ValueError(
                f"topic {name!r} on ros2 has no Zenoh key; transports with keys: bridge, rmw-zenoh"
            )


class Client:
    """The test's side of the supervisor protocol: voicectl's own client, plus waits."""

    def __init__(self, bus: Bus, robot: str) -> None:
        self.bus = bus
        self.keys = RobotKeys(robot)
        self._client = VoicectlClient(bus)

    async def ask(self, request: Message) -> SupervisorReply:
        """The supervisor's reply as it is, a refusal (`Failed`) too."""
        return await self._client.request(self.keys.robot, request)

    async def ask_submit(self, *orders: Order) -> SupervisorReply:
        """Submit and return whatever the supervisor answers (a refusal too)."""
        return await self.ask(Submit(request_id=uuid.uuid4().hex, orders=list(orders)))

    async def submit(self, *orders: Order, request_id: str | None = None) -> list[str]:
        reply = await self.ask(
            Submit(request_id=request_id or uuid.uuid4().hex, orders=list(orders))
        )
        assert isinstance(reply, Submitted), reply
        return reply.order_ids

    async def state(self) -> State:
        reply = await self.ask(GetState())
        assert isinstance(reply, StateReply), reply
        return reply.state

    async def history(self, offset: int = 0, limit: int = 500) -> HistoryPage:
        reply = await self.ask(GetHistory(offset=offset, limit=limit))
        assert isinstance(reply, HistoryPage), reply
        return reply

    async def finished(self, order_id: str, timeout: float = 20.0) -> OrderRecord:
        found: list[OrderRecord] = []

        async def check() -> bool:
            found[:] = [r for r in (await self.history()).records if r.id == order_id]
            return bool(found)

        await async_wait_until(check, timeout, f"order {order_id} to finish")
        return found[0]

    async def wait_state(self, predicate: Callable[[State], bool], what: str) -> State:
        states: list[State] = []

        async def check() -> bool:
            states[:] = [state] if predicate(state := await self.state()) else []
            return bool(states)

        await async_wait_until(check, STARTING, what)
        return states[0]


async def client_wait_ready(client: Client, executor: bool = True) -> None:
    """Wait for the supervisor to answer, and (by default) to see its executor."""

    async def ready() -> bool:
        try:
            return (await client.state()).executor_online or not executor
        except BusError:
            return False  # supervisor not up yet

    await async_wait_until(ready, STARTING, "the supervisor (and its executor)")
