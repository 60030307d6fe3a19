"""`voicectl sim` as a real process behind a real Zenoh router, driven the way a client of
zenoh-bridge-ros2dds drives a robot: CDR on the bridge's keys, action queries and topics."""

from __future__ import annotations

import itertools
import math
import subprocess
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
import zenoh

from harness.wait import wait_until
from voicectl.shared.bus import BusOptions
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import (
    CANCEL_ALL,
    CancelCode,
    CancelResponse,
    GoalStatus,
    Image,
    NavigateFeedback,
    NavigateResult,
    Odometry,
    Pose2D,
    Ros2Codec,
    RosDistro,
    new_goal_id,
)

from .conftest import Processes

ACTION = "navigate_to_pose"
TIME_SCALE = 10


class RobotClient:
    """The test's end of the bridge for one namespace: topics recorded, actions called."""

    def __init__(
        self, session: zenoh.Session, namespace: str, distro: RosDistro = RosDistro.JAZZY
    ) -> None:
        self.session = session
        self.keys = RobotNames(namespace)
        self.codec = Ros2Codec(distro)
        self.odom: list[Odometry] = []
        self.feedback: list[NavigateFeedback] = []
        self.status: list[list[tuple[bytes, GoalStatus]]] = []
        self.images: list[Image] = []
        self._subscribers = [
            self._record(self.keys.odom, self.codec.read_odometry, self.odom),
            self._record(self._action("feedback"), self.codec.read_feedback, self.feedback),
            self._record(self._action("status"), self.codec.read_goal_status_array, self.status),
            self._record(self.keys.camera_image, self.codec.read_image, self.images),
        ]

    def _action(self, member: str) -> str:
        return self.keys.action(ACTION, member)

    def _record(self, key: str, decode: Callable[[bytes], Any], into: list[Any]) -> Any:
        return self.session.declare_subscriber(
            key, lambda sample: into.append(decode(sample.payload.to_bytes()))
        )

    # --- waiting on data --------------------------------------------------------------------

    def wait_ready(self) -> None:
        """The sim declares its routes before its first odom: odom means ready."""
        wait_until(lambda: self.odom, 20.0, f"odom on {self.keys.odom}")

    def pose(self) -> Pose2D:
        return self.odom[-1].pose

    def next_odom(self, count: int = 1) -> list[Odometry]:
        """The next `count` odom messages from now on."""
        start = len(self.odom)
        wait_until(lambda: len(self.odom) >= start + count, 5.0, f"{count} more odom")
        return self.odom[start : start + count]

    # --- actions -----------------------------------------------------------------------------

    def query(self, member: str, payload: bytes, timeout: float = 10.0) -> bytes:
        replies = list(self.session.get(self._action(member), payload=payload, timeout=timeout))
        assert len(replies) == 1, f"{member}: {len(replies)} replies"
        (reply,) = replies
        assert reply.ok is not None, f"{member}: {reply.err}"
        payload_bytes: bytes = reply.ok.payload.to_bytes()
        return payload_bytes

    def send_goal(
        self, goal_id: bytes, x: float, y: float, yaw: float = 0.0, frame: str = "map"
    ) -> bool:
        request = self.codec.send_goal_request(goal_id, frame, Pose2D(x, y, yaw))
        return self.codec.read_send_goal_response(self.query("send_goal", request))

    def get_result(self, goal_id: bytes, timeout: float = 30.0) -> NavigateResult:
        reply = self.query("get_result", self.codec.get_result_request(goal_id), timeout)
        return self.codec.read_get_result_response(reply)

    def cancel(self, goal_id: bytes = CANCEL_ALL) -> CancelResponse:
        reply = self.query("cancel_goal", self.codec.cancel_goal_request(goal_id))
        return self.codec.read_cancel_goal_response(reply)

    def statuses_of(self, goal_id: bytes) -> list[GoalStatus]:
        """Every status the goal was published with, in order, without repeats."""
        seen: list[GoalStatus] = []
        for array in self.status:
            for gid, status in array:
                if gid == goal_id and (not seen or seen[-1] != status):
                    seen.append(status)
        return seen


@pytest.fixture
def session(router: str) -> Iterator[zenoh.Session]:
    with zenoh.open(BusOptions(connect=[router]).zenoh_config()) as client:
        yield client


def start_sim(
    processes: Processes, router: str, namespace: str, *extra: str
) -> subprocess.Popen[bytes]:
    args = ["--connect", router, "--time-scale", str(TIME_SCALE), "--namespace", namespace]
    return processes.start("voicectl.services.sim", *args, *extra, name=f"sim-{namespace}")


@pytest.fixture
def bot1(processes: Processes, router: str, session: zenoh.Session) -> RobotClient:
    client = RobotClient(session, "bot1")
    start_sim(processes, router, "bot1")
    client.wait_ready()
    return client


def near(pose: Pose2D, x: float, y: float, tolerance: float = 0.03) -> bool:
    return math.hypot(pose.x - x, pose.y - y) <= tolerance


# --- navigate_to_pose ---------------------------------------------------------------------------


def test_goal_succeeds_with_feedback_status_and_odom(bot1: RobotClient) -> None:
    goal_id = new_goal_id()
    assert bot1.send_goal(goal_id, 2.0, 1.0, yaw=0.5)
    # cmd_vel during navigation is ignored: the controller drives.
    for _ in range(5):
        bot1.session.put(bot1.keys.cmd_vel, bot1.codec.twist(0.0, 1.5))
    result = bot1.get_result(goal_id)
    assert result == (GoalStatus.SUCCEEDED, 0, "")

    mine = [f for f in bot1.feedback if f.goal_id == goal_id]
    assert mine, "no feedback"
    assert mine[0].distance_remaining == pytest.approx(math.hypot(2.0, 1.0), abs=0.3)
    remaining = [f.distance_remaining for f in mine]
    assert remaining == sorted(remaining, reverse=True)
    wait_until(lambda: GoalStatus.SUCCEEDED in bot1.statuses_of(goal_id), 5.0, "status")
    assert bot1.statuses_of(goal_id) == [GoalStatus.EXECUTING, GoalStatus.SUCCEEDED]

    (odom,) = bot1.next_odom()
    assert near(odom.pose, 2.0, 1.0)
    assert odom.pose.yaw == pytest.approx(0.5, abs=0.02)
    assert (odom.linear_x, odom.angular_z) == (0.0, 0.0)
    # A finished goal's result is still there to ask for.
    assert bot1.get_result(goal_id).status is GoalStatus.SUCCEEDED


def test_cancel_stops_the_robot_at_once(bot1: RobotClient) -> None:
    goal_id = new_goal_id()
    assert bot1.send_goal(goal_id, -8.0, -6.0)
    wait_until(
        lambda: any(f.goal_id == goal_id and f.distance_remaining < 9.0 for f in bot1.feedback),
        10.0,
        "the robot under way",
    )
    assert bot1.odom[-1].linear_x > 0
    assert bot1.cancel(goal_id) == (CancelCode.NONE, (goal_id,))
    # One odom may have left before the cancel; every one after it shows a standstill.
    after = bot1.next_odom(4)[1:]
    assert all((o.linear_x, o.angular_z) == (0.0, 0.0) for o in after)
    assert len({(o.pose.x, o.pose.y, o.pose.yaw) for o in after}) == 1
    assert 0.5 < math.hypot(after[0].pose.x, after[0].pose.y) < 9.5  # stopped midway

    assert bot1.get_result(goal_id).status is GoalStatus.CANCELED
    wait_until(lambda: GoalStatus.CANCELED in bot1.statuses_of(goal_id), 5.0, "status")
    assert bot1.statuses_of(goal_id)[-2:] == [GoalStatus.CANCELING, GoalStatus.CANCELED]
    # Nothing left to cancel.
    assert bot1.cancel(goal_id).return_code is CancelCode.GOAL_TERMINATED
    assert bot1.cancel() == (CancelCode.NONE, ())  # as rclcpp: nothing to cancel, no error
    assert bot1.cancel(new_goal_id()).return_code is CancelCode.UNKNOWN_GOAL_ID


def test_goals_outside_bounds_or_in_unknown_frames_are_rejected(bot1: RobotClient) -> None:
    outside = new_goal_id()
    assert not bot1.send_goal(outside, 50.0, 0.0)
    assert not bot1.send_goal(new_goal_id(), 10.5, 0.0, frame="base_link")
    assert not bot1.send_goal(new_goal_id(), 1.0, 0.0, frame="world")
    assert bot1.get_result(outside).status is GoalStatus.UNKNOWN
    assert all((o.linear_x, o.angular_z) == (0.0, 0.0) for o in bot1.next_odom(2))


def test_base_link_goal_is_relative_and_a_new_goal_preempts(bot1: RobotClient) -> None:
    first = new_goal_id()
    assert bot1.send_goal(first, 9.0, 0.0)
    wait_until(
        lambda: any(f.goal_id == first and f.distance_remaining < 8.0 for f in bot1.feedback),
        10.0,
        "the robot under way",
    )
    second = new_goal_id()
    assert bot1.send_goal(second, 0.0, 1.0, yaw=math.pi / 2, frame="base_link")
    start = bot1.odom[-1].pose  # within a tick of where the second goal was resolved

    assert bot1.get_result(first) == (GoalStatus.ABORTED, 0, "preempted by a newer goal")
    assert bot1.get_result(second).status is GoalStatus.SUCCEEDED
    end = bot1.next_odom()[0].pose
    # One metre to the robot's left, turned a quarter to the left; x drifts by under a tick.
    assert end.x == pytest.approx(start.x, abs=0.3)
    assert end.y == pytest.approx(start.y + 1.0, abs=0.03)
    assert end.yaw == pytest.approx(math.pi / 2, abs=0.02)


# --- topics --------------------------------------------------------------------------------------


def test_cmd_vel_moves_the_robot_until_the_watchdog_stops_it(bot1: RobotClient) -> None:
    first = len(bot1.odom) - 1
    start = bot1.pose()
    forward = bot1.codec.twist(0.5, 0.0)

    def driven() -> bool:
        """It reported the commanded speed and has gone over half a metre. (Under load a
        pause between two commands can outlast the simulator's watchdog, 50 ms of wall
        time here, which stops the robot until the next one: the last odometry message
        alone says nothing.)"""
        reported = any(o.linear_x == 0.5 for o in bot1.odom[first:])
        return reported and bot1.pose().x - start.x > 0.5

    deadline = time.monotonic() + 30.0
    while not driven():
        assert time.monotonic() < deadline, "timed out after 30 s waiting for the drive"
        bot1.session.put(bot1.keys.cmd_vel, forward)
        time.sleep(0.02)  # a teleop's publishing rate, 50 Hz
    # No more commands: within 0.5 s of sim time the base stands still.
    wait_until(lambda: bot1.odom[-1].linear_x == 0.0, 2.0, "the watchdog")
    end = bot1.pose()
    # A busy machine stretches how long the commands lasted, not the kinematics: the
    # distance is the speed each odometry message reports times the time to the next one
    # (stamps are wall-clock seconds; the model runs TIME_SCALE times faster).
    steps = list(itertools.pairwise(bot1.odom[first:]))
    travelled = TIME_SCALE * sum(a.linear_x * (b.stamp_s - a.stamp_s) for a, b in steps)
    tick = TIME_SCALE * max(b.stamp_s - a.stamp_s for a, b in steps)
    assert end.x - start.x > 0.5
    assert end.x - start.x == pytest.approx(travelled, abs=0.5 * tick)
    assert end.y == pytest.approx(start.y, abs=1e-6)


def test_two_namespaces_do_not_interfere(
    processes: Processes, router: str, session: zenoh.Session
) -> None:
    bot1 = RobotClient(session, "bot1")
    bot2 = RobotClient(session, "bot2", RosDistro.HUMBLE)
    start_sim(processes, router, "bot1")
    start_sim(processes, router, "bot2", "--distro", "humble")
    bot1.wait_ready()
    bot2.wait_ready()

    goal_id = new_goal_id()
    assert bot2.send_goal(goal_id, 1.0, -1.0)
    assert bot2.get_result(goal_id) == (GoalStatus.SUCCEEDED, 0, "")  # a Humble result
    assert near(bot2.next_odom()[0].pose, 1.0, -1.0)

    assert bot1.get_result(goal_id).status is GoalStatus.UNKNOWN
    assert not bot1.feedback
    assert not bot1.status
    assert all(near(o.pose, 0.0, 0.0, 1e-9) for o in bot1.odom)
    wait_until(lambda: bot1.images and len(bot2.images) > 1, 5.0, "camera frames")
    width, height, encoding, data = bot1.images[-1]
    assert (width, height, encoding, len(data)) == (64, 48, "rgb8", 64 * 48 * 3)
    assert bot2.images[-1].data != data  # the picture follows the pose


def test_sim_answers_waiting_results_and_exits_0_on_sigterm(
    processes: Processes, router: str, bot1: RobotClient
) -> None:
    goal_id = new_goal_id()
    assert bot1.send_goal(goal_id, -9.0, 9.0)
    pending = bot1.session.get(
        bot1.keys.action(ACTION, "get_result"),
        payload=bot1.codec.get_result_request(goal_id),
        timeout=10.0,
    )
    wait_until(lambda: any(f.goal_id == goal_id for f in bot1.feedback), 5.0, "feedback")
    (sim, *_) = [p for _, p, _ in processes.started]
    assert processes.stop(sim) == 0
    replies = [reply.ok.payload.to_bytes() for reply in pending if reply.ok is not None]
    assert len(replies) == 1
    assert bot1.codec.read_get_result_response(replies[0]) == (
        GoalStatus.ABORTED,
        0,
        "the simulator is stopping",
    )
