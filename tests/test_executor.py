"""The executor against the simulator through real Zenoh, the test in the supervisor's
seat: every built-in executor, cancel and halt, label tokens."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import pytest
from PIL import Image as PilImage

from services.executor.robot import RobotLink
from shared.bus import json_decoder
from shared.keys import RobotNames
from shared.messages import (
    CancelOrder,
    Done,
    Execute,
    ExecutorReply,
    Failed,
    Halt,
    Order,
    OrderProgress,
    OrderStatus,
    Rejected,
    TargetPose,
)
from shared.robot import TransportKind, open_transport
from shared.robot_options import RobotOptions
from shared.ros2 import Pose2D, Ros2Codec, RosDistro

from .conftest import Processes, async_wait_until
from .support import TURN_LEFT, harness_on, joined, order, start_robot, until_heard


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> tuple[str, Path]:
    photos = tmp_path / "photos"
    executor_args = ("--cancel-deadline", "0.5", "--executor", "tests.executors_for_tests:Runaway")
    start_robot(processes, router, photos, executor_args=executor_args)
    return router, photos


async def test_drive_and_rotate_close_the_loop_on_odometry(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        start = harness.pose().pose
        result = await harness.finished(await harness.execute(order("drive", distance=0.6)))
        assert (result.status, result.message) == (OrderStatus.SUCCEEDED, "drove 0.6 m")
        await asyncio.sleep(0.2)
        moved = harness.pose().pose
        assert math.hypot(moved.x - start.x, moved.y - start.y) == pytest.approx(0.6, abs=0.05)
        assert harness.pose().linear_x == 0.0

        result = await harness.finished(await harness.execute(TURN_LEFT))
        assert result.status == OrderStatus.SUCCEEDED
        await asyncio.sleep(0.2)
        turned = harness.pose().pose.yaw - moved.yaw
        assert math.atan2(math.sin(turned), math.cos(turned)) == pytest.approx(1.57, abs=0.05)
        progress = [e for e in harness.events[result.order_id] if isinstance(e, OrderProgress)]
        assert progress
        assert progress[0].progress.distance_angular == pytest.approx(1.57, abs=0.1)

        bad = await harness.finished(await harness.execute(order("drive")))
        assert bad.status == OrderStatus.FAILED
        assert "needs a 'distance' parameter or a base_link target pose" in bad.message


async def test_pic_saves_the_next_camera_frame_as_png(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        result = await harness.finished(await harness.execute(order("pic", wait=1)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        (photo,) = robot[1].glob("*.png")
        assert str(photo) in result.message
        with PilImage.open(photo) as picture:
            assert picture.size == (64, 48)
            assert picture.mode == "RGB"
        progress = [e for e in harness.events[result.order_id] if isinstance(e, OrderProgress)]
        assert progress[0].progress.text == "photo in 1 s"


async def test_mbgoal_reports_remaining_distance_and_cancel_stops_the_robot_fast(
    robot: tuple[str, Path],
) -> None:
    async with harness_on(robot[0]) as harness:
        far = Order(
            order="goal",
            label="mbgoal",
            description="reach far",
            target_pose=TargetPose(frame="map", x=6.0, y=0.0),
        )
        order_id = await harness.execute(far)

        def driving() -> bool:
            distances = [
                e.progress.distance_linear
                for e in harness.events.get(order_id, [])
                if isinstance(e, OrderProgress) and e.progress.distance_linear
            ]
            return bool(distances) and harness.pose().linear_x > 0.3

        await async_wait_until(driving, 20.0, "navigation to drive and report progress")
        loop = asyncio.get_running_loop()
        cancelled_at = loop.time()
        assert isinstance(await harness.control(CancelOrder(order_id=order_id)), Done)
        await async_wait_until(
            lambda: harness.odometry[-1][0] > cancelled_at and harness.pose().linear_x == 0.0,
            5.0,
            "the robot to stop",
        )
        stopped_at = next(
            t for t, odom in harness.odometry if t > cancelled_at and odom.linear_x == 0.0
        )
        assert stopped_at - cancelled_at < 0.2  # time scale 1: wall time is sim time
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "cancelled")


async def test_halt_stops_a_driving_robot_outside_any_order(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        order_id = await harness.execute(order("drive", distance=5.0))
        await async_wait_until(lambda: harness.pose().linear_x > 0.2, 10.0, "driving")
        halting = asyncio.get_running_loop().time()
        assert isinstance(await harness.control(Halt()), Done)
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "emergency stop")
        await async_wait_until(
            lambda: harness.odometry[-1][0] > halting and harness.pose().linear_x == 0.0,
            5.0,
            "the robot to stop",
        )
        # Odometry arrives in the order the simulator sent it, so what moved before the halt
        # may arrive late on a loaded machine, but never after the first still one.
        stopped_at = next(t for t, odom in harness.odometry if t > halting and odom.linear_x == 0.0)
        assert stopped_at - halting < 0.25  # time scale 1: wall time is sim time
        await async_wait_until(lambda: len(harness.since(stopped_at)) >= 10, 5.0, "odometry")
        assert all(odom.linear_x == 0.0 for odom in harness.since(stopped_at))


async def test_executor_announces_its_labels(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        replies = harness.bus.session.liveliness().get("voice/r1/labels/*", timeout=2)
        labels = sorted(str(r.ok.key_expr).rsplit("/", 1)[1] for r in replies if r.ok)
        assert labels == ["drive", "mbgoal", "mul", "pic", "rotate", "runaway", "wait"]
        simulator = harness.bus.session.liveliness().get(RobotNames().simulator, timeout=2)
        assert [str(r.ok.key_expr) for r in simulator if r.ok] == ["voicectl_sim/alive"]


async def test_sim_publishes_tf_that_agrees_with_odometry(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        codec = Ros2Codec(RosDistro.JAZZY)
        transforms: list[list[tuple[str, str, object]]] = []
        harness.bus.subscribe(
            RobotNames().tf, codec.read_transform, lambda _key, tf: transforms.append(tf)
        )
        await harness.finished(await harness.execute(order("drive", distance=0.3)))
        await async_wait_until(lambda: len(transforms) > 2, 5.0, "tf messages")
        ((parent, child, pose),) = transforms[-1]
        assert (parent, child) == ("odom", "base_link")
        odom = harness.pose().pose
        assert pose == odom  # the robot stands still: the latest of each agree exactly


async def test_wait_pauses_for_the_spoken_seconds(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        loop = asyncio.get_running_loop()
        started = loop.time()
        result = await harness.finished(await harness.execute(order("wait", seconds=1.5)))
        assert (result.status, result.message) == (OrderStatus.SUCCEEDED, "waited 1.5 s")
        assert loop.time() - started >= 1.5
        _, bad = await harness.offer(order("wait", seconds=-1))
        assert bad == Rejected(
            order_id=bad.order_id if isinstance(bad, Rejected) else "",
            reason="'do wait' (wait): parameter 'seconds': Expected `float` >= 0.0",
        )


async def test_an_executor_that_outlives_its_order_cannot_move_the_robot(
    robot: tuple[str, Path],
) -> None:
    """`runaway` swallows its cancel and keeps calling drive: once cut off, its robot
    handle is revoked, the robot stops and stays stopped, and no order runs beside it."""

    async with harness_on(robot[0]) as harness:
        order_id = await harness.execute(order("runaway"))
        await async_wait_until(lambda: harness.pose().linear_x > 0.2, 10.0, "driving")
        assert isinstance(await harness.control(CancelOrder(order_id=order_id)), Done)
        result = await harness.finished(order_id)
        assert result.status == OrderStatus.CANCELLED
        assert result.message == "cancelled; executor did not stop in time, robot halted"
        cut_off = asyncio.get_running_loop().time()
        # Still trying, every 50 ms: one second of odometry shows the robot at rest.
        await async_wait_until(
            lambda: len([o for o in harness.since(cut_off + 0.3)]) >= 20, 10.0, "1 s of odometry"
        )
        assert all(odom.linear_x == 0.0 for odom in harness.since(cut_off + 0.3))
        assert not [e for e in harness.events[order_id][-1:] if isinstance(e, OrderProgress)]

        _, refused = await harness.offer(order("mul", first=2, second=3))
        assert isinstance(refused, Rejected)
        assert refused.reason == (
            f"the executor of order '{order_id}' ignored its cancel and still runs; "
            "no new order until it ends (restarting the executor ends it)"
        )


async def test_each_executor_key_takes_only_its_own_requests(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        decode = json_decoder(ExecutorReply)
        keys = harness.keys
        wrong_key = await harness.bus.request(keys.executor_execute, Halt(), decode)
        assert isinstance(wrong_key, Failed)
        assert wrong_key.reason.startswith("undecodable request")
        execute = Execute(order_id="x", order=order("mul", first=1, second=2))
        wrong_key = await harness.bus.request(keys.executor_control, execute, decode)
        assert isinstance(wrong_key, Failed)
        assert wrong_key.reason.startswith("undecodable request")
        assert pytest.approx(0.0) == harness.pose().linear_x  # and nothing moved


async def test_an_order_cancelled_as_a_pose_arrives_is_cancelled(router: str) -> None:
    """A cancel in the very turn of the loop in which a pose arrives ends the wait for
    that pose. (asyncio.wait_for, on Python 3.11, returned the pose and lost the cancel: a
    drive cancelled because its supervisor was lost went on and met its revoked handle.)"""
    codec = Ros2Codec(RosDistro.JAZZY)
    with joined(router) as bus, joined(router) as robot:
        link = RobotLink(open_transport(bus, TransportKind.BRIDGE, "voicectl_test"), RobotOptions())
        link.start()
        waiting = asyncio.ensure_future(link.next_pose())
        link.on_pose(lambda _pose: waiting.cancel())  # called as the pose is set
        await until_heard(robot, RobotNames().odom)
        robot.publish_bytes(RobotNames().odom, codec.odometry(Pose2D(x=1.0), 0.0, 0.0, 0.0))
        done, _ = await asyncio.wait({waiting}, timeout=10.0)
        assert done, "no pose came"
        assert waiting.cancelled(), f"the cancel was lost: {waiting.result()}"
