"""The tests' side of the supervisor protocol, shared by the supervisor test files."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import subprocess
import uuid
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path
from typing import Any, TypeVar

from shared.bus import Bus, BusOptions, json_decoder
from shared.client import VoicectlClient
from shared.errors import BusError
from shared.keys import RmwZenohKeys, RobotKeys, RobotNames
from shared.messages import (
    Accepted,
    CancelOrder,
    ControlRequest,
    Execute,
    ExecutorEvent,
    ExecutorReply,
    GetHistory,
    GetState,
    Halt,
    HistoryPage,
    Message,
    Order,
    OrderFinished,
    OrderRecord,
    Running,
    State,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
    TargetPose,
)
from shared.robot import TransportKind, open_transport
from shared.ros2 import Odometry, Ros2Codec, RosDistro, dds_type_name, type_hash

from .conftest import Processes, async_wait_until

T = TypeVar("T")


def joined(where: str | BusOptions) -> Bus:
    """A bus joined to `where` (a router's endpoint, or options) on the running loop, to
    use as `with joined(router) as bus:` in an async test; closed whatever happens."""
    options = BusOptions(connect=[where]) if isinstance(where, str) else where
    return Bus.open(options, asyncio.get_running_loop())


def on_bus(where: str | BusOptions, body: Callable[[Bus], Coroutine[Any, Any, T]]) -> T:
    """Run `body` with a bus joined to `where`, in an event loop of its own: for the few
    synchronous places that need the bus (a listener class, a browser test whose thread
    Playwright's sync API holds, the compose test). Other tests are async: `joined`."""

    async def main() -> T:
        with joined(where) as bus:
            return await body(bus)

    return asyncio.run(main())


async def until_heard(bus: Bus, key: str, timeout: float = 10.0) -> None:
    """Wait until a subscriber on `key` in another session has reached the router, seen
    from `bus`: a publisher declared here matches it then. Instead of sleeping and hoping."""
    stream = bus.stream(key)
    try:
        assert await stream.matched(timeout), f"no subscriber on {key} reached the router"
    finally:
        stream.close()


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


STARTING = 45.0
"""Seconds a service started by a test has to come up: a bound, not a wait (a few on an
idle machine, twenty and more with two suites on two cores)."""


def order(label: str, **params: Any) -> Order:
    return Order(order=label, label=label, description=f"do {label}", params=params)


TURN_LEFT = Order(
    order="rotation",
    label="rotate",
    description="turn left",
    target_pose=TargetPose(frame="base_link", yaw=1.57),
)
"""A quarter turn on the spot, closed on odometry by the `rotate` executor."""


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


class ExecutorHarness:
    """Sends orders straight to an executor, in the supervisor's seat, and keeps what it
    reports and the robot's odometry (with the loop time each arrived)."""

    def __init__(
        self,
        bus: Bus,
        robot: str = "r1",
        names: RobotNames | None = None,
        transport: TransportKind = TransportKind.BRIDGE,
    ) -> None:
        self.bus = bus
        self.keys = RobotKeys(robot)
        self.names = names or RobotNames()
        self.transport = open_transport(bus, transport, "voicectl_test", self.names.namespace)
        """The robot's graph as the test sees it, on the robot's own transport."""
        self.events: dict[str, list[ExecutorEvent]] = {}
        self.odometry: list[tuple[float, Odometry]] = []
        self._decode = json_decoder(ExecutorReply)
        loop = asyncio.get_running_loop()
        bus.subscribe(self.keys.executor_events, json_decoder(ExecutorEvent), self._on_event)
        self.transport.subscribe(
            self.names.odom,
            "nav_msgs/msg/Odometry",
            Ros2Codec().read_odometry,
            lambda odom: self.odometry.append((loop.time(), odom)),
        )

    def _on_event(self, _key: str, event: ExecutorEvent) -> None:
        self.events.setdefault(event.order_id, []).append(event)

    async def ready(self) -> None:
        def up() -> bool:
            if not self.odometry:
                return False
            replies = self.bus.session.liveliness().get(self.keys.alive("executor"), timeout=1)
            return any(r.ok is not None for r in replies)

        await async_wait_until(up, 20.0, "the executor and the simulator")

    async def offer(self, order: Order) -> tuple[str, ExecutorReply]:
        """Send `order` for execution: its id and the executor's answer."""
        order_id = uuid.uuid4().hex[:12]
        reply = await self.bus.request(
            self.keys.executor_execute, Execute(order_id=order_id, order=order), self._decode
        )
        return order_id, reply

    async def execute(self, order: Order) -> str:
        order_id, reply = await self.offer(order)
        assert isinstance(reply, Accepted), reply
        return order_id

    async def control(self, request: CancelOrder | Halt) -> object:
        return await self.bus.request(self.keys.executor_control, request, self._decode)

    async def finished(self, order_id: str, timeout: float = 30.0) -> OrderFinished:
        def done() -> OrderFinished | None:
            return next(
                (e for e in self.events.get(order_id, []) if isinstance(e, OrderFinished)), None
            )

        await async_wait_until(done, timeout, f"order {order_id} to finish")
        result = done()
        assert result is not None
        return result

    def pose(self) -> Odometry:
        return self.odometry[-1][1]

    def since(self, moment: float) -> list[Odometry]:
        """Odometry that arrived after loop time `moment`."""
        return [odom for at, odom in self.odometry if at > moment]


@contextlib.asynccontextmanager
async def harness_on(
    router: str, names: RobotNames | None = None, transport: TransportKind = TransportKind.BRIDGE
) -> AsyncIterator[ExecutorHarness]:
    """A harness on a bus connected to `router`, once the executor and the robot are up."""
    with joined(router) as bus:
        harness = ExecutorHarness(bus, names=names, transport=transport)
        await harness.ready()
        yield harness


def start_robot(
    processes: Processes,
    router: str,
    photos: Path,
    sim_args: tuple[str, ...] = (),
    executor_args: tuple[str, ...] = (),
) -> None:
    """The simulator and an executor for robot 'r1' that saves photos in `photos`."""
    processes.start("services.sim", "--connect", router, *sim_args)
    processes.start(
        "services.executor",
        "--connect",
        router,
        "--robot",
        "r1",
        "--photo-dir",
        str(photos),
        *executor_args,
    )


EXECUTORS = ["--executor", "tests.executors_for_tests:Slow=slow"]
"""Executors the supervisor tests bind besides the built-in ones."""


class Site:
    """A router, a supervisor with a database that outlives it, executors per robot."""

    def __init__(self, router: str, processes: Processes, db: Path) -> None:
        self.router = router
        self.processes = processes
        self.db = db
        self.supervisor: subprocess.Popen[bytes] | None = None
        self.executors: dict[str, subprocess.Popen[bytes]] = {}

    def start_supervisor(self, *extra: str) -> None:
        """A supervisor serving r1 from the start (other robots once an executor comes)."""
        self.supervisor = self.processes.start(
            "services.supervisor",
            *("--connect", self.router, "--db", str(self.db), "--robot", "r1", *extra),
        )

    def kill_supervisor(self) -> None:
        assert self.supervisor is not None
        self.supervisor.send_signal(signal.SIGKILL)
        self.supervisor.wait()

    def start_executor(self, robot: str = "r1") -> None:
        self.executors[robot] = self.processes.start(
            "services.executor", "--connect", self.router, "--robot", robot, *EXECUTORS
        )

    def kill_executor(self, robot: str = "r1") -> None:
        self.executors[robot].send_signal(signal.SIGKILL)
        self.executors[robot].wait()

    def joined(self) -> Bus:
        return joined(self.router)

    def log(self) -> str:
        """What the supervisor started last has written so far."""
        assert self.supervisor is not None
        return self.processes.log(self.supervisor)


class StandIn:
    """The executor's two services on a session of the test's own, a stand-in at the bus
    seam: it accepts every order it is handed and keeps it in `taken`, with what
    `witness(order)` saw at that moment (the store's row of the order, say)."""

    def __init__(self, witness: Callable[[Execute], object] = lambda _execute: None) -> None:
        self.taken: asyncio.Queue[Execute] = asyncio.Queue()
        self.witnessed: dict[str, object] = {}
        self._witness = witness

    def serve(self, bus: Bus, keys: RobotKeys) -> None:
        bus.serve(keys.executor_execute, json_decoder(Execute), self._execute)
        bus.serve(keys.executor_control, json_decoder(ControlRequest), self._control)

    async def _execute(self, request: Execute) -> Message:
        self.witnessed[request.order_id] = self._witness(request)
        await self.taken.put(request)
        return Accepted(order_id=request.order_id)

    async def _control(self, request: ControlRequest) -> Message:
        return Running()
