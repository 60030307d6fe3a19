"""The executor against the simulator through real Zenoh, the test in the supervisor's
seat: every built-in executor, cancel and halt, label tokens."""

from __future__ import annotations

import asyncio
import math
import threading
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from PIL import Image as PilImage

from harness.wait import async_wait_until
from voicectl.services.executor.fence import OrderRobot
from voicectl.services.executor.robot import RobotLink
from voicectl.services.executor.speed import CONTROL_STEP, SAFE_LIMITS, limited
from voicectl.services.sim.robot import Bounds
from voicectl.services.sim.world import floor_plan
from voicectl.shared.bus import Bus, json_decoder
from voicectl.shared.geometry import map_cell
from voicectl.shared.messages import (
    CancelOrder,
    Done,
    Execute,
    ExecutorReply,
    Failed,
    Halt,
    Order,
    OrderFinished,
    OrderProgress,
    OrderStatus,
    Rejected,
    TargetPose,
)
from voicectl.shared.robot import TransportKind, open_transport
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.robot_options import RobotOptions
from voicectl.shared.ros2 import Pose2D, Ros2Codec, RosDistro

from .conftest import Processes
from .support import TURN_LEFT, harness_on, joined, order, start_robot, until_heard


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> tuple[str, Path]:
    photos = tmp_path / "photos"
    executor_args = ("--cancel-deadline", "0.5", "--executor", "harness.executors:Runaway")
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


async def test_mbgoal_reports_remaining_distance_and_cancel_stops_the_robot(
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
        # Stopped by the cancel, short of the goal, and for good. (How fast: bench/stop.py
        # times STOP, which cancels the same way.)
        await async_wait_until(lambda: len(harness.since(stopped_at)) >= 10, 5.0, "odometry")
        assert all(odom.linear_x == 0.0 for odom in harness.since(stopped_at))
        assert harness.pose().pose.x < 5.0
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "cancelled")


async def test_a_goal_navigation_refuses_says_where_it_is_on_the_robots_map(
    robot: tuple[str, Path],
) -> None:
    """Nav2 refuses a goal without a reason; the robot's own map gives the person one."""
    async with harness_on(robot[0]) as harness:
        for frame, reason in (
            ("map", "navigation refused the goal: it is outside the robot's map"),
            (
                "base_link",
                "navigation refused the goal: it is outside the robot's map (by odometry)",
            ),
        ):
            far = Order(
                order="goal",
                label="mbgoal",
                description="reach far away",
                target_pose=TargetPose(frame=frame, x=30.0, y=0.0),
            )
            result = await harness.finished(await harness.execute(far))
            assert (result.status, result.message) == (OrderStatus.FAILED, reason)


def test_a_map_cell_is_read_in_the_grids_own_frame() -> None:
    grid = floor_plan(Bounds(-10.0, -10.0, 10.0, 10.0))
    assert map_cell(grid, 0.0, 0.0) == 0
    assert map_cell(grid, -9.99, 0.0) == 100  # the outer wall
    assert map_cell(grid, 10.5, 0.0) is None
    turned = grid._replace(origin=Pose2D(10.0, -10.0, math.pi / 2))  # x along the world's y
    assert map_cell(turned, 0.0, 0.0) == 0
    assert map_cell(turned, 10.5, 0.0) is None
    assert map_cell(turned, -10.5, 0.0) is None
    assert map_cell(turned, 9.99, 0.0) == 100


async def test_halt_stops_a_driving_robot_outside_any_order(robot: tuple[str, Path]) -> None:
    async with harness_on(robot[0]) as harness:
        start = harness.pose().pose
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
        await async_wait_until(lambda: len(harness.since(stopped_at)) >= 10, 5.0, "odometry")
        assert all(odom.linear_x == 0.0 for odom in harness.since(stopped_at))
        assert harness.pose().pose.x - start.x < 4.0  # well short of the 5 m it was driving


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


async def test_an_order_cancelled_while_its_sender_is_checked_never_starts(
    robot: tuple[str, Path],
) -> None:
    """Before it takes an order, the executor asks who supervises the robot: a moment on
    the bus. A cancel that comes meanwhile (it would have found the order running had it
    started at once) withdraws it: the cancel is answered as the order's end, and the
    order never starts. (Seen: a cancel answered 'not running here', then the order ran.)"""
    async with harness_on(robot[0]) as harness:
        harness.hold = asyncio.Event()
        offering = asyncio.ensure_future(harness.offer(order("drive", distance=1.0)))
        await async_wait_until(lambda: harness.asked, 10.0, "the executor to ask who sent it")
        assert harness.running is not None
        order_id = harness.running.id
        cancelled = await harness.control(CancelOrder(order_id=order_id))
        assert cancelled == OrderFinished(
            order_id=order_id, status=OrderStatus.CANCELLED, message="cancelled"
        )
        since = asyncio.get_running_loop().time()
        harness.hold.set()
        offered_id, refused = await offering
        assert offered_id == order_id
        assert refused == Rejected(order_id=order_id, reason="cancelled before it started")
        await async_wait_until(lambda: len(harness.since(since)) >= 10, 10.0, "odometry")
        assert all(odom.linear_x == 0.0 for odom in harness.since(since))


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


async def test_a_stop_that_overtakes_a_command_on_its_way_is_sent_again_after_it(
    router: str,
) -> None:
    """An executor's thread is inside `drive` when the emergency stop latches on another
    thread, whose zero goes out first: the robot heard the command last and moved on
    (tests/test_stop.py's commanding-from-blocked-loop, once, with the suite on three
    workers at load 7). The command is held in the transport until the stop has sent its
    zero, to make that order of events every time; another zero must follow it."""
    with joined(router) as bus, joined(router) as robot:
        link = RobotLink(open_transport(bus, TransportKind.BRIDGE, "voicectl_test"), RobotOptions())
        heard = CmdVel(robot)
        await until_heard(bus, RobotNames().cmd_vel)
        handle = OrderRobot(link, "o1")
        inside, stopped = threading.Event(), threading.Event()
        send = link.transport.publish

        def held(name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
            if threading.current_thread().name == "executor" and not stopped.is_set():
                inside.set()
                assert stopped.wait(10.0), "the stop never came"
            send(name, ros_type, payload, urgent)

        link.transport.publish = held  # type: ignore[method-assign]

        def stop() -> None:  # as the executor's latch does it (runner.py, `_on_latch`)
            assert inside.wait(10.0), "the command never went out"
            link.latched = True
            handle.revoke()
            link.stop_moving()
            stopped.set()

        driving = threading.Thread(target=handle.drive, args=(0.3, 0.0), name="executor")
        stopping = threading.Thread(target=stop, name="latch")
        driving.start()
        stopping.start()
        await asyncio.to_thread(driving.join, 10.0)
        await asyncio.to_thread(stopping.join, 10.0)
        await async_wait_until(
            lambda: any(v[1] > 0.0 for v in heard.heard), 10.0, "the command on cmd_vel"
        )
        commanded = next(i for i, v in enumerate(heard.heard) if v[1] > 0.0)  # as limits let it
        assert heard.heard[0][1] == 0.0  # the stop's zero went first
        await async_wait_until(
            lambda: len(heard.heard) > commanded + 1, 10.0, "a zero after the command"
        )
        assert all(v[1:] == (0.0, 0.0) for v in heard.heard[commanded + 1 :]), heard.heard


class CmdVel:
    """What the robot hears on cmd_vel (the simulator's, through the bridge's keys):
    (loop time, linear m/s, angular rad/s) of each velocity command."""

    def __init__(self, bus: Bus) -> None:
        loop = asyncio.get_running_loop()
        self.heard: list[tuple[float, float, float]] = []
        bus.subscribe(
            RobotNames().cmd_vel,
            Ros2Codec().read_twist,
            lambda _key, velocity: self.heard.append((loop.time(), *velocity)),
        )

    def fastest(self) -> tuple[float, float]:
        return max(abs(v[1]) for v in self.heard), max(abs(v[2]) for v in self.heard)

    def steepest(self) -> tuple[float, float]:
        """The largest rise in speed from one command to the next (linear, angular)."""
        pairs = list(zip(self.heard, self.heard[1:], strict=False))
        return (
            max(abs(b[1]) - abs(a[1]) for a, b in pairs),
            max(abs(b[2]) - abs(a[2]) for a, b in pairs),
        )


async def test_orders_asking_1000_m_s_are_held_to_the_speed_limits_on_cmd_vel(
    robot: tuple[str, Path],
) -> None:
    """Issue 32, item 4: `drive` and `rotate` with speed 1000 put 50 m/s and 50 rad/s on
    cmd_vel (only the simulator's own clamp kept the robot slow). Now every command holds
    to the executor's limits (by default 0.5 m/s, 1.5 rad/s) and speeds up by at most
    1 m/s² and 3 rad/s² (a rise of 0.1 m/s and 0.3 rad/s per command at most)."""
    limits = SAFE_LIMITS
    async with harness_on(robot[0]) as harness:
        cmd_vel = CmdVel(harness.bus)
        drive = await harness.execute(order("drive", distance=1.0, speed=1000.0))
        assert (await harness.finished(drive)).status == OrderStatus.SUCCEEDED
        turn = await harness.execute(order("rotate", angle=1.5, angular_speed=1000.0))
        assert (await harness.finished(turn)).status == OrderStatus.SUCCEEDED
        fastest_linear, fastest_angular = cmd_vel.fastest()
        print(f"asked 1000: cmd_vel at most {fastest_linear:g} m/s, {fastest_angular:g} rad/s")
        assert 0.4 < fastest_linear <= limits.linear
        assert 1.0 < fastest_angular <= limits.angular
        rise_linear, rise_angular = cmd_vel.steepest()
        assert rise_linear <= limits.linear_accel * CONTROL_STEP + 1e-9
        assert rise_angular <= limits.angular_accel * CONTROL_STEP + 1e-9


async def test_speed_limits_are_the_robots_own_and_hold_for_raw_velocity_too(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """Limits are per robot (the executor's flags), and a user executor that publishes
    its own Twist bytes on cmd_vel is held to them as `drive` is."""
    limits = ("--max-speed", "0.2", "--max-angular-speed", "0.4", "--max-accel", "0.5")
    binding = ("--executor", "harness.executors:RawVelocity")
    start_robot(processes, router, tmp_path / "photos", executor_args=(*limits, *binding))
    async with harness_on(router) as harness:
        cmd_vel = CmdVel(harness.bus)
        drive = await harness.execute(order("drive", distance=0.3, speed=1000.0))
        assert (await harness.finished(drive)).status == OrderStatus.SUCCEEDED
        assert cmd_vel.fastest()[0] == pytest.approx(0.2)
        cmd_vel.heard.clear()
        raw = await harness.execute(order("rawvel", speed=1000.0, seconds=1.0))
        assert (await harness.finished(raw)).status == OrderStatus.SUCCEEDED
        assert cmd_vel.fastest()[0] == pytest.approx(0.2)
        assert cmd_vel.steepest()[0] <= 0.5 * CONTROL_STEP + 1e-9
        assert cmd_vel.heard[-1][1:] == (0.0, 0.0)  # the stop is the last word, not overtaken


@given(
    wanted=st.floats(-2000.0, 2000.0),
    last=st.floats(-0.5, 0.5),
    dt=st.floats(0.0, CONTROL_STEP),
)
def test_a_held_velocity_never_passes_the_top_speed_nor_speeds_up_faster(
    wanted: float, last: float, dt: float
) -> None:
    held = limited(wanted, last, top=0.5, accel=1.0, dt=dt)
    assert abs(held) <= 0.5
    asked = max(-0.5, min(0.5, wanted))
    same_way = last != 0.0 and (asked > 0.0) == (last > 0.0)
    if asked == 0.0 or (same_way and abs(asked) <= abs(last)):
        assert held == asked  # slowing down, or stopping: at once
    else:  # speeding up, from `last` or (reversing) from rest, towards what was asked
        base = last if same_way else 0.0
        assert abs(held) <= abs(base) + 1.0 * dt + 1e-12
        assert abs(held) <= abs(asked)
        assert held == 0.0 or (held > 0.0) == (asked > 0.0)
