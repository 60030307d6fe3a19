"""The robot as executors see it: ROS 2 through zenoh-bridge-ros2dds' keys, CDR payloads."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable

from shared.bus import Bus
from shared.errors import BusError, OrderFailed
from shared.keys import BridgeKeys
from shared.messages import RobotPose, TargetPose
from shared.ros2 import (
    GoalStatus,
    Image,
    NavigateFeedback,
    Odometry,
    Pose2D,
    Ros2Codec,
    new_goal_id,
)

_LOGGER = logging.getLogger(__name__)

NAVIGATE = "navigate_to_pose"
POSE_EVERY = 0.5
"""Seconds between two poses published for panels."""
SEND_GOAL_TIMEOUT = 10.0
RESULT_TIMEOUT = 24 * 3600.0
"""get_result answers when navigation ends, which can take as long as the robot needs."""


class RobotLink:
    """Topics and actions of one robot, shared by every executor of the process."""

    def __init__(
        self, bus: Bus, keys: BridgeKeys, codec: Ros2Codec, pose_key: str | None = None
    ) -> None:
        self.bus = bus
        self.keys = keys
        self.codec = codec
        self._pose_key = pose_key
        """Where to publish the pose for panels (`voice/<robot>/robot/pose`), if anywhere."""
        self._pose_sent = 0.0
        self.pose: Pose2D | None = None
        """Latest pose from odometry, None until the first message."""
        self.image: Image | None = None
        """Latest camera frame, None until the first one."""
        self._feedback: dict[bytes, Callable[[Pose2D, float], None]] = {}
        self._odometry = asyncio.Event()
        self._frame = asyncio.Event()

    def start(self) -> None:
        self.bus.subscribe(self.keys.odom, self.codec.read_odometry, self._on_odom)
        self.bus.subscribe(
            self.keys.action(NAVIGATE, "feedback"), self.codec.read_feedback, self._on_feedback
        )
        self.bus.subscribe(self.keys.camera_image, self.codec.read_image, self._on_image)

    def _on_odom(self, _key: str, odometry: Odometry) -> None:
        self.pose = odometry.pose
        self._odometry.set()
        now = asyncio.get_running_loop().time()
        if self._pose_key is not None and now - self._pose_sent >= POSE_EVERY:
            self._pose_sent = now
            pose = RobotPose(x=self.pose.x, y=self.pose.y, yaw=self.pose.yaw)
            self.bus.publish(self._pose_key, pose, superseded=True)

    def _on_image(self, _key: str, image: Image) -> None:
        self.image = image
        self._frame.set()

    async def next_pose(self, timeout: float = 5.0) -> Pose2D:
        """The next odometry pose (fresher than any seen so far)."""
        self._odometry.clear()
        try:
            await asyncio.wait_for(self._odometry.wait(), timeout)
        except TimeoutError:
            raise OrderFailed(f"no odometry on '{self.keys.odom}' for {timeout:g} s") from None
        assert self.pose is not None
        return self.pose

    async def next_image(self, timeout: float = 5.0) -> Image:
        """The next camera frame (taken after this call)."""
        self._frame.clear()
        try:
            await asyncio.wait_for(self._frame.wait(), timeout)
        except TimeoutError:
            key = self.keys.camera_image
            raise OrderFailed(f"no camera frame on '{key}' for {timeout:g} s") from None
        assert self.image is not None
        return self.image

    def _on_feedback(self, _key: str, feedback: NavigateFeedback) -> None:
        listener = self._feedback.get(feedback.goal_id)
        if listener is not None:
            listener(feedback.pose, feedback.distance_remaining)

    def drive(self, linear_x: float, angular_z: float) -> None:
        """Publish one velocity command on cmd_vel."""
        self.bus.publish_bytes(self.keys.cmd_vel, self.codec.twist(linear_x, angular_z))

    async def halt(self) -> None:
        """Zero velocity now, then cancel every navigation goal."""
        self.bus.publish_bytes(self.keys.cmd_vel, self.codec.twist(0.0, 0.0), urgent=True)
        with contextlib.suppress(BusError):
            await self.bus.request_bytes(
                self.keys.action(NAVIGATE, "cancel_goal"),
                self.codec.cancel_goal_request(),
                timeout=2.0,
            )

    async def navigate(
        self, target: TargetPose, on_feedback: Callable[[Pose2D, float], None]
    ) -> None:
        """Run Nav2's NavigateToPose to `target`; return on success, raise otherwise.

        The goal keeps its frame: Nav2 resolves a 'base_link' goal against the robot's
        pose when it receives it, that is when this order starts executing.
        """
        goal_id = new_goal_id()
        pose = Pose2D(x=target.x, y=target.y, yaw=target.yaw)
        try:
            reply = await self.bus.request_bytes(
                self.keys.action(NAVIGATE, "send_goal"),
                self.codec.send_goal_request(goal_id, target.frame, pose),
                timeout=SEND_GOAL_TIMEOUT,
            )
        except BusError as exc:
            raise OrderFailed(f"navigation unavailable: {exc}") from exc
        if not self.codec.read_send_goal_response(reply):
            raise OrderFailed(
                f"navigation rejected the goal ({target.frame} {target.x:g}, {target.y:g})"
            )
        self._feedback[goal_id] = on_feedback
        try:
            result = await self.bus.request_bytes(
                self.keys.action(NAVIGATE, "get_result"),
                self.codec.get_result_request(goal_id),
                timeout=RESULT_TIMEOUT,
            )
        except asyncio.CancelledError:
            await asyncio.shield(self._cancel_goal(goal_id))
            raise
        except BusError as exc:
            raise OrderFailed(f"navigation result lost: {exc}") from exc
        finally:
            self._feedback.pop(goal_id, None)
        status = self.codec.read_get_result_response(result).status
        if status == GoalStatus.SUCCEEDED:
            return
        if status == GoalStatus.CANCELED:
            raise OrderFailed("navigation was cancelled on the robot")
        raise OrderFailed(f"navigation ended with status {GoalStatus(status).name}")

    async def _cancel_goal(self, goal_id: bytes) -> None:
        try:
            await self.bus.request_bytes(
                self.keys.action(NAVIGATE, "cancel_goal"),
                self.codec.cancel_goal_request(goal_id),
                timeout=2.0,
            )
        except BusError as exc:
            _LOGGER.warning("cancel of navigation goal failed: %s; halting", exc)
            self.drive(0.0, 0.0)
