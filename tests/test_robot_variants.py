"""The executor against the robots it meets outside the simulator's defaults, each played
by `voicectl sim` in the matching mode over real Zenoh: remapped names with a namespace,
TwistStamped cmd_vel, a compressed camera, Humble's navigator, and navigation that
refuses a cancel, never answers one, loses a result or aborts a goal. Every robot is
played twice: behind zenoh-bridge-ros2dds and as nodes on rmw_zenoh (navigation's faults
only behind the bridge; the default robot's goal feedback, turn and cancel only on
rmw_zenoh, tests/test_executor.py playing them behind the bridge).

The executor is given names only; the transport and the types it must find out itself
(the graph's tokens for the transport and the topics, a get_result probe for the
distribution), as on a robot nobody documented."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from pathlib import Path

import pytest
from PIL import Image as PilImage

from harness.client import robot_key
from harness.wait import async_wait_until
from voicectl.shared.bus import json_decoder
from voicectl.shared.keys import RobotKeys
from voicectl.shared.kinds import ON_ZENOH, CmdVelType
from voicectl.shared.messages import (
    CancelOrder,
    Done,
    ExecutorInfo,
    Failed,
    Halt,
    Order,
    OrderProgress,
    OrderStatus,
    TargetPose,
)
from voicectl.shared.robot import TransportKind, open_transport
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import SPEED_LIMIT, Ros2Codec, RosDistro

from .conftest import Processes, voicectl
from .support import (
    TURN_LEFT,
    ExecutorHarness,
    harness_on,
    joined,
    order,
    start_robot,
    until_heard,
)

CODEC = Ros2Codec()
Start = Callable[..., None]
"""start(sim_args, executor_args): the simulator and an executor for robot 'r1'."""

NAMES = (
    "--namespace",
    "bot1",
    "--cmd-vel",
    "diff_drive_controller/cmd_vel",
    "--odom",
    "diff_drive_controller/odom",
    "--camera",
    "front/image",
    "--navigate",
    "nav/navigate_to_pose",
)
REMAPPED = RobotNames(
    "bot1",
    cmd_vel_name="diff_drive_controller/cmd_vel",
    odom_name="diff_drive_controller/odom",
    camera_name="front/image",
    navigate_name="nav/navigate_to_pose",
)


@pytest.fixture(params=list(ON_ZENOH))
def transport(request: pytest.FixtureRequest) -> TransportKind:
    """How the simulated robot shows its graph; the executor finds out by itself."""
    kind: TransportKind = request.param
    return kind


BRIDGE_ONLY = pytest.mark.parametrize("transport", [TransportKind.BRIDGE], ids=str)
"""For what happens above the transport (navigation's faults, the distribution's check):
played once, behind the bridge. What reaches the robot differently on each transport
(driving, turning, goals with feedback and results, cancels, the camera, the stop at
start-up, Humble's layout) is played on both."""


RMW_ZENOH_ONLY = pytest.mark.parametrize("transport", [TransportKind.RMW_ZENOH], ids=str)
"""What tests/test_executor.py plays behind the bridge on the simulator's defaults (a goal's
feedback, a turn, a cancel that succeeds), played on rmw_zenoh here: once each, cheap."""


@pytest.fixture
def start(router: str, processes: Processes, tmp_path: Path, transport: TransportKind) -> Start:
    def start(sim_args: tuple[str, ...] = (), executor_args: tuple[str, ...] = ()) -> None:
        sim = ("--transport", transport.value, *sim_args)
        start_robot(processes, router, tmp_path / "photos", sim, executor_args)

    return start


def goal(frame: str, x: float) -> Order:
    return Order(
        order="goal",
        label="mbgoal",
        description=f"reach {x:g} m in {frame}",
        target_pose=TargetPose(frame=frame, x=x),
    )


async def executor_info(harness: ExecutorHarness, matches: Callable[[ExecutorInfo], bool]) -> None:
    seen: list[ExecutorInfo] = []
    harness.bus.subscribe(
        harness.keys.executor_info,
        json_decoder(ExecutorInfo),
        lambda _key, info: seen.append(info),
        history=True,
    )
    await async_wait_until(lambda: seen and matches(seen[-1]), 15.0, "the executor's info")


async def moving(harness: ExecutorHarness) -> None:
    await async_wait_until(lambda: harness.pose().linear_x > 0.2, 15.0, "the robot to drive")


async def test_a_remapped_robot_with_stamped_cmd_vel_and_a_compressed_camera(
    router: str, start: Start, transport: TransportKind, tmp_path: Path
) -> None:
    start(
        (*NAMES, "--cmd-vel-type", "stamped", "--camera-type", "compressed"),
        NAMES,
    )

    async with harness_on(router, REMAPPED, transport) as harness:
        # The stamped type comes from the bridge's token: Twist would not decode, and the
        # robot would not move.
        await executor_info(harness, lambda info: info.cmd_vel_type == "stamped")
        begin = harness.pose().pose
        result = await harness.finished(await harness.execute(order("drive", distance=0.5)))
        assert (result.status, result.message) == (OrderStatus.SUCCEEDED, "drove 0.5 m")
        moved = harness.pose().pose
        assert math.hypot(moved.x - begin.x, moved.y - begin.y) == pytest.approx(0.5, abs=0.05)

        result = await harness.finished(await harness.execute(order("pic", wait=0)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        (photo,) = (tmp_path / "photos").glob("*")
        assert photo.suffix == ".jpg"  # the robot's JPEG, saved as it came
        with PilImage.open(photo) as picture:
            assert (picture.format, picture.size) == ("JPEG", (64, 48))

        result = await harness.finished(await harness.execute(goal("map", 1.5)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        assert harness.pose().pose.x == pytest.approx(1.5, abs=0.15)


async def test_the_camera_is_subscribed_only_while_a_photo_is_taken(
    router: str, start: Start, transport: TransportKind
) -> None:
    start()

    async with harness_on(router, transport=transport) as harness:
        key = robot_key(transport, RobotNames().camera_image, "sensor_msgs/msg/Image")
        camera = harness.bus.session.declare_publisher(key)

        def subscribed() -> bool:
            return bool(getattr(camera.matching_status, "matching", False))

        try:
            await asyncio.sleep(1.0)  # time for a subscriber, were there one, to be seen
            assert not subscribed()
            order_id = await harness.execute(order("pic", wait=3))
            await async_wait_until(subscribed, 10.0, "the executor to subscribe to the camera")
            result = await harness.finished(order_id)
            assert result.status == OrderStatus.SUCCEEDED, result.message
            await async_wait_until(lambda: not subscribed(), 10.0, "the camera to be let go")
        finally:
            camera.undeclare()


async def test_humble_goals_relative_to_the_robot_stay_where_they_were_asked(
    router: str, start: Start, transport: TransportKind
) -> None:
    """Humble's navigator re-transforms a base_link goal at every replan (1 Hz here), so
    sent as it is the goal would run ahead of the robot. The executor finds the distro
    by itself and sends an odom goal instead."""
    start(("--distro", "humble"))

    async with harness_on(router, transport=transport) as harness:
        await executor_info(harness, lambda info: info.distro == "humble")
        begin = harness.pose().pose
        result = await harness.finished(await harness.execute(goal("base_link", 2.0)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        end = harness.pose().pose
        assert end.x - begin.x == pytest.approx(2.0, abs=0.15)


@BRIDGE_ONLY
async def test_a_distro_mismatch_fails_navigation_before_any_goal(
    router: str, start: Start, transport: TransportKind
) -> None:
    start(("--distro", "humble"), ("--distro", "jazzy"))

    async with harness_on(router, transport=transport) as harness:
        begin = harness.pose().pose
        result = await harness.finished(await harness.execute(goal("map", 2.0)))
        assert (result.status, result.message) == (
            OrderStatus.FAILED,
            "the robot's navigation speaks ROS 2 Humble, not Jazzy as --distro says; "
            "restart the executor with --distro humble (or auto)",
        )
        await asyncio.sleep(0.5)
        assert harness.pose().pose == begin
        assert harness.pose().linear_x == 0.0


@BRIDGE_ONLY
@pytest.mark.parametrize(
    ("fault", "problem"),
    [
        ("cancel-rejected", "navigation refused to cancel every goal"),
        ("cancel-unanswered", "navigation did not answer the cancel of every goal"),
    ],
)
async def test_a_stop_the_robot_does_not_confirm_is_reported_not_assumed(
    router: str, start: Start, transport: TransportKind, fault: str, problem: str
) -> None:
    start(("--fault", fault))

    async with harness_on(router, transport=transport) as harness:
        order_id = await harness.execute(goal("map", 8.0))
        await moving(harness)
        reply = await harness.control(Halt())
        assert isinstance(reply, Failed)
        assert reply.reason.startswith(f"robot did not confirm the stop: {problem}")
        result = await harness.finished(order_id)
        assert result.status == OrderStatus.CANCELLED
        assert "navigation" in result.message  # the cancel of its own goal went unconfirmed


async def test_a_cancelled_goal_the_robot_keeps_is_named_in_the_result(
    router: str, start: Start, transport: TransportKind
) -> None:
    start(("--fault", "cancel-rejected"))

    async with harness_on(router, transport=transport) as harness:
        order_id = await harness.execute(goal("map", 8.0))
        await moving(harness)
        assert isinstance(await harness.control(CancelOrder(order_id=order_id)), Done)
        result = await harness.finished(order_id)
        assert result.status == OrderStatus.CANCELLED
        assert result.message.startswith("cancelled; navigation refused to cancel goal ")


def distances_left(harness: ExecutorHarness, order_id: str) -> list[float]:
    """The distance left to the goal in each progress event of an order, as Nav2's
    feedback gave it."""
    return [
        e.progress.distance_linear
        for e in harness.events[order_id]
        if isinstance(e, OrderProgress) and e.progress.distance_linear is not None
    ]


@RMW_ZENOH_ONLY
async def test_a_goal_s_feedback_reaches_the_order_s_progress(
    router: str, start: Start, transport: TransportKind
) -> None:
    start()

    async with harness_on(router, transport=transport) as harness:
        result = await harness.finished(await harness.execute(goal("map", 1.0)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        remaining = distances_left(harness, result.order_id)
        assert remaining, "no feedback reached the order's progress"
        assert remaining[0] == pytest.approx(1.0, abs=0.2)
        assert remaining[-1] < remaining[0]


@RMW_ZENOH_ONLY
async def test_a_rolling_robot_is_known_by_its_hashes_and_its_feedback_read(
    router: str, start: Start, transport: TransportKind
) -> None:
    """Rolling's Nav2 feedback has two more fields than Jazzy's and so another type hash;
    its get_result reply is Jazzy's. On rmw_zenoh the robot's tokens tell: the executor
    names the distribution from them and reads the feedback in its layout."""
    start(("--distro", "rolling"))

    async with harness_on(router, transport=transport) as harness:
        await executor_info(harness, lambda info: info.distro is RosDistro.ROLLING)
        result = await harness.finished(await harness.execute(goal("map", 1.0)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        remaining = distances_left(harness, result.order_id)
        assert remaining, "no feedback reached the order's progress"
        assert remaining[0] == pytest.approx(1.0, abs=0.2)


async def test_a_robot_with_navigation_says_it_is_available(
    router: str, start: Start, transport: TransportKind
) -> None:
    """The other side of the one above: the robot's navigate_to_pose announced, the
    executor holds the navigation token (a part the panel shows) and says so to health."""
    start()
    keys = RobotKeys("r1")
    async with harness_on(router, transport=transport) as harness:
        await executor_info(harness, lambda info: info.navigation == "")

        def token() -> bool:
            replies = harness.bus.session.liveliness().get(keys.alive("navigation"), timeout=2)
            return any(reply.ok is not None for reply in replies)

        await async_wait_until(token, 15.0, "the navigation token")
        said = await asyncio.to_thread(
            voicectl, "health", "executor", "--robot", "r1", "--connect", router
        )
        assert said.stdout.endswith("; navigation available\n"), said.stdout


@RMW_ZENOH_ONLY
async def test_a_turn_closes_on_odometry(
    router: str, start: Start, transport: TransportKind
) -> None:
    start()

    async with harness_on(router, transport=transport) as harness:
        begin = harness.pose().pose
        result = await harness.finished(await harness.execute(TURN_LEFT))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        await async_wait_until(lambda: harness.pose().angular_z == 0.0, 5.0, "the turn to end")
        turned = harness.pose().pose.yaw - begin.yaw
        assert math.atan2(math.sin(turned), math.cos(turned)) == pytest.approx(1.57, abs=0.05)


@RMW_ZENOH_ONLY
async def test_a_running_goal_is_cancelled_and_the_robot_stops(
    router: str, start: Start, transport: TransportKind
) -> None:
    start()

    async with harness_on(router, transport=transport) as harness:
        order_id = await harness.execute(goal("map", 8.0))
        await moving(harness)
        cancelled_at = asyncio.get_running_loop().time()
        assert isinstance(await harness.control(CancelOrder(order_id=order_id)), Done)
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "cancelled")
        await async_wait_until(
            lambda: harness.since(cancelled_at) and harness.pose().linear_x == 0.0,
            5.0,
            "the robot to stop",
        )
        assert harness.pose().pose.x < 6.0  # stopped well short of the goal


@BRIDGE_ONLY
async def test_a_result_lost_once_is_asked_again(
    router: str, start: Start, transport: TransportKind
) -> None:
    start(("--fault", "result-lost-once"))

    async with harness_on(router, transport=transport) as harness:
        result = await harness.finished(await harness.execute(goal("map", 1.0)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        assert harness.pose().pose.x == pytest.approx(1.0, abs=0.15)


@BRIDGE_ONLY
async def test_a_result_that_never_comes_cancels_the_goal_before_failing(
    router: str, start: Start, transport: TransportKind
) -> None:
    start(("--fault", "result-lost"), ("--result-grace", "2"))

    async with harness_on(router, transport=transport) as harness:
        result = await harness.finished(await harness.execute(goal("map", 8.0)))
        assert result.status == OrderStatus.FAILED
        assert result.message.startswith("navigation result lost (")
        assert result.message.endswith("); the goal was cancelled")
        failed_at = asyncio.get_running_loop().time()
        await async_wait_until(
            lambda: len(harness.since(failed_at + 0.3)) >= 10, 10.0, "odometry after the failure"
        )
        assert all(odom.linear_x == 0.0 for odom in harness.since(failed_at + 0.3))
        assert harness.pose().pose.x < 6.0  # stopped well short of the goal


@BRIDGE_ONLY
@pytest.mark.parametrize(
    ("distro", "message"),
    [
        ("jazzy", "navigation ended ABORTED: error 105 (controller: failed to make progress)"),
        ("humble", "navigation ended ABORTED (Humble's Nav2 gives no reason)"),
    ],
)
async def test_an_aborted_goal_reports_what_the_robot_said(
    router: str, start: Start, transport: TransportKind, distro: str, message: str
) -> None:
    start(("--distro", distro, "--fault", "goal-aborts"))

    async with harness_on(router, transport=transport) as harness:
        result = await harness.finished(await harness.execute(goal("map", 8.0)))
        assert (result.status, result.message) == (OrderStatus.FAILED, message)


def test_a_namespace_ros_would_refuse_is_refused_with_what_is_allowed() -> None:
    refused = voicectl("executor", "--namespace", "bot-1", timeout=30)
    assert refused.returncode == 2
    assert (
        "argument --namespace: ROS namespace 'bot-1': 'bot-1' is not a ROS 2 name; use letters, "
        "digits and single '_', not starting with a digit ('-' and '.' are not allowed)"
    ) in refused.stderr


async def test_the_stop_at_start_up_is_in_the_type_the_robot_takes(
    router: str, processes: Processes, tmp_path: Path, transport: TransportKind
) -> None:
    """A starting executor stops whatever moves the robot; on a TwistStamped robot that
    stop must be a TwistStamped, so it waits for the robot to say so first."""
    processes.start(
        "voicectl.services.sim",
        "--connect",
        router,
        *NAMES,
        "--cmd-vel-type",
        "stamped",
        "--transport",
        transport.value,
    )
    stamped = "geometry_msgs/msg/TwistStamped"

    with joined(router) as bus:
        sent: list[bytes] = []
        watch = open_transport(bus, transport, "voicectl_test", REMAPPED.namespace)
        watch.subscribe(REMAPPED.cmd_vel, stamped, bytes, sent.append)
        with joined(router) as probe:
            await until_heard(probe, robot_key(transport, REMAPPED.cmd_vel, stamped))
        processes.start("voicectl.services.executor", "--connect", router, "--robot", "r1", *NAMES)
        online = RobotKeys("r1").alive("executor")

        def executor_online() -> bool:
            replies = bus.session.liveliness().get(online, timeout=1)
            return any(reply.ok is not None for reply in replies)

        await async_wait_until(executor_online, 30.0, "the executor to come online")
        assert len(sent) >= 3, "no stop at start-up"
        assert all(CODEC.read_twist_stamped(raw) == (0.0, 0.0) for raw in sent)


WILD = (
    ("drive", "nan", "linear speed nan: not a finite number"),
    ("turn", "inf", "angular speed inf: not a finite number"),
    ("raw", "-inf", "linear.x -inf: every axis must be a finite number"),
    ("other", "nan", "angular.z nan: every axis must be a finite number"),
    ("goal", "nan", "a goal at x nan, y 0.0, yaw 0.0 in 'map': not a finite pose"),
)
"""Each way `harness.executors:Wild` asks for what is not a number, and what it is told."""


async def test_a_speed_or_goal_that_is_not_a_number_never_moves_the_robot(
    router: str, start: Start, transport: TransportKind
) -> None:
    """Issue 43: `limited(nan, ...)` drove at the top speed. Now a NaN or infinite speed,
    asked by `drive`, in a user's own Twist bytes on cmd_vel or on another topic, or a goal
    that is not finite, never reaches the robot: the robot is stopped, the order fails
    saying why, and the executor, which carries on driving, moves it no more."""
    start(executor_args=("--executor", "harness.executors:Wild"))
    heard: dict[str, list[tuple[float, ...]]] = {"cmd_vel": [], "cmd_vel_nav": []}
    codec = Ros2Codec()
    async with harness_on(router, transport=transport) as harness:
        for topic, kept in heard.items():
            harness.transport.subscribe(
                topic,
                "geometry_msgs/msg/Twist",
                lambda raw: codec.velocity_axes(CmdVelType.TWIST, raw),
                kept.append,
            )
        for how, value, reason in WILD:
            order_id = await harness.execute(order("wild", how=how, value=value))
            result = await harness.finished(order_id)
            assert result.status == OrderStatus.FAILED, (how, result)
            assert reason in result.message, (how, result.message)
            ended = asyncio.get_running_loop().time()
            # The executor tries 0.3 m/s every 50 ms still: a second of odometry at rest.
            await async_wait_until(
                lambda ended=ended: len(harness.since(ended + 0.3)) >= 20, 10.0, "1 s of odometry"
            )
            assert all(odom.linear_x == 0.0 for odom in harness.since(ended + 0.3)), how
        for topic, kept in heard.items():
            assert kept, f"nothing heard on {topic}"
            assert all(math.isfinite(axis) for axes in kept for axis in axes), topic
            assert max(abs(axes[0]) for axes in kept) <= 0.5
        assert heard["cmd_vel_nav"] == [(0.0,) * 6]  # the NaN Twist, stilled


async def test_a_robot_without_navigation_is_driven_and_says_so(
    router: str, start: Start, transport: TransportKind
) -> None:
    """Issue 43: a robot that announces no navigate_to_pose (cmd_vel and odometry alone):
    velocity orders run; a navigation order fails at once saying why, instead of waiting
    for a probe or a goal to time out; `voicectl health` and the panel's parts (the
    navigation token) say that navigation is unavailable."""
    start(("--fault", "no-navigation"))
    keys = RobotKeys("r1")
    async with harness_on(router, transport=transport) as harness:
        drive = await harness.finished(await harness.execute(order("drive", distance=0.3)))
        assert drive.status == OrderStatus.SUCCEEDED, drive
        failed = await harness.finished(await harness.execute(goal("map", 2.0)))
        assert failed.status == OrderStatus.FAILED
        assert failed.message == (
            "navigation unavailable: the robot announces no 'navigate_to_pose' action on the "
            f"{transport} transport (is Nav2 running, under that name? --navigate names it)"
        )
        await executor_info(harness, lambda info: info.navigation == failed.message)
        said = await asyncio.to_thread(
            voicectl, "health", "executor", "--robot", "r1", "--connect", router
        )
        assert said.returncode == 0, said.stderr
        assert said.stdout == (
            f"executor of robot 'r1' is up ({keys.alive('executor')}); {failed.message}\n"
        )
        tokens = harness.bus.session.liveliness().get(keys.alive("navigation"), timeout=2.0)
        assert not [reply for reply in tokens if reply.ok is not None]


async def test_nav2_is_told_the_speed_limit_before_each_goal(
    router: str, start: Start, transport: TransportKind
) -> None:
    """Issue 43: Nav2's goals carry no speed, and the executor's limits never reached
    navigation. Now, before each goal, the executor's top speed goes on Nav2's
    speed_limit topic (nav2_msgs/SpeedLimit, m/s), and the robot's navigation (the
    simulator plays Nav2's controller server) drives no faster."""
    start(executor_args=("--max-speed", "0.2"))
    heard: list[tuple[float, bool]] = []
    async with harness_on(router, transport=transport) as harness:
        harness.transport.subscribe(
            RobotNames().speed_limit, SPEED_LIMIT, CODEC.read_speed_limit, heard.append
        )
        begin = asyncio.get_running_loop().time()
        result = await harness.finished(await harness.execute(goal("map", 1.0)))
        assert result.status == OrderStatus.SUCCEEDED, result
        assert heard == [(0.2, False)]
        driven = [odom.linear_x for odom in harness.since(begin)]
        assert 0.15 < max(driven) <= 0.2 + 1e-9, max(driven)
