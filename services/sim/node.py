"""The simulated robot as zenoh-bridge-ros2dds exposes a real one: topics and Nav2's action.

Keys and payloads are exactly the bridge's (`BridgeKeys`, CDR from `Ros2Codec`), so code that
drives this node drives a real robot behind the real bridge unchanged:

- ``cmd_vel`` (geometry_msgs/Twist) in; ``odom`` (nav_msgs/Odometry) out at 20 Hz;
  ``camera/image_raw`` (sensor_msgs/Image, 64x48 rgb8) out at 2 Hz;
- ``navigate_to_pose/_action/{send_goal,get_result,cancel_goal}`` queryables and
  ``.../{feedback,status}`` publications, behaving like Nav2's bt_navigator.

Decisions, where Nav2 leaves a choice:

- 'map' and 'odom' are the same world frame here; a 'base_link' goal is taken relative to
  the robot's pose when the goal is accepted; other frames, and goals outside the bounds, are
  rejected.
- One goal at a time: a new goal preempts the active one, which ends ABORTED, as Nav2's
  SimpleActionServer does.
- While a goal is active the controller drives and cmd_vel is ignored (Nav2 itself would be
  the one publishing cmd_vel); it cancels nothing.
- A cancel stops the robot at once: the next odom (one tick later) shows zero velocity.

Simulated time runs `time_scale` times faster than the wall clock: ticks stay at 20 Hz wall
and each advances the model by the scaled wall time since the previous tick. Header stamps
are wall-clock seconds, as on a robot without a simulated clock.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shared.bus import Bus
from shared.keys import BridgeKeys
from shared.ros2 import CANCEL_ALL, CancelCode, GoalStatus, Ros2Codec

from .robot import Bounds, GoToPose, Limits, Robot, compose

_LOGGER = logging.getLogger(__name__)

ACTION = "navigate_to_pose"
TICK_S = 0.05
"""Wall seconds between ticks: odom at 20 Hz."""
FEEDBACK_EVERY = 2
"""Ticks between feedback messages: 10 Hz."""
CAMERA_EVERY = 10
"""Ticks between camera frames: 2 Hz."""
CAMERA_SIZE = (64, 48)
HISTORY = 16
"""Finished goals remembered for get_result and status."""
WORLD_FRAMES = ("map", "odom")
ROBOT_FRAME = "base_link"


@dataclass(frozen=True)
class SimConfig:
    namespace: str = ""
    """The bridge namespace the robot's keys live under ('' or 'bot1')."""
    time_scale: float = 1.0
    """Simulated seconds per wall second."""
    bounds: Bounds = field(default_factory=Bounds)
    limits: Limits = field(default_factory=Limits)

    def __post_init__(self) -> None:
        if not self.time_scale > 0:
            raise ValueError(f"time scale must be positive, not {self.time_scale}")


@dataclass(eq=False)
class _Goal:
    goal_id: bytes
    controller: GoToPose
    started_at: float
    """Sim time of acceptance."""
    accepted_stamp: float
    """Wall time of acceptance."""
    status: GoalStatus = GoalStatus.EXECUTING
    error_msg: str = ""
    ended: asyncio.Event = field(default_factory=asyncio.Event)


class SimNode:
    """One simulated robot on the bus; `declare()` then `run()`, `shutdown()` at the end."""

    def __init__(
        self,
        bus: Bus,
        codec: Ros2Codec,
        config: SimConfig,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._bus = bus
        self._codec = codec
        self._config = config
        self._keys = BridgeKeys(config.namespace)
        self._clock = clock
        self._epoch = clock()
        self._robot = Robot(config.limits)
        self._active: _Goal | None = None
        self._finished: collections.deque[_Goal] = collections.deque(maxlen=HISTORY)
        self._waiting = 0
        self._drained = asyncio.Event()
        self._drained.set()

    def sim_time(self) -> float:
        return (self._clock() - self._epoch) * self._config.time_scale

    def declare(self) -> None:
        """Subscribe and serve; call before `run()` so that odom means 'ready'."""
        keys = self._keys
        self._bus.subscribe(keys.cmd_vel, self._codec.read_twist, self._on_cmd_vel)
        self._bus.serve_bytes(keys.action(ACTION, "send_goal"), self._on_send_goal)
        self._bus.serve_bytes(keys.action(ACTION, "get_result"), self._on_get_result)
        self._bus.serve_bytes(keys.action(ACTION, "cancel_goal"), self._on_cancel_goal)
        _LOGGER.info(
            "simulated robot on '%s' (%s), time x%g",
            keys.namespace or "/",
            self._codec.distro,
            self._config.time_scale,
        )

    async def run(self) -> None:
        """Tick at 20 Hz wall until cancelled."""
        loop = asyncio.get_running_loop()
        last = self.sim_time()
        deadline = loop.time()
        tick = 0
        while True:
            now = self.sim_time()
            self._step(now - last, now)
            last = now
            self._publish(tick)
            tick += 1
            deadline += TICK_S
            delay = deadline - loop.time()
            if delay < -TICK_S:  # fell behind (a stalled machine): do not catch up in a burst
                deadline = loop.time()
                delay = 0.0
            await asyncio.sleep(max(delay, 0.0))

    async def shutdown(self) -> None:
        """End the active goal so that waiting get_result queries get their answer."""
        if self._active is not None:
            self._finish(self._active, GoalStatus.ABORTED, "the simulator is stopping")
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):
                await self._drained.wait()
        # A handler's reply is sent from its task's done-callbacks, a loop turn after it ends.
        for _ in range(3):
            await asyncio.sleep(0)

    # --- the model ------------------------------------------------------------------------

    def _step(self, dt: float, now: float) -> None:
        robot = self._robot
        goal = self._active
        if dt <= 0:
            return
        if goal is None:
            robot.step(*robot.cmd_vel(now), dt)
            return
        linear, angular = goal.controller.command(robot.pose, dt)
        robot.step(linear, angular, dt)
        if goal.controller.done:
            robot.stop()
            self._finish(goal, GoalStatus.SUCCEEDED)

    def _finish(self, goal: _Goal, status: GoalStatus, error_msg: str = "") -> None:
        goal.status = status
        goal.error_msg = error_msg
        goal.ended.set()
        if self._active is goal:
            self._active = None
        self._finished.append(goal)
        _LOGGER.info("goal %s %s %s", goal.goal_id.hex()[:8], status.name, error_msg)
        self._publish_status()

    # --- publications ---------------------------------------------------------------------

    def _publish(self, tick: int) -> None:
        robot = self._robot
        stamp = time.time()
        self._bus.publish_bytes(
            self._keys.odom,
            self._codec.odometry(robot.pose, robot.linear, robot.angular, stamp),
        )
        self._bus.publish_bytes(self._keys.tf, self._codec.transform(robot.pose, stamp))
        goal = self._active
        if goal is not None and tick % FEEDBACK_EVERY == 0:
            self._bus.publish_bytes(
                self._keys.action(ACTION, "feedback"),
                self._codec.feedback(
                    goal.goal_id,
                    robot.pose,
                    goal.controller.distance_remaining(robot.pose),
                    self.sim_time() - goal.started_at,
                    stamp_s=stamp,
                ),
            )
        if tick % CAMERA_EVERY == 0:
            width, height = CAMERA_SIZE
            self._bus.publish_bytes(
                self._keys.camera_image,
                self._codec.image(width, height, "rgb8", self._camera_frame(), stamp_s=stamp),
            )

    def _publish_status(self) -> None:
        goals = [*self._finished, *([self._active] if self._active else [])]
        payload = self._codec.goal_status_array([(g.goal_id, g.status) for g in goals])
        self._bus.publish_bytes(self._keys.action(ACTION, "status"), payload)

    def _camera_frame(self) -> bytes:
        """A picture that changes with the pose: colour from the position, a bar for the yaw."""
        width, height = CAMERA_SIZE
        bounds = self._config.bounds
        pose = self._robot.pose

        def level(value: float, low: float, high: float) -> int:
            return int(255 * min(1.0, max(0.0, (value - low) / (high - low))))

        frame = np.empty((height, width, 3), dtype=np.uint8)
        frame[:] = (
            level(pose.x, bounds.xmin, bounds.xmax),
            level(pose.y, bounds.ymin, bounds.ymax),
            96,
        )
        column = int((pose.yaw + math.pi) / (2 * math.pi) * width) % width
        frame[:, column] = 255
        return frame.tobytes()

    # --- topic and action handlers --------------------------------------------------------

    def _on_cmd_vel(self, _key: str, velocity: tuple[float, float]) -> None:
        if self._active is not None:
            _LOGGER.debug("cmd_vel ignored while a goal is active")
            return
        self._robot.set_cmd_vel(*velocity, now=self.sim_time())

    async def _on_send_goal(self, raw: bytes) -> bytes:
        request = self._codec.read_send_goal_request(raw)
        robot = self._robot
        if request.frame in WORLD_FRAMES:
            target = request.pose
        elif request.frame == ROBOT_FRAME:
            target = compose(robot.pose, request.pose)
        else:
            _LOGGER.warning(
                "goal rejected: frame %r is not one of %s",
                request.frame,
                ", ".join((*WORLD_FRAMES, ROBOT_FRAME)),
            )
            return self._codec.send_goal_response(False, time.time())
        if not self._config.bounds.contains(target.x, target.y):
            _LOGGER.warning(
                "goal rejected: (%.2f, %.2f) is outside %s", target.x, target.y, self._config.bounds
            )
            return self._codec.send_goal_response(False, time.time())
        if self._find(request.goal_id) is not None:
            _LOGGER.warning("goal rejected: id %s is already known", request.goal_id.hex())
            return self._codec.send_goal_response(False, time.time())
        if self._active is not None:
            self._finish(self._active, GoalStatus.ABORTED, "preempted by a newer goal")
        stamp = time.time()
        self._robot.clear_cmd_vel()
        self._active = _Goal(
            goal_id=request.goal_id,
            controller=GoToPose(target, self._config.limits),
            started_at=self.sim_time(),
            accepted_stamp=stamp,
        )
        _LOGGER.info(
            "goal %s accepted: (%.2f, %.2f, %.2f) in %s",
            request.goal_id.hex()[:8],
            target.x,
            target.y,
            target.yaw,
            request.frame,
        )
        self._publish_status()
        return self._codec.send_goal_response(True, stamp)

    async def _on_get_result(self, raw: bytes) -> bytes:
        goal = self._find(self._codec.read_get_result_request(raw))
        if goal is None:  # what an rclcpp action server answers for a goal it does not know
            return self._codec.get_result_response(GoalStatus.UNKNOWN)
        self._waiting += 1
        self._drained.clear()
        try:
            await goal.ended.wait()
        finally:
            self._waiting -= 1
            if self._waiting == 0:
                self._drained.set()
        return self._codec.get_result_response(goal.status, error_msg=goal.error_msg)

    async def _on_cancel_goal(self, raw: bytes) -> bytes:
        request = self._codec.read_cancel_goal_request(raw)
        if request.goal_id != CANCEL_ALL:
            goal = self._find(request.goal_id)
            if goal is None:
                return self._codec.cancel_goal_response(CancelCode.UNKNOWN_GOAL_ID)
            if goal.status.terminal and request.stamp_s == 0:
                return self._codec.cancel_goal_response(CancelCode.GOAL_TERMINATED)
        active = self._active
        if active is None or not self._cancels(request.goal_id, request.stamp_s, active):
            return self._codec.cancel_goal_response(CancelCode.REJECTED)
        self._robot.stop()
        active.status = GoalStatus.CANCELING
        self._publish_status()
        self._finish(active, GoalStatus.CANCELED)
        return self._codec.cancel_goal_response(CancelCode.NONE, (active.goal_id,))

    @staticmethod
    def _cancels(goal_id: bytes, stamp_s: float, goal: _Goal) -> bool:
        """action_msgs' policy: by id, by acceptance time at or before the stamp, or all."""
        if goal_id == CANCEL_ALL and stamp_s == 0:
            return True
        return goal_id == goal.goal_id or (stamp_s != 0 and goal.accepted_stamp <= stamp_s)

    def _find(self, goal_id: bytes) -> _Goal | None:
        if self._active is not None and self._active.goal_id == goal_id:
            return self._active
        return next((g for g in self._finished if g.goal_id == goal_id), None)
