"""A robot under every fault STOP must beat, and a stopwatch at the simulator.

One simulated robot with its supervisor and executor as processes on a router; the
executor also serves the faulty executors of harness/executors.py. `run(case)`
puts the robot in motion the way the case says (a healthy navigation, an executor that
blocks its loop, one that commands from a blocked loop, one that swallows its cancel,
processes killed, a long queue), sends STOP through `VoicectlClient.stop` (what the panel
and `voicectl stop` use), and measures, from the moment STOP is asked:

- the first zero velocity on cmd_vel, and for a navigation the goal's end in the status
  the simulator publishes when it handles the cancel, each timed on arrival (Zenoh's
  thread), one hop from the simulator like the robot itself; on rmw_zenoh, zero velocity
  is heard only where the robot's own subscription would hear it: on the key its
  liveliness token announces (its type and type hash), as rmw_zenoh subscribes;
- the motion afterwards: how far the robot moved from `SETTLE` to `WATCH` seconds after
  STOP, and whether any odometry after `SETTLE` shows velocity (the benchmarks' figures);
  and, whatever the time it took, whether the robot came to a stand once it was told to
  stop, and moved no more (the tests' condition).

Used by tests/test_stop.py (one round per case, waiting for conditions) and by
bench/stop.py and bench/stop_transports.py (many rounds, percentiles).
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import math
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from harness.client import robot_key
from harness.processes import Processes
from harness.wait import async_wait_until
from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.client import VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.messages import (
    GetState,
    Order,
    OrderRecord,
    ParamValue,
    Release,
    StateReply,
    Stopped,
    Submit,
    TargetPose,
)
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot.keys import RmwKind, RmwZenohKeys, RobotNames
from voicectl.shared.ros2 import CmdVelType, Odometry, Ros2Codec, ros_type_of

ROBOT = "r1"
CODEC = Ros2Codec()
SETTLE = 0.3
"""Seconds after STOP from which the robot must stand still."""
WATCH = 1.5
"""Seconds after STOP until which it is watched for motion."""
HOLD = WATCH - SETTLE
"""Seconds it is watched for at least once it was told to stop, however late that was."""
WAIT = 30.0
FAULT_SECONDS = 4.0
"""How long the faulty executors of `blocked-loop` and `commanding-from-blocked-loop` block
their loop: a STOP that waited for that loop would reach the robot this late."""
EXECUTORS = (
    "harness.executors:BlockingNavigator",
    "harness.executors:BlockedDriver",
    "harness.executors:Runaway",
)
CASES = (
    "healthy",
    "blocked-loop",
    "commanding-from-blocked-loop",
    "swallowed-cancel",
    "executor-killed",
    "supervisor-and-executor-killed",
    "50-queued",
)
NAVIGATING = {
    "healthy",
    "blocked-loop",
    "executor-killed",
    "supervisor-and-executor-killed",
    "50-queued",
}


@dataclass(frozen=True)
class Outcome:
    case: str
    stopped: Stopped
    zero_velocity: float
    """Seconds from STOP to the first zero velocity at the simulator's side of the bus."""
    cancelled: float | None
    """Seconds from STOP to the goal's end in the simulator's status (navigation only)."""
    moved: float
    """Metres the robot moved from SETTLE to WATCH after STOP."""
    fastest_after: float
    """The highest speed any odometry showed after SETTLE."""
    stood: float
    """Seconds from STOP to the first odometry at a stand once the robot was told to stop
    (zero velocity, and the goal's end for a navigation); inf if it never stood."""
    moved_standing: float
    """Metres the robot moved from then on, while watched (inf if it never stood)."""
    fastest_standing: float
    """The highest speed any odometry showed from then on (inf if it never stood)."""

    @property
    def latency(self) -> float:
        """STOP to the robot told to stop: the later of the two for a navigation."""
        return max(self.zero_velocity, self.cancelled or 0.0)


async def ended(
    client: VoicectlClient, matches: Callable[[OrderRecord], bool], what: str
) -> OrderRecord:
    """The first finished order in the robot's history that `matches`, once there is one."""
    found: list[OrderRecord] = []

    async def there() -> bool:
        reply = await client.ask(ROBOT, GetState())
        assert isinstance(reply, StateReply)
        found[:] = [r for r in reply.state.history if matches(r)]
        return bool(found)

    await async_wait_until(there, 20.0, what)
    return found[0]


def order(label: str, **params: ParamValue) -> Order:
    return Order(order=label, label=label, description=f"do {label}", params=params)


class StopRig:
    def __init__(
        self,
        router: str,
        processes: Processes,
        db: Path,
        time_scale: float = 1.0,
        stall_limit: float = 30.0,
        transport: TransportKind = TransportKind.BRIDGE,
        sim_args: tuple[str, ...] = (),
    ) -> None:
        """`sim_args`: more flags for the simulator (the robot it plays, its faults)."""
        self.stall_limit = stall_limit
        """30 s by default: the watchdog is tested on its own, STOP must do it alone."""
        self.router = router
        self.processes = processes
        self.db = db
        self.transport = transport
        self.sim = processes.start(
            "voicectl.services.sim",
            "--connect",
            router,
            "--time-scale",
            f"{time_scale:g}",
            "--transport",
            transport.value,
            *sim_args,
        )
        self.cmd_vel_keys: list[str] = []
        """Where zero velocity is heard: cmd_vel's key, or on rmw_zenoh the keys of the
        robot's cmd_vel subscriptions as their tokens announce them."""
        self.supervisor: subprocess.Popen[bytes] | None = None
        self.executor: subprocess.Popen[bytes] | None = None
        self.odometry: list[tuple[float, Odometry]] = []
        self.zero_at: list[float] = []
        self.status_at: list[float] = []
        self.start_supervisor()
        self.start_executor()

    def start_supervisor(self) -> None:
        self.supervisor = self.processes.supervisor(self.router, ROBOT, self.db)

    def start_executor(self) -> None:
        executors = [arg for name in EXECUTORS for arg in ("--executor", name)]
        self.executor = self.processes.executor(
            self.router,
            ROBOT,
            "--stall-limit",
            f"{self.stall_limit:g}",
            # Named, not detected: on a busy machine the simulator may announce itself
            # after `auto` has given up waiting, and these tests are about STOP.
            "--transport",
            self.transport.value,
            *executors,
        )

    @staticmethod
    def kill(process: subprocess.Popen[bytes] | None) -> None:
        if process is not None and process.poll() is None:
            process.kill()
            process.wait()

    @contextlib.contextmanager
    def client(self) -> Iterator[VoicectlClient]:
        """A client of the rig's stack, with the stopwatch (`listen`) in a session of its
        own, as the robot has: one that shared the client's would hear its puts without
        the router."""
        loop = asyncio.get_running_loop()
        options = BusOptions(connect=[self.router])
        with Bus.open(options, loop) as bus, Bus.open(options, loop) as ear:
            self.listen(ear)
            yield VoicectlClient(bus)

    def listen(self, bus: Bus) -> None:
        """Timestamps, on Zenoh's thread as they arrive: odometry, zero velocities, and
        the navigation status the simulator publishes when a goal ends."""
        names = RobotNames()

        def key(name: str, ros_type: str) -> str:
            return robot_key(self.transport, name, ros_type, any_hash=True)

        def on_cmd_vel(_key: str, velocity: tuple[float, float]) -> None:
            if velocity == (0.0, 0.0):
                self.zero_at.append(time.monotonic())

        def hear_cmd_vel(key: str, kind: CmdVelType) -> None:
            if key not in self.cmd_vel_keys:
                self.cmd_vel_keys.append(key)
                decode = functools.partial(CODEC.read_velocity, kind)
                bus.subscribe(key, decode, on_cmd_vel, on_loop=False)

        if self.transport is TransportKind.RMW_ZENOH:
            # A robot's rmw_zenoh subscription hears its own type and type hash only.
            rmw = RmwZenohKeys(0)

            def on_token(token_key: str, present: bool) -> None:
                token = rmw.parse_token(token_key)
                if present and token is not None and token.kind is RmwKind.SUBSCRIBER:
                    kind = CmdVelType.of(ros_type_of(token.dds_type))
                    if token.name == names.cmd_vel and kind is not None:
                        hear_cmd_vel(rmw.data(token.name, token.dds_type, token.type_hash), kind)

            bus.watch(rmw.tokens, on_token)
        else:
            hear_cmd_vel(names.cmd_vel, CmdVelType.TWIST)
        bus.subscribe(
            key(names.navigate("status"), "action_msgs/msg/GoalStatusArray"),
            bytes,
            lambda _key, _raw: self.status_at.append(time.monotonic()),
            on_loop=False,
        )
        bus.subscribe(
            key(names.odom, "nav_msgs/msg/Odometry"),
            CODEC.read_odometry,
            lambda _key, odom: self.odometry.append((time.monotonic(), odom)),
            on_loop=False,
        )

    async def ready(self, client: VoicectlClient) -> None:
        """Supervisor and executor up, the stop released, the executor idle."""
        if self.supervisor is None or self.supervisor.poll() is not None:
            self.start_supervisor()
        if self.executor is None or self.executor.poll() is not None:
            self.start_executor()

        seen: list[object] = ["nothing"]

        async def up() -> bool:
            try:
                await client.request(ROBOT, Release())
                reply = await client.ask(ROBOT, GetState())
            except BusError as exc:
                seen[0] = exc
                return False
            assert isinstance(reply, StateReply)
            state = seen[0] = reply.state
            return state.executor_online and not state.stopped and state.current is None

        try:
            await async_wait_until(up, WAIT, "supervisor and executor ready, stop released")
        except AssertionError as exc:
            raise AssertionError(f"{exc}; last seen: {seen[0]}") from None
        await async_wait_until(lambda: self.odometry, WAIT, "odometry")

    async def driving(self) -> None:
        await async_wait_until(
            lambda: self.odometry and abs(self.odometry[-1][1].linear_x) > 0.2,
            WAIT,
            "the robot to drive",
        )

    def _away(self) -> Order:
        """A goal far from where the robot is, on the x axis: round after round it goes
        back and forth instead of arriving."""
        x = 0.0 if self.odometry[-1][1].pose.x > 4.0 else 8.0
        return Order(
            order="goal",
            label="mbgoal",
            description=f"reach x {x:g}",
            target_pose=TargetPose(frame="map", x=x),
        )

    async def run(self, case: str, client: VoicectlClient) -> Outcome:
        await self.ready(client)
        far = self._away()
        match case:
            case "healthy" | "executor-killed" | "supervisor-and-executor-killed":
                await self.submit(client, far)
            case "blocked-loop":
                x = far.target_pose.x if far.target_pose else 8.0
                await self.submit(client, order("blocknav", seconds=FAULT_SECONDS, x=x))
            case "commanding-from-blocked-loop":
                await self.submit(client, order("blockdrive", seconds=FAULT_SECONDS))
            case "swallowed-cancel":
                await self.submit(client, order("runaway"))
            case "50-queued":
                await self.submit(
                    client, far, *[order("mul", first=i, second=2) for i in range(49)]
                )
            case _:
                raise ValueError(f"unknown case {case!r}")
        await self.driving()
        await asyncio.sleep(0.3)  # well under way (a blocked loop is blocked by now)
        if case in ("executor-killed", "supervisor-and-executor-killed"):
            self.kill(self.executor)
        if case == "supervisor-and-executor-killed":
            self.kill(self.supervisor)
        asked = time.monotonic()
        stopped = await client.stop(ROBOT)
        told = await self._told(case, asked)
        await asyncio.sleep(max(0.0, max(asked + WATCH, told + HOLD) - time.monotonic()))
        outcome = self._measure(case, stopped, asked)
        if case == "swallowed-cancel":
            # It never ends on its own: only a new executor process does away with it.
            self.kill(self.executor)
        return outcome

    def first_zero(self, asked: float) -> float:
        """Seconds from `asked` to the first zero velocity heard since; inf if none."""
        return next((at for at in self.zero_at if at >= asked), math.inf) - asked

    def first_end(self, asked: float) -> float:
        """Seconds from `asked` to the first navigation status heard since; inf if none."""
        return next((at for at in self.status_at if at >= asked), math.inf) - asked

    async def _told(self, case: str, asked: float) -> float:
        """When the robot was told to stop (zero velocity, and the goal's end for a
        navigation), waiting up to WAIT for it; `asked + WAIT` if it never was."""
        navigating = case in NAVIGATING

        def told() -> float:
            return max(self.first_zero(asked), self.first_end(asked) if navigating else 0.0)

        with contextlib.suppress(AssertionError):  # never told: measured as such
            await async_wait_until(lambda: told() < math.inf, WAIT, "the robot told to stop")
        return asked + min(told(), WAIT)

    async def submit(self, client: VoicectlClient, *orders: Order) -> None:
        await client.ask(ROBOT, Submit(request_id=f"{time.monotonic_ns()}", orders=list(orders)))

    def _measure(self, case: str, stopped: Stopped, asked: float) -> Outcome:
        zero = self.first_zero(asked)
        cancelled = None
        if case in NAVIGATING or case == "50-queued":
            cancelled = self.first_end(asked)
        settled = [odom for at, odom in self.odometry if at >= asked + SETTLE]
        told = asked + max(zero, cancelled or 0.0)
        after = [(at, odom) for at, odom in self.odometry if at >= told]
        at_rest = next((i for i, (_, odom) in enumerate(after) if _speed(odom) == 0.0), None)
        if at_rest is None:
            stood = moved_standing = fastest_standing = math.inf
        else:
            standing = [odom for _, odom in after[at_rest:]]
            stood = after[at_rest][0] - asked
            moved_standing = _moved(standing)
            fastest_standing = max(map(_speed, standing))
        return Outcome(
            case,
            stopped,
            zero,
            cancelled,
            _moved(settled),
            max(map(_speed, settled)),
            stood,
            moved_standing,
            fastest_standing,
        )


def _speed(odom: Odometry) -> float:
    return abs(odom.linear_x) + abs(odom.angular_z)


def _moved(odometry: list[Odometry]) -> float:
    """Metres from the first pose to the last."""
    first, last = odometry[0].pose, odometry[-1].pose
    return math.dist((first.x, first.y), (last.x, last.y))
