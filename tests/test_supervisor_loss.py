"""The executor when its supervisor goes (the operator's STOP with it), with real processes
on loopback and the simulator: an order that moves the robot is cancelled and the robot
stopped; an order that does not command the robot goes on; nothing commands the robot
until a supervisor is back."""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from harness.client import Client, client_wait_ready
from harness.wait import async_wait_until
from voicectl.services.executor.fence import UNSUPERVISED
from voicectl.services.executor.runner import SUPERVISOR_LOST
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import Done, Order, OrderStatus, Resume, TargetPose
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Odometry, Pose2D, Ros2Codec

from .conftest import Processes
from .support import (
    EXECUTORS,
    harness_on,
    joined,
    order,
    start_robot,
)

WAIT = 30.0
STOP_BOUND = 2.0
"""Seconds from SIGKILL to zero velocity on odometry: on loopback the supervisor's token
goes within milliseconds and the simulator reports at 20 Hz, so this is generous."""
FAR = Order(
    order="goal",
    label="mbgoal",
    description="reach far",
    target_pose=TargetPose(frame="map", x=8.0, y=0.0),
)
DRIVE_FAR = order("drive", distance=8.0)


class Robot:
    """The simulator, a supervisor and an executor for robot r1; the robot's odometry
    with the loop time each message arrived."""

    def __init__(self, router: str, processes: Processes, db: Path) -> None:
        self.router = router
        self.processes = processes
        self.db = db
        processes.start("voicectl.services.sim", "--connect", router)
        self.supervisor = self.start_supervisor()
        self.executor = processes.executor(router, "r1", *EXECUTORS)
        self.odometry: list[tuple[float, Odometry]] = []

    def start_supervisor(self) -> subprocess.Popen[bytes]:
        self.supervisor = self.processes.supervisor(self.router, "r1", self.db)
        return self.supervisor

    def kill_supervisor(self) -> None:
        self.processes.kill(self.supervisor)

    def executor_log(self) -> str:
        return self.processes.log(self.executor)

    @contextlib.asynccontextmanager
    async def session(self) -> AsyncIterator[Client]:
        """A client of r1's supervisor once it and the executor are up, with the robot's
        odometry recorded."""
        with joined(self.router) as bus:
            loop = asyncio.get_running_loop()
            bus.subscribe(
                RobotNames().odom,
                Ros2Codec().read_odometry,
                lambda _key, odom: self.odometry.append((loop.time(), odom)),
            )
            await async_wait_until(lambda: self.odometry, WAIT, "odometry from the sim")
            client = Client(bus, "r1")
            await client_wait_ready(client)
            yield client

    async def driving(self) -> None:
        await async_wait_until(
            lambda: self.odometry[-1][1].linear_x > 0.2, WAIT, "the robot to drive"
        )

    async def standing(self, since: float) -> tuple[float, Pose2D]:
        """Wait for zero velocity reported after loop time `since`: how long it took, and
        the pose there."""

        def first_still() -> tuple[float, Odometry] | None:
            return next(
                (
                    (at, odom)
                    for at, odom in self.odometry
                    if at > since and odom.linear_x == 0.0 and odom.angular_z == 0.0
                ),
                None,
            )

        await async_wait_until(first_still, WAIT, "the robot to stand still")
        found = first_still()
        assert found is not None
        return found[0] - since, found[1].pose


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> Robot:
    return Robot(router, processes, tmp_path / "supervisor.sqlite3")


@pytest.mark.parametrize("moving", [DRIVE_FAR, FAR], ids=["drive", "mbgoal"])
async def test_a_lost_supervisor_stops_the_moving_robot(robot: Robot, moving: Order) -> None:
    async with robot.session() as client:
        running, sibling = await client.submit(moving, order("mul", first=2, second=3))
        (later,) = await client.submit(order("mul", first=4, second=5))
        await robot.driving()
        lost = asyncio.get_running_loop().time()
        robot.kill_supervisor()  # and the operator's STOP with it
        took, stood = await robot.standing(lost)
        print(f"supervisor SIGKILLed to zero velocity on odom ({moving.label}): {took:.3f} s")
        assert took < STOP_BOUND
        assert stood.x < 7.0  # far from where it was going
        await asyncio.sleep(1.0)  # a window to watch it stand
        assert abs(robot.odometry[-1][1].pose.x - stood.x) < 0.01, "it moved again"

        robot.start_supervisor()
        await client_wait_ready(client)
        record = await client.finished(running)
        assert (record.status, record.message) == (OrderStatus.CANCELLED, SUPERVISOR_LOST)
        # The rest of its utterance is cancelled, as after an executor's loss; another
        # utterance's order is kept, waiting for resume.
        rest = await client.finished(sibling)
        assert (rest.status, rest.message) == (
            OrderStatus.CANCELLED,
            f"cancelled because “{moving.description}” before it was cancelled",
        )
        state = await client.state()
        assert [r.id for r in state.queue] == [later]
        assert state.paused
        assert isinstance(await client.ask(Resume()), Done)
        assert (await client.finished(later)).message == "4 x 5 = 20"
        assert [r.id for r in (await client.history()).records] == [later, sibling, running]
        assert robot.executor_log().count("supervisor lost while order") == 1


async def test_an_order_that_does_not_command_the_robot_goes_on(robot: Robot) -> None:
    async with robot.session() as client:
        running, after = await client.submit(
            order("slow", seconds=3), order("mul", first=3, second=3)
        )
        await client.wait_state(
            lambda s: s.current is not None and s.current.progress is not None,
            "the slow order to run on the executor",
        )
        robot.kill_supervisor()
        await async_wait_until(
            lambda: f"order {running} goes on" in robot.executor_log(),
            WAIT,
            "the executor to see its supervisor go",
        )
        robot.start_supervisor()
        await client_wait_ready(client)
        record = await client.finished(running)
        assert (record.status, record.message) == (OrderStatus.SUCCEEDED, "slept")
        assert [r.id for r in (await client.state()).queue] == [after]


async def test_no_order_commands_the_robot_until_a_supervisor_is_back(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """The test holds the supervisor's token, and sends orders as no supervisor would
    while it is gone."""
    start_robot(processes, router, tmp_path / "photos")
    executor = processes.started[-1][1]

    def logged(text: str) -> Callable[[], bool]:
        return lambda: text in processes.log(executor)

    async with harness_on(router) as harness:
        supervisor = RobotKeys("r1").alive("supervisor")
        withdraw = harness.bus.announce(supervisor)
        await async_wait_until(logged("supervisor online"), WAIT, "the supervisor to be seen")
        withdraw()
        await async_wait_until(logged("supervisor lost; no order runs"), WAIT, "the loss")

        sent = asyncio.get_running_loop().time()
        refused = await harness.finished(await harness.execute(order("drive", distance=1.0)))
        assert (refused.status, refused.message) == (OrderStatus.FAILED, UNSUPERVISED)
        assert all(odom.linear_x == 0.0 for odom in harness.since(sent))
        photo = await harness.finished(await harness.execute(order("pic")))
        assert photo.status == OrderStatus.SUCCEEDED  # reading the robot is not commanding it

        harness.bus.announce(supervisor)
        await async_wait_until(logged("supervisor back"), WAIT, "the supervisor to be back")
        driven = await harness.finished(await harness.execute(order("drive", distance=0.3)))
        assert (driven.status, driven.message) == (OrderStatus.SUCCEEDED, "drove 0.3 m")
