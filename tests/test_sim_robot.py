"""The simulator's kinematics and go-to-pose controller, stepped by hand without any I/O."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voicectl.services.sim.robot import (
    CMD_VEL_TIMEOUT,
    Bounds,
    GoToPose,
    Phase,
    Robot,
    SpeedLimits,
    integrate,
)
from voicectl.shared.geometry import compose, normalize_angle
from voicectl.shared.ros2 import Pose2D

LIMITS = SpeedLimits(max_linear=0.5, max_angular=1.5)


def drive_to(
    target: Pose2D, start: Pose2D, dt: float, max_time: float = 120.0
) -> tuple[Robot, float]:
    """Run the controller like the node does; return the robot and the sim time it took."""
    robot = Robot(LIMITS, start)
    controller = GoToPose(target, LIMITS)
    elapsed = 0.0
    while not controller.done:
        assert elapsed < max_time, f"no arrival at {target} from {start} in {max_time} s"
        linear, angular = controller.command(robot.pose, dt)
        assert abs(linear) <= LIMITS.max_linear + 1e-12
        assert abs(angular) <= LIMITS.max_angular + 1e-12
        robot.step(linear, angular, dt)
        elapsed += dt
    return robot, elapsed


def assert_at(pose: Pose2D, target: Pose2D) -> None:
    assert math.hypot(pose.x - target.x, pose.y - target.y) <= 0.02
    assert abs(normalize_angle(pose.yaw - target.yaw)) <= 0.01


# --- geometry -------------------------------------------------------------------------------


def test_integrate_straight_and_on_an_arc() -> None:
    ahead = integrate(Pose2D(1.0, 1.0, math.pi / 2), 0.5, 0.0, 2.0)
    assert (ahead.x, ahead.y) == pytest.approx((1.0, 2.0))
    # A quarter circle of radius 1 to the left, from the origin facing +x.
    quarter = integrate(Pose2D(), math.pi / 2, math.pi / 2, 1.0)
    assert (quarter.x, quarter.y, quarter.yaw) == pytest.approx((1.0, 1.0, math.pi / 2))


def test_compose_resolves_a_base_link_goal() -> None:
    robot = Pose2D(2.0, 1.0, math.pi / 2)
    goal = compose(robot, Pose2D(1.0, 0.5, math.pi / 2))
    assert (goal.x, goal.y) == pytest.approx((1.5, 2.0))
    assert goal.yaw == pytest.approx(-math.pi)  # normalised into [-pi, pi)


def test_bounds() -> None:
    bounds = Bounds.parse("-1,-2,3,4.5")
    assert bounds == Bounds(-1.0, -2.0, 3.0, 4.5)
    assert bounds.contains(3.0, -2.0)
    assert not bounds.contains(3.01, 0.0)
    with pytest.raises(ValueError, match="four numbers"):
        Bounds.parse("1,2,3")
    with pytest.raises(ValueError, match="four numbers"):
        Bounds.parse("a,b,c,d")
    with pytest.raises(ValueError, match="empty"):
        Bounds.parse("1,0,-1,5")


# --- the controller -------------------------------------------------------------------------


@pytest.mark.parametrize("dt", [0.05, 0.5])
@pytest.mark.parametrize(
    ("start", "target"),
    [
        (Pose2D(), Pose2D(2.0, 1.0, 0.0)),
        (Pose2D(), Pose2D(-3.0, 0.0, 0.0)),  # behind: turn half a circle first
        (Pose2D(1.0, 1.0, 0.0), Pose2D(1.0, 1.0, 3.0)),  # rotate on the spot
        (Pose2D(0.0, 0.0, 3.1), Pose2D(-1.0, 0.0, -3.1)),  # yaws across the +-pi seam
        (Pose2D(5.0, -5.0, -1.0), Pose2D(-5.0, 5.0, 1.0)),
    ],
)
def test_controller_reaches_the_goal(start: Pose2D, target: Pose2D, dt: float) -> None:
    robot, elapsed = drive_to(target, start, dt)
    assert_at(robot.pose, target)
    # Turn, straight line, turn: close to the fastest possible at these limits.
    distance = math.hypot(target.x - start.x, target.y - start.y)
    fastest = distance / LIMITS.max_linear + 2 * math.pi / LIMITS.max_angular
    assert elapsed <= fastest + 4 * dt


def test_controller_turns_before_it_drives() -> None:
    robot = Robot(LIMITS)
    controller = GoToPose(Pose2D(0.0, 2.0, 0.0), LIMITS)
    linear, angular = controller.command(robot.pose, 0.05)
    assert controller.phase is Phase.TURN_TO_GOAL
    assert (linear, angular) == (0.0, LIMITS.max_angular)


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-10, 10),
    y=st.floats(-10, 10),
    yaw=st.floats(-math.pi, math.pi),
    start_yaw=st.floats(-math.pi, math.pi),
    dt=st.sampled_from([0.05, 0.1, 0.5, 1.0]),
)
def test_controller_reaches_any_goal_in_bounds(
    x: float, y: float, yaw: float, start_yaw: float, dt: float
) -> None:
    target = Pose2D(x, y, yaw)
    robot, _ = drive_to(target, Pose2D(0.0, 0.0, start_yaw), dt)
    assert_at(robot.pose, target)


# --- the base -------------------------------------------------------------------------------


def test_cmd_vel_is_applied_while_fresh_and_zero_after_the_watchdog() -> None:
    robot = Robot(LIMITS)
    assert robot.cmd_vel(0.0) == (0.0, 0.0)
    robot.set_cmd_vel(0.4, 0.2, now=10.0)
    assert robot.cmd_vel(10.0 + CMD_VEL_TIMEOUT) == (0.4, 0.2)
    assert robot.cmd_vel(10.0 + CMD_VEL_TIMEOUT + 0.01) == (0.0, 0.0)
    robot.set_cmd_vel(0.4, 0.2, now=20.0)
    robot.clear_cmd_vel()
    assert robot.cmd_vel(20.0) == (0.0, 0.0)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_velocity_that_is_not_a_number_means_stop(bad: float) -> None:
    robot = Robot(LIMITS)
    robot.set_cmd_vel(bad, 0.2, now=1.0)
    assert robot.cmd_vel(1.0) == (0.0, 0.2)
    robot.set_cmd_vel(0.3, bad, now=2.0)
    assert robot.cmd_vel(2.0) == (0.3, 0.0)
    robot.step(*robot.cmd_vel(2.0), 1.0)
    assert math.isfinite(robot.pose.x)
    assert math.isfinite(robot.pose.yaw)


def test_step_clamps_to_the_limits() -> None:
    robot = Robot(LIMITS)
    robot.step(3.0, -9.0, 1.0)
    assert (robot.linear, robot.angular) == (0.5, -1.5)


def test_stop_halts_mid_goal() -> None:
    """What a cancel does to the model: zero velocity at once, and the pose stays put."""
    robot = Robot(LIMITS)
    controller = GoToPose(Pose2D(5.0, 0.0, 0.0), LIMITS)
    for _ in range(10):
        robot.step(*controller.command(robot.pose, 0.1), 0.1)
    assert robot.linear == pytest.approx(0.5)
    robot.stop()
    assert (robot.linear, robot.angular) == (0.0, 0.0)
    stopped_at = robot.pose
    robot.step(*robot.cmd_vel(1.0), 0.1)
    assert robot.pose == stopped_at


def test_limits_must_be_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        SpeedLimits(max_linear=0.0)
