"""The tests' side of the supervisor protocol beyond harness/client.py (its `Client`), shared
by the supervisor test files: buses joined to a router, an executor driven from the
supervisor's seat, a site of processes, a stand-in executor."""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import uuid
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path
from typing import Any, TypeVar

from harness.client import Client, client_wait_ready
from harness.wait import async_wait_until
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Accepted,
    CancelOrder,
    ControlRequest,
    Execute,
    ExecutorEvent,
    ExecutorReply,
    Failed,
    GetState,
    Halt,
    Message,
    Order,
    OrderFinished,
    OrderRecord,
    OrderStatus,
    Running,
    State,
    StateReply,
    SupervisorRequest,
    TargetPose,
)
from voicectl.shared.robot import TransportKind, open_transport
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Odometry, Ros2Codec

from .conftest import Processes

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


def order(label: str, **params: Any) -> Order:
    return Order(order=label, label=label, description=f"do {label}", params=params)


TURN_LEFT = Order(
    order="rotation",
    label="rotate",
    description="turn left",
    target_pose=TargetPose(frame="base_link", yaw=1.57),
)
"""A quarter turn on the spot, closed on odometry by the `rotate` executor."""


class ExecutorHarness:
    """Sends orders straight to an executor, in the supervisor's seat, and keeps what it
    reports and the robot's odometry (with the loop time each arrived).

    The executor takes orders only from its robot's supervisor (services/executor/owner.py):
    the harness is one as far as that rule goes, a stand-in at the bus seam. It holds the
    robot's owner token and answers `GetState` on the robot's request key with the order
    it offers as the one it runs, and nothing else."""

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
        self.running: OrderRecord | None = None
        """The order it says it runs, as a supervisor would: the last one offered."""
        self.asked = 0
        """How many times the executor asked it (`GetState`)."""
        self.hold: asyncio.Event | None = None
        """While set and not set yet, its answers wait for it: an executor's check of who
        sent an order held in flight."""
        bus.announce(self.keys.supervisor_owner(str(bus.session.zid())))
        bus.serve(self.keys.supervisor, json_decoder(SupervisorRequest), self._as_supervisor)
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

    async def _as_supervisor(self, request: SupervisorRequest) -> Message:
        if isinstance(request, GetState):
            self.asked += 1
            state = State(robot=self.keys.robot, current=self.running)
            if self.hold is not None:
                await self.hold.wait()
            return StateReply(state=state)
        return Failed(reason="the tests' stand-in supervisor answers GetState only")

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
        self.running = OrderRecord(id=order_id, order=order, status=OrderStatus.RUNNING)
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
    processes.start("voicectl.services.sim", "--connect", router, *sim_args)
    processes.start(
        "voicectl.services.executor",
        "--connect",
        router,
        "--robot",
        "r1",
        "--photo-dir",
        str(photos),
        *executor_args,
    )


EXECUTORS = ["--executor", "harness.executors:Slow=slow"]
"""Executors the supervisor tests bind besides the built-in ones."""

ROBOT_GIVEN = ("--transport", "bridge", "--cmd-vel-type", "twist")
"""How to reach the robot, on the executor's command line as an integrator who knows it
would write it: an executor left to find out waits for a robot that says nothing (3 s for
the transport, 2 s for cmd_vel's type) before it is online, where no simulator runs.
tests/test_robot_dds.py checks that wait once."""


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
        self.supervisor = self.processes.supervisor(self.router, "r1", self.db, *extra)

    def kill_supervisor(self) -> None:
        assert self.supervisor is not None
        self.processes.kill(self.supervisor)

    def start_executor(self, robot: str = "r1") -> None:
        self.executors[robot] = self.processes.executor(
            self.router, robot, *EXECUTORS, *ROBOT_GIVEN
        )

    def kill_executor(self, robot: str = "r1") -> None:
        self.processes.kill(self.executors[robot])

    def joined(self) -> Bus:
        return joined(self.router)

    @contextlib.asynccontextmanager
    async def ready(self) -> AsyncIterator[Client]:
        """A supervisor and r1's executor started, and a client of r1 once it sees both."""
        self.start_supervisor()
        self.start_executor()
        with self.joined() as bus:
            client = Client(bus, "r1")
            await client_wait_ready(client)
            yield client

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
