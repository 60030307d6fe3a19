"""A robot made of real ROS 2 (rclpy), for the tests of the ros2 transport: what a Nav2
robot shows on DDS, with nothing of voicectl inside. Run in a venv of
harness/ros2_env.py, in a network namespace with only loopback up:

    python -m harness.ros2_robot [--namespace bot1] [--cmd-vel-type twist|stamped] [--no-nav2]

- ``cmd_vel`` (Twist or TwistStamped) in, integrated into ``odom`` (nav_msgs/Odometry) at
  20 Hz; a velocity older than 0.5 s counts as zero, as a base's watchdog does;
- ``map`` (nav_msgs/OccupancyGrid), latched: published once, kept for late subscribers;
- Nav2's ``navigate_to_pose`` action server: goals in map, odom or base_link (others
  refused), driven to at 0.5 m/s and 1.5 rad/s with feedback at 10 Hz, cancellable, and
  aborted with FollowPath's "failed to make progress" (105) when outside ±10 m; while a
  goal runs, cmd_vel is ignored (Nav2 is the one driving). Its controller takes a limit on
  ``speed_limit`` (nav2_msgs/SpeedLimit, in m/s or in percent; 0 lifts it), as Nav2's
  controller server does. With ``--no-nav2``, none of this: a robot driven by cmd_vel
  alone, which imports nothing of Nav2.

What the tests time is said on stdout, one JSON line each, stamped with CLOCK_MONOTONIC
(the same clock in every process of the machine): ``{"event": "zero", "at": ...}`` for
each zero velocity (``"moving"`` for any other), ``{"event": "cancel", ...}`` for each
cancel request, ``"goal"``, ``"succeeded"``, ``"canceled"`` and ``"aborted"`` for goals,
``{"event": "speed_limit", "limit": ..., "percentage": ...}`` for each speed limit,
``{"event": "ready"}`` once everything is declared.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from typing import Any

import rclpy
from geometry_msgs.msg import Twist, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile

TICK = 0.05
MAX_LINEAR = 0.5
MAX_ANGULAR = 1.5
WATCHDOG = 0.5
BOUND = 10.0
ABORT_CODE = 105
FRAMES = ("map", "odom", "base_link")


_SAYING = threading.Lock()


def say(event: str, **details: Any) -> None:
    """One event on stdout, whole: the executor's threads say things at once."""
    line = json.dumps({"event": event, "at": time.monotonic(), **details}) + "\n"
    with _SAYING:
        sys.stdout.write(line)
        sys.stdout.flush()


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


class StandIn:
    def __init__(self, namespace: str, stamped: bool, nav2: bool = True) -> None:
        prefix = f"/{namespace}" if namespace else ""
        self.node = rclpy.create_node("robot_standin")
        group = ReentrantCallbackGroup()
        self.lock = threading.Lock()
        self.x = self.y = self.yaw = 0.0
        self.command = (0.0, 0.0)
        self.commanded_at = -math.inf
        self.navigating = False
        self.active: Any = None
        """The goal being driven to; an older one still running sees it is preempted."""
        node = self.node
        kind = TwistStamped if stamped else Twist
        node.create_subscription(kind, f"{prefix}/cmd_vel", self.on_cmd_vel, 10)
        self.odom = node.create_publisher(Odometry, f"{prefix}/odom", 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.map = node.create_publisher(OccupancyGrid, f"{prefix}/map", latched)
        self.map.publish(self.floor())
        self.top_speed = MAX_LINEAR
        """What the controller drives at, at most: its own limit, or the last speed limit."""
        if nav2:
            from nav2_msgs.action import NavigateToPose
            from nav2_msgs.msg import SpeedLimit

            self.navigate_type: Any = NavigateToPose
            ActionServer(
                node,
                NavigateToPose,
                f"{prefix}/navigate_to_pose",
                self.execute,
                goal_callback=self.on_goal,
                cancel_callback=self.on_cancel,
                callback_group=group,
            )
            node.create_subscription(SpeedLimit, f"{prefix}/speed_limit", self.on_speed_limit, 10)
        node.create_timer(TICK, self.tick, callback_group=group)

    @staticmethod
    def floor() -> OccupancyGrid:
        grid = OccupancyGrid()
        grid.header.frame_id = "map"
        grid.info.resolution = 0.25
        grid.info.width = grid.info.height = 80
        grid.info.origin.position.x = grid.info.origin.position.y = -BOUND
        grid.info.origin.orientation.w = 1.0
        edge = {0, 79}
        grid.data = [100 if r in edge or c in edge else 0 for r in range(80) for c in range(80)]
        return grid

    def on_cmd_vel(self, message: Twist | TwistStamped) -> None:
        twist = message.twist if isinstance(message, TwistStamped) else message
        linear, angular = twist.linear.x, twist.angular.z
        if linear == 0.0 and angular == 0.0:
            say("zero")
        else:
            say("moving", linear=linear, angular=angular)
        with self.lock:
            if self.navigating:
                return
            self.command = (linear, angular)
            self.commanded_at = time.monotonic()

    def tick(self) -> None:
        with self.lock:
            fresh = self.navigating or time.monotonic() - self.commanded_at < WATCHDOG
            linear, angular = self.command if fresh else (0.0, 0.0)
            self.yaw = wrap(self.yaw + angular * TICK)
            self.x += linear * TICK * math.cos(self.yaw)
            self.y += linear * TICK * math.sin(self.yaw)
            x, y, yaw = self.x, self.y, self.yaw
        odom = Odometry()
        odom.header.stamp = self.node.get_clock().now().to_msg()
        odom.header.frame_id = "odom"
        odom.child_frame_id = "base_link"
        odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
        odom.pose.pose.orientation.z = math.sin(yaw / 2)
        odom.pose.pose.orientation.w = math.cos(yaw / 2)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = linear, angular
        self.odom.publish(odom)

    def on_speed_limit(self, message: Any) -> None:
        """As Nav2's controllers take it: 0 lifts the limit, else m/s or percent of top."""
        say("speed_limit", limit=message.speed_limit, percentage=message.percentage)
        limit = message.speed_limit
        if limit <= 0.0:
            top = MAX_LINEAR
        elif message.percentage:
            top = MAX_LINEAR * min(limit, 100.0) / 100.0
        else:
            top = min(MAX_LINEAR, limit)
        with self.lock:
            self.top_speed = top

    def on_goal(self, goal: Any) -> GoalResponse:
        frame = goal.pose.header.frame_id
        accepted = frame in FRAMES
        say("goal", frame=frame, accepted=accepted)
        return GoalResponse.ACCEPT if accepted else GoalResponse.REJECT

    def on_cancel(self, _handle: Any) -> CancelResponse:
        say("cancel")
        return CancelResponse.ACCEPT

    def target(self, goal: Any) -> tuple[float, float, float]:
        pose = goal.pose.pose
        yaw = 2 * math.atan2(pose.orientation.z, pose.orientation.w)
        if goal.pose.header.frame_id != "base_link":
            return pose.position.x, pose.position.y, yaw
        with self.lock:  # relative to where the robot is when it starts: Jazzy's navigator
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            x = self.x + c * pose.position.x - s * pose.position.y
            y = self.y + s * pose.position.x + c * pose.position.y
            return x, y, wrap(self.yaw + yaw)

    def execute(self, handle: Any) -> Any:
        """Drive to the goal, as Nav2 does: one goal at a time, a newer one preempts it."""
        tx, ty, tyaw = self.target(handle.request)
        started = time.monotonic()
        result = self.navigate_type.Result()
        with self.lock:
            self.active = handle
            self.navigating = True
        try:
            while True:
                if handle.is_cancel_requested:
                    handle.canceled()
                    say("canceled")
                    return result
                with self.lock:
                    preempted = self.active is not handle
                    x, y, yaw = self.x, self.y, self.yaw
                if preempted:
                    result.error_msg = "preempted by a newer goal"
                    handle.abort()
                    say("aborted")
                    return result
                distance = math.hypot(tx - x, ty - y)
                if max(abs(tx), abs(ty)) > BOUND and time.monotonic() - started > 0.5:
                    result.error_code = ABORT_CODE
                    result.error_msg = "no progress: the goal is outside the map"
                    handle.abort()
                    say("aborted")
                    return result
                heading = math.atan2(ty - y, tx - x) if distance > 0.05 else tyaw
                turn = wrap(heading - yaw)
                if distance <= 0.05 and abs(turn) < 0.02:
                    handle.succeed()
                    say("succeeded")
                    return result
                angular = max(-MAX_ANGULAR, min(MAX_ANGULAR, 3.0 * turn))
                with self.lock:
                    top = self.top_speed
                    linear = min(top, distance) if distance > 0.05 and abs(turn) < 0.3 else 0.0
                    self.command = (linear, angular)
                handle.publish_feedback(self.feedback(x, y, yaw, distance, started))
                time.sleep(2 * TICK)  # the controller's period, not a wait for anyone
        finally:
            with self.lock:
                if self.active is handle:
                    self.active = None
                    self.navigating = False
                    self.command = (0.0, 0.0)

    def feedback(self, x: float, y: float, yaw: float, distance: float, started: float) -> Any:
        feedback = self.navigate_type.Feedback()
        feedback.current_pose.header.frame_id = "map"
        feedback.current_pose.pose.position.x = x
        feedback.current_pose.pose.position.y = y
        feedback.current_pose.pose.orientation.z = math.sin(yaw / 2)
        feedback.current_pose.pose.orientation.w = math.cos(yaw / 2)
        feedback.distance_remaining = distance
        elapsed = time.monotonic() - started
        feedback.navigation_time.sec = int(elapsed)
        feedback.navigation_time.nanosec = int((elapsed % 1) * 1e9)
        return feedback


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m harness.ros2_robot", description=__doc__)
    parser.add_argument("--namespace", default="")
    parser.add_argument("--cmd-vel-type", choices=("twist", "stamped"), default="twist")
    parser.add_argument("--no-nav2", action="store_true", help="no navigation at all")
    args = parser.parse_args(argv)
    rclpy.init()
    stand_in = StandIn(args.namespace, args.cmd_vel_type == "stamped", nav2=not args.no_nav2)
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(stand_in.node)
    say("ready")
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # SIGTERM's shutdown can also meet the executor while it builds its wait set, and
        # rclpy then raises "the given context is not valid" (seen once under load): a
        # stop like the others. With the context still valid, it is a real error.
        if rclpy.ok():
            raise
    finally:
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
