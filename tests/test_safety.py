"""The robot under faults, with real processes on loopback and the simulator: STOP stops it
with the executor dead, the stop latches, nothing moves at start-up unasked, a starting
executor ends stray motion, and queue order survives many reorders and a restart."""

from __future__ import annotations

import asyncio
import contextlib
import stat
import subprocess
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import pytest

from harness.client import Client, client_wait_ready
from harness.wait import async_wait_until
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    ControlRequest,
    Done,
    EmergencyStop,
    Execute,
    ExecutorEvent,
    ExecutorReply,
    Failed,
    Message,
    Order,
    OrderFinished,
    OrderProgress,
    OrderRecord,
    OrderStatus,
    Rejected,
    Release,
    Reorder,
    Resume,
    State,
    StateReply,
    Stopped,
    SupervisorRequest,
    TargetPose,
)
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.robot.stop import ExecutorLatch
from voicectl.shared.ros2 import Odometry, Pose2D, Ros2Codec, RosDistro, new_goal_id

from .conftest import Processes
from .support import joined, order

WAIT = 30.0
CODEC = Ros2Codec(RosDistro.JAZZY)
FAR = Order(
    order="goal",
    label="mbgoal",
    description="reach far",
    target_pose=TargetPose(frame="map", x=8.0, y=0.0),
)


class Robot:
    """A simulated robot with its supervisor and executor, each one killable."""

    def __init__(
        self,
        router: str,
        processes: Processes,
        db: Path,
        robot_args: tuple[str, ...] = (),
        bridge: RobotNames | None = None,
    ) -> None:
        self.router = router
        self.processes = processes
        self.db = db
        self.robot_args = robot_args
        """Flags that say which robot the sim plays; the executor gets the names only."""
        self.bridge = bridge or RobotNames()
        self.sim = processes.start("voicectl.services.sim", "--connect", router, *robot_args)
        self.supervisor: subprocess.Popen[bytes] | None = None
        self.executor: subprocess.Popen[bytes] | None = None
        self.odometry: list[tuple[float, Odometry]] = []

    def start_supervisor(self) -> None:
        self.supervisor = self.processes.supervisor(self.router, "r1", self.db)

    def start_executor(self) -> None:
        self.executor = self.processes.executor(self.router, "r1", *_names_only(self.robot_args))

    def kill(self, process: subprocess.Popen[bytes] | None) -> None:
        assert process is not None
        self.processes.kill(process)

    @contextlib.asynccontextmanager
    async def session(self) -> AsyncIterator[tuple[Bus, Client]]:
        """A bus and a client of r1's supervisor, with the robot's odometry recorded."""
        with joined(self.router) as bus:
            loop = asyncio.get_running_loop()
            bus.subscribe(
                self.bridge.odom,
                CODEC.read_odometry,
                lambda _key, odom: self.odometry.append((loop.time(), odom)),
            )
            await async_wait_until(lambda: self.odometry, WAIT, "odometry from the sim")
            yield bus, Client(bus, "r1")

    async def driving(self) -> None:
        await async_wait_until(
            lambda: self.odometry[-1][1].linear_x > 0.2, WAIT, "the robot to drive"
        )

    async def standing(self, since: float) -> Pose2D:
        """Wait for zero velocity reported after `since`; the pose there."""
        await async_wait_until(
            lambda: self.odometry[-1][0] > since and self.odometry[-1][1].linear_x == 0.0,
            WAIT,
            "the robot to stand still",
        )
        return self.odometry[-1][1].pose


def _names_only(robot_args: tuple[str, ...]) -> list[str]:
    """The flags that name things, without those that give types (left to detection)."""
    pairs = zip(robot_args[::2], robot_args[1::2], strict=True)
    return [part for flag, value in pairs if not flag.endswith("-type") for part in (flag, value)]


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> Robot:
    return Robot(router, processes, tmp_path / "supervisor.sqlite3")


REMAPPED = (
    "--namespace",
    "bot1",
    "--cmd-vel",
    "base/cmd_vel",
    "--cmd-vel-type",
    "stamped",
    "--odom",
    "base/odom",
    "--navigate",
    "nav/navigate_to_pose",
)


@pytest.fixture
def remapped_robot(router: str, processes: Processes, tmp_path: Path) -> Robot:
    """A robot whose names are all remapped and whose cmd_vel takes TwistStamped."""
    bridge = RobotNames("bot1", cmd_vel_name="base/cmd_vel", odom_name="base/odom")
    return Robot(router, processes, tmp_path / "supervisor.sqlite3", REMAPPED, bridge)


async def test_a_lost_executor_leaves_no_motion_behind(robot: Robot) -> None:
    robot.start_supervisor()
    robot.start_executor()

    async with robot.session() as (_bus, client):
        await client_wait_ready(client)
        (moving,) = await client.submit(FAR)
        await robot.driving()
        lost = asyncio.get_running_loop().time()
        robot.kill(robot.executor)  # Nav2 would drive on to the goal without anyone in charge
        stopped = await robot.standing(lost)
        assert stopped.x < 7.0
        record = await client.finished(moving)
        assert (record.status, record.message) == (
            OrderStatus.FAILED,
            "executor lost; halting the robot",
        )
        await asyncio.sleep(1.0)
        assert abs(robot.odometry[-1][1].pose.x - stopped.x) < 0.01, "it moved again"


async def test_a_lost_executor_stops_a_remapped_stamped_robot_too(remapped_robot: Robot) -> None:
    """The supervisor stops the robot with what the executor told it: its names, and the
    cmd_vel type the executor learnt from the bridge."""
    robot = remapped_robot
    robot.start_supervisor()
    robot.start_executor()

    async with robot.session() as (bus, client):
        await client_wait_ready(client)
        (moving,) = await client.submit(FAR)
        sent: list[bytes] = []
        bus.subscribe(robot.bridge.cmd_vel, bytes, lambda _key, raw: sent.append(raw))
        await robot.driving()
        lost = asyncio.get_running_loop().time()
        robot.kill(robot.executor)
        stopped = await robot.standing(lost)
        assert stopped.x < 7.0
        await asyncio.sleep(1.0)
        assert abs(robot.odometry[-1][1].pose.x - stopped.x) < 0.01, "it moved again"
        assert (await client.finished(moving)).status == OrderStatus.FAILED
        # The zero velocity went out as the TwistStamped this robot takes.
        assert sent
        assert all(CODEC.read_twist_stamped(raw) == (0.0, 0.0) for raw in sent)


async def test_an_executor_killed_before_it_answers_leaves_no_motion_behind(robot: Robot) -> None:
    """An executor that set the robot moving and died before its answer reached the
    supervisor: the dispatch fails without saying whether the order started, so the
    supervisor stops the robot itself. (The executor is played here, on a session of its
    own, to die at exactly that moment; a killed process did so one run in a few.)"""
    robot.start_supervisor()

    async with robot.session() as (_bus, client):
        await client_wait_ready(client, executor=False)
        keys = RobotKeys("r1")
        loop = asyncio.get_running_loop()
        started = asyncio.Event()

        async def execute(request: Execute) -> Message:
            reply = await executor.request_bytes(
                RobotNames().action("navigate_to_pose", "send_goal"),
                CODEC.send_goal_request(new_goal_id(), "map", Pose2D(x=8.0, y=0.0, yaw=0.0)),
                timeout=WAIT,
            )
            assert CODEC.read_send_goal_response(reply)
            started.set()
            await asyncio.Event().wait()  # dies before it answers
            raise AssertionError("unreachable")

        async def control(request: ControlRequest) -> Message:
            return Failed(reason="not running here")

        with joined(robot.router) as executor:
            executor.serve(keys.executor_execute, json_decoder(Execute), execute)
            executor.serve(keys.executor_control, json_decoder(ControlRequest), control)
            executor.announce(keys.alive("executor"))
            await client.wait_state(lambda s: s.executor_online, "the executor to be online")
            (moving,) = await client.submit(FAR)
            await asyncio.wait_for(started.wait(), WAIT)
            await robot.driving()
            lost = loop.time()
        stopped = await robot.standing(lost)
        assert stopped.x < 7.0
        record = await client.finished(moving)
        assert record.status == OrderStatus.FAILED
        assert record.message.startswith("executor did not take it"), record.message
        await asyncio.sleep(1.0)
        assert abs(robot.odometry[-1][1].pose.x - stopped.x) < 0.01, "it moved again"


async def test_a_stop_that_reaches_the_executor_first_stops_the_queue_too(robot: Robot) -> None:
    """A client stops the robot directly as well as through the supervisor, and the
    direct latch can reach the executor first: the running order ends, and the next one,
    sent before the supervisor hears of the stop, is refused for the stop. The supervisor
    then stops too: that order and the rest end as the stop's, none runs."""
    robot.start_supervisor()
    robot.start_executor()
    async with robot.session() as (bus, client):
        await client_wait_ready(client)
        (moving,) = await client.submit(FAR)
        queued = await client.submit(order("drive", distance=1.0), order("rotate", angle=1.0))
        await robot.driving()
        # Latched as the client latches it (and the supervisor: one `ExecutorLatch`).
        latch = ExecutorLatch(bus, RobotKeys("r1"), json_decoder(ExecutorReply), timeout=5.0)
        latched = await latch.latch()
        assert latched.detail.startswith("executor: latched"), latched
        assert latched.safe, latched
        stopped = await robot.standing(asyncio.get_running_loop().time())
        assert (await client.finished(moving)).status == OrderStatus.CANCELLED
        # The first was sent to the executor, which refused it for the stop; the second
        # was never sent.
        records = [await client.finished(order_id) for order_id in queued]
        for record in records:
            assert (record.status, record.message) == (OrderStatus.CANCELLED, "emergency stop")
        assert records[1].started_at is None, records[1]
        assert (await client.state()).stopped
        await asyncio.sleep(1.0)
        assert abs(robot.odometry[-1][1].pose.x - stopped.x) < 0.01, "it moved again"
        assert isinstance(await client.ask(Release()), Done)
        (after,) = await client.submit(order("mul", first=2, second=3))
        assert (await client.finished(after)).status == OrderStatus.SUCCEEDED


async def test_stop_stops_the_robot_when_the_executor_is_dead(robot: Robot) -> None:
    robot.start_supervisor()

    async with robot.session() as (bus, client):
        await client_wait_ready(client, executor=False)
        # Motion no executor of ours started (another client, or a crashed executor's goal).
        reply = await bus.request_bytes(
            RobotNames().action("navigate_to_pose", "send_goal"),
            CODEC.send_goal_request(new_goal_id(), "map", Pose2D(x=8.0, y=0.0, yaw=0.0)),
            timeout=WAIT,
        )
        assert CODEC.read_send_goal_response(reply)
        await robot.driving()
        asked = asyncio.get_running_loop().time()
        stop = await client.ask(EmergencyStop())
        assert isinstance(stop, Stopped), stop
        assert stop.detail.startswith("sent zero velocity on 'cmd_vel'")
        assert "no executor online" in stop.detail
        assert stop.confirmed
        assert "navigation cancelled every goal" in stop.detail
        stopped = await robot.standing(asked)
        await asyncio.sleep(1.0)
        assert abs(robot.odometry[-1][1].pose.x - stopped.x) < 0.01, "it moved again"


async def test_the_emergency_stop_latches_until_released(robot: Robot) -> None:
    robot.start_supervisor()
    robot.start_executor()

    async with robot.session() as (_bus, client):
        await client_wait_ready(client)
        assert isinstance(await client.ask(EmergencyStop()), Stopped)
        refused = await client.ask_submit(order("mul", first=2, second=3))
        assert isinstance(refused, Failed)
        assert refused.reason.startswith("the emergency stop is on: release it first")
        assert (await client.state()).stopped
        robot.kill(robot.supervisor)  # the latch is stored: a restart keeps it
        robot.start_supervisor()
        await client_wait_ready(client)
        assert (await client.state()).stopped
        assert isinstance(await client.ask(Release()), Done)
        assert not (await client.state()).stopped
        (ran,) = await client.submit(order("mul", first=2, second=3))
        assert (await client.finished(ran)).message == "2 x 3 = 6"


async def test_orders_restored_after_a_restart_wait_for_resume(robot: Robot) -> None:
    robot.start_supervisor()  # no executor yet: orders stay queued

    async with robot.session() as (_bus, client):
        await client_wait_ready(client, executor=False)
        first, second = await client.submit(
            order("mul", first=1, second=2), order("mul", first=3, second=4)
        )
        robot.kill(robot.supervisor)
        robot.start_supervisor()
        robot.start_executor()
        await client_wait_ready(client)
        state = await client.state()
        assert state.paused == "2 order(s) restored after a restart: resume or cancel them"
        await asyncio.sleep(1.0)  # an executor is there, and still nothing runs
        state = await client.state()
        assert state.current is None
        assert [r.id for r in state.queue] == [first, second]
        assert isinstance(await client.ask(Resume()), Done)
        assert (await client.finished(second)).message == "3 x 4 = 12"
        assert (await client.state()).paused == ""


async def test_a_starting_executor_ends_stray_motion(robot: Robot) -> None:
    async with robot.session() as (bus, _client):
        # A goal nobody owns any more (as after an executor crash), sent straight to Nav2.
        goal = new_goal_id()
        reply = await bus.request_bytes(
            RobotNames().action("navigate_to_pose", "send_goal"),
            CODEC.send_goal_request(goal, "map", Pose2D(x=8.0, y=0.0, yaw=0.0)),
            timeout=WAIT,
        )
        assert CODEC.read_send_goal_response(reply)
        await robot.driving()
        started = asyncio.get_running_loop().time()
        robot.start_executor()
        await robot.standing(started)


async def test_queue_order_survives_many_reorders_and_a_restart(robot: Robot) -> None:
    robot.start_supervisor()

    async with robot.session() as (_bus, client):
        await client_wait_ready(client, executor=False)
        ids = await client.submit(*(order("mul", first=n, second=1) for n in range(4)))
        expected = list(ids)
        for turn in range(120):  # each move halves a gap between two stored positions
            moving = expected[3] if turn % 2 == 0 else expected[2]
            reply = await client.ask(Reorder(order_id=moving, position=2))
            assert isinstance(reply, Done), reply
            expected.remove(moving)
            expected.insert(2, moving)
        assert [r.id for r in (await client.state()).queue] == expected
        robot.kill(robot.supervisor)
        robot.start_supervisor()
        await client_wait_ready(client, executor=False)
        assert [r.id for r in (await client.state()).queue] == expected
        beyond = await client.ask(Reorder(order_id=expected[0], position=99))
        assert isinstance(beyond, Done)
        assert beyond.detail == f"moved {expected[0]} to position 3"


async def test_a_result_reached_while_the_supervisor_was_down_is_kept(robot: Robot) -> None:
    robot.start_supervisor()
    robot.start_executor()

    async with robot.session() as (bus, client):
        events: list[ExecutorEvent] = []
        bus.subscribe(
            RobotKeys("r1").executor_events,
            json_decoder(ExecutorEvent),
            lambda _key, event: events.append(event),
        )
        await client_wait_ready(client)
        waiting, after = await client.submit(
            order("wait", seconds=1.0), order("mul", first=2, second=2)
        )
        # The executor's own progress, not the supervisor's state: the supervisor marks an
        # order current before its request reaches the executor, and a kill in between
        # would leave nothing running.
        await async_wait_until(
            lambda: any(isinstance(e, OrderProgress) and e.order_id == waiting for e in events),
            WAIT,
            "the executor to run the wait",
        )
        robot.kill(robot.supervisor)
        await async_wait_until(
            lambda: any(isinstance(e, OrderFinished) for e in events),
            WAIT,
            "the wait to end with no supervisor",
        )
        robot.start_supervisor()
        await client_wait_ready(client)
        record = await client.finished(waiting)
        assert (record.status, record.message) == (OrderStatus.SUCCEEDED, "waited 1 s")
        assert [r.id for r in (await client.state()).queue] == [after]  # waits for resume


async def test_the_database_is_readable_by_its_owner_only(robot: Robot) -> None:
    robot.start_supervisor()

    async with robot.session() as (_bus, client):
        await client_wait_ready(client, executor=False)
        assert stat.S_IMODE(robot.db.stat().st_mode) == 0o600


async def test_the_executor_takes_orders_only_from_the_supervisor_that_owns_the_robot(
    robot: Robot, tmp_path: Path
) -> None:
    """Issue 43: anyone on the bus could hand the executor an order on its execute key and
    move the robot. It now takes orders only from the supervisor that owns the robot, by
    the supervisors' own rule: who holds the owner token and answers as the robot's
    supervisor, not who declares a token. Refused, the robot not moved: an order with no
    supervisor on the bus, one from a made-up supervisor that holds a token, one from a
    process that answers as the supervisor beside the real one; a second real supervisor
    stands down; the owner's orders run."""
    keys = RobotKeys("r1")
    decode = json_decoder(ExecutorReply)
    robot.start_executor()
    async with robot.session() as (bus, client):

        def refused(order_id: str, because: str) -> Callable[[], Awaitable[bool]]:
            """Offer an order straight to the executor until it is refused `because`
            (what the executor sees of the bus settles in a moment)."""

            async def offered() -> bool:
                execute = Execute(order_id=order_id, order=order("drive", distance=1.0))
                try:
                    reply = await bus.request(keys.executor_execute, execute, decode)
                except BusError:
                    return False  # the executor not reachable yet
                assert isinstance(reply, Rejected), reply
                return because in reply.reason

            return offered

        await async_wait_until(
            refused("alone", "no supervisor owns robot 'r1' (no owner token is up)"),
            WAIT,
            "the executor to refuse an order when no supervisor is up",
        )
        # The highest Zenoh id: a supervisor settling a claim made as it starts keeps the
        # robot against it (the lower id wins), whatever the forger answers then.
        highest = f'id:"{"f" * 32}"'
        with joined(BusOptions(connect=[robot.router], settings=(highest,))) as forger:
            made_up = str(forger.session.zid())
            forger.announce(keys.supervisor_owner(made_up))
            await async_wait_until(
                refused("token", f"an owner token names Zenoh id {made_up}, which does not"),
                WAIT,
                "the executor to refuse an order from a made-up supervisor",
            )
            robot.start_supervisor()  # it finds the made-up token and serves all the same
            await client_wait_ready(client)
            forged = OrderRecord(
                id="forged", order=order("drive", distance=1.0), status=OrderStatus.RUNNING
            )

            async def as_supervisor(_request: SupervisorRequest) -> Message:
                return StateReply(state=State(robot="r1", current=forged))

            forger.serve(keys.supervisor, json_decoder(SupervisorRequest), as_supervisor)
            await async_wait_until(
                refused("forged", "2 processes claim robot 'r1' and answer as its supervisor"),
                WAIT,
                "the executor to refuse an order from a second claimant",
            )
        await async_wait_until(
            refused("stale", "order 'stale' is not the one robot 'r1''s supervisor"),
            WAIT,
            "the executor to refuse an order its supervisor does not run",
        )
        second = robot.processes.supervisor(
            robot.router, "r1", tmp_path / "second.sqlite3", name="second-supervisor"
        )
        await async_wait_until(lambda: second.poll() is not None, WAIT, "the second to stop")
        assert "robot 'r1' already has a supervisor" in robot.processes.log(second)
        assert all(odom.linear_x == 0.0 for _, odom in robot.odometry)  # nothing moved yet

        [order_id] = await client.submit(order("drive", distance=0.3))
        record = await client.finished(order_id, timeout=WAIT)
        assert record.status is OrderStatus.SUCCEEDED, record
