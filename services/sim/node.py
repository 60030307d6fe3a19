"""The simulated robot as a real one shows itself over Zenoh: topics and Nav2's action.

It speaks through the same transports as the executor (shared/robot/): as zenoh-bridge-
ros2dds exposes a robot, or as a robot whose nodes run on rmw_zenoh, with the same CDR
(`Ros2Codec`), so code that drives this node drives a real robot unchanged:

- ``cmd_vel`` (geometry_msgs/Twist, or TwistStamped) in; ``odom`` (nav_msgs/Odometry) out
  at 20 Hz; ``camera/image_raw`` (sensor_msgs/Image, 64x48 rgb8, or a JPEG
  CompressedImage) out at 2 Hz; ``map`` (nav_msgs/OccupancyGrid, its world's walls,
  `world.py`) every 2 s; every name can be remapped;
- ``navigate_to_pose/_action/{send_goal,get_result,cancel_goal}`` queryables and
  ``.../{feedback,status}`` publications, behaving like Nav2's bt_navigator, and
  ``speed_limit`` (nav2_msgs/SpeedLimit) in, which holds its controller to a top linear
  speed (m/s or percent; 0 lifts it), as Nav2's controller server does;
- a liveliness token per interface, as the bridge or rmw_zenoh announces it, naming its
  ROS type.

Decisions, where Nav2 leaves a choice:

- 'map' and 'odom' are the same world frame here. A 'base_link' goal is taken relative to
  the robot's pose when the goal is accepted, as Jazzy's navigator does; playing Humble, it
  is taken again relative to the current pose at every replan (once a second), as Humble's
  planner does, so such a goal moves with the robot. Other frames, and goals outside the
  bounds, are rejected.
- One goal at a time: a new goal preempts the active one, which ends ABORTED, as Nav2's
  SimpleActionServer does.
- While a goal is active the controller drives and cmd_vel is ignored (Nav2 itself would be
  the one publishing cmd_vel); it cancels nothing.
- A cancel stops the robot at once: the next odom (one tick later) shows zero velocity.
- A cancel of every goal when none is active answers "no error" with no goal, as rclcpp's
  action server does.

`SimFault`s make it misbehave the way links and robots do, for tests.

Simulated time runs `time_scale` times faster than the wall clock: ticks stay at 20 Hz wall
and each advances the model by the scaled wall time since the previous tick. Header stamps
are wall-clock seconds, as on a robot without a simulated clock.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import enum
import io
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from PIL import Image as PilImage

from voicectl.shared.geometry import compose
from voicectl.shared.process import Service
from voicectl.shared.robot import Interface, RobotTransport, Role, TransportKind
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import (
    CANCEL_ALL,
    CANCEL_GOAL,
    NAVIGATE_FEEDBACK,
    NAVIGATE_GET_RESULT,
    NAVIGATE_SEND_GOAL,
    NAVIGATE_TO_POSE,
    SPEED_LIMIT,
    CameraType,
    CancelCode,
    CmdVelType,
    GoalStatus,
    Pose2D,
    Ros2Codec,
    RosDistro,
)

from .robot import Bounds, GoToPose, Robot, SpeedLimits
from .world import floor_plan

_LOGGER = logging.getLogger(__name__)

TICK_S = 0.05
"""Wall seconds between ticks: odom at 20 Hz."""
FEEDBACK_EVERY = 2
"""Ticks between feedback messages: 10 Hz."""
CAMERA_EVERY = 10
"""Ticks between camera frames: 2 Hz."""
MAP_EVERY = 20
"""Ticks between two publications of the map: every second (a map server publishes once
and latches it; publishing again lets whoever subscribes late have it too, and within
the executor's MAP_WAIT when a loaded host stretches the ticks)."""
CAMERA_SIZE = (64, 48)
HISTORY = 16
"""Finished goals remembered for get_result and status."""
WORLD_FRAMES = ("map", "odom")
ROBOT_FRAME = "base_link"
REPLAN_S = 1.0
"""Sim seconds between two replans of Humble's navigator (its default BT replans at 1 Hz)."""
ABORT_AFTER_S = 1.0
"""Sim seconds a goal runs before `SimFault.GOAL_ABORTS` aborts it."""
ABORT_CODE = 105
"""What an aborted goal's result says on Jazzy: FollowPath's FAILED_TO_MAKE_PROGRESS."""
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
STATUS = "action_msgs/msg/GoalStatusArray"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"


class SimFault(enum.StrEnum):
    """Ways the simulated robot misbehaves, on purpose."""

    CANCEL_REJECTED = "cancel-rejected"
    """cancel_goal answers REJECTED and the goal goes on."""
    CANCEL_UNANSWERED = "cancel-unanswered"
    """cancel_goal is never answered (and cancels nothing)."""
    RESULT_LOST_ONCE = "result-lost-once"
    """The first get_result of each goal ends with no reply, as over a dropped link."""
    RESULT_LOST = "result-lost"
    """No get_result is ever answered."""
    GOAL_ABORTS = "goal-aborts"
    """Every goal aborts after a second, with an error code on Jazzy."""
    NO_NAVIGATION = "no-navigation"
    """No Nav2 at all: no navigate_to_pose action is served or announced (a robot driven
    by cmd_vel alone)."""


@dataclass(frozen=True)
class SimConfig:
    names: RobotNames = field(default_factory=RobotNames)
    """The robot's namespace and the names of its topics and action."""
    cmd_vel_type: CmdVelType = CmdVelType.TWIST
    camera_type: CameraType = CameraType.RAW
    faults: frozenset[SimFault] = frozenset()
    time_scale: float = 1.0
    """Simulated seconds per wall second."""
    bounds: Bounds = field(default_factory=Bounds)
    limits: SpeedLimits = field(default_factory=SpeedLimits)
    transport: TransportKind = TransportKind.BRIDGE
    """How it shows its ROS graph: as the bridge exposes a robot, or on rmw_zenoh."""
    distro: RosDistro = RosDistro.JAZZY
    """The ROS 2 distribution it plays (its message layouts, its navigator's ways)."""
    domain_id: int = 0
    """Its ROS domain, on rmw_zenoh."""

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
    relative: Pose2D | None = None
    """A 'base_link' goal as sent, which Humble's navigator takes again at every replan."""
    planned_at: float = 0.0
    """Sim time of the last (re)plan."""
    status: GoalStatus = GoalStatus.EXECUTING
    error_code: int = 0
    error_msg: str = ""
    result_asks: int = 0
    ended: asyncio.Event = field(default_factory=asyncio.Event)


class SimNode(Service):
    """One simulated robot on the bus.

    A service (shared/process.py): `start()` subscribes, serves and offers the robot's
    interfaces, then calls `ready` (which announces the simulator); `run()` ticks the
    model; `stop()` ends the active goal so that waiting queries get their answer.
    """

    def __init__(
        self,
        transport: RobotTransport,
        codec: Ros2Codec,
        config: SimConfig,
        clock: Callable[[], float] = time.monotonic,
        ready: Callable[[], object] = lambda: None,
    ) -> None:
        self._ready = ready
        self._transport = transport
        self._codec = codec
        self._config = config
        self._names = config.names
        self._clock = clock
        self._epoch = clock()
        self._robot = Robot(config.limits)
        self._navigation_limits = config.limits
        """What navigation drives at, at most: the robot's limits, or a speed limit."""
        self._map = codec.occupancy_grid(floor_plan(config.bounds))
        self._active: _Goal | None = None
        self._finished: collections.deque[_Goal] = collections.deque(maxlen=HISTORY)
        self._waiting = 0
        self._drained = asyncio.Event()
        self._drained.set()

    def sim_time(self) -> float:
        return (self._clock() - self._epoch) * self._config.time_scale

    async def start(self) -> None:
        names = self._names
        kind = self._config.cmd_vel_type
        transport = self._transport
        transport.subscribe(
            names.cmd_vel,
            kind.ros_type,
            lambda raw: self._codec.read_velocity(kind, raw),
            self._on_cmd_vel,
        )
        offered = [
            Interface(Role.SUBSCRIBER, names.cmd_vel, kind.ros_type),
            Interface(Role.PUBLISHER, names.odom, ODOMETRY),
            Interface(Role.PUBLISHER, names.tf, TF),
            Interface(Role.PUBLISHER, names.camera_image, self._config.camera_type.ros_type),
            Interface(Role.PUBLISHER, names.map, OCCUPANCY_GRID),
        ]
        if SimFault.NO_NAVIGATION not in self._config.faults:
            transport.subscribe(
                names.speed_limit, SPEED_LIMIT, self._codec.read_speed_limit, self._on_speed_limit
            )
            offered.append(Interface(Role.SUBSCRIBER, names.speed_limit, SPEED_LIMIT))
            transport.serve(names.navigate("send_goal"), NAVIGATE_SEND_GOAL, self._on_send_goal)
            transport.serve(names.navigate("get_result"), NAVIGATE_GET_RESULT, self._on_get_result)
            transport.serve(names.navigate("cancel_goal"), CANCEL_GOAL, self._on_cancel_goal)
            offered.append(
                Interface(Role.ACTION_SERVER, names.topic(names.navigate_name), NAVIGATE_TO_POSE)
            )
        for interface in offered:
            transport.offer(interface)
        faults = ", ".join(sorted(self._config.faults)) or "none"
        _LOGGER.info(
            "simulated robot on '%s' over %s (%s, cmd_vel %s, camera %s), time x%g; faults: %s",
            names.namespace or "/",
            transport.kind,
            self._codec.distro,
            kind,
            self._config.camera_type,
            self._config.time_scale,
            faults,
        )
        self._ready()

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

    async def stop(self) -> None:
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
        if SimFault.GOAL_ABORTS in self._config.faults and now - goal.started_at >= ABORT_AFTER_S:
            robot.stop()
            code = ABORT_CODE if self._codec.distro is not RosDistro.HUMBLE else 0
            self._finish(goal, GoalStatus.ABORTED, error_code=code)
            return
        if goal.relative is not None and now - goal.planned_at >= REPLAN_S:
            # Humble: the planner transforms the base_link goal again, from where the robot is.
            goal.controller = GoToPose(compose(robot.pose, goal.relative), self._navigation_limits)
            goal.planned_at = now
        linear, angular = goal.controller.command(robot.pose, dt)
        robot.step(linear, angular, dt)
        if goal.controller.done:
            robot.stop()
            self._finish(goal, GoalStatus.SUCCEEDED)

    def _finish(
        self, goal: _Goal, status: GoalStatus, error_msg: str = "", error_code: int = 0
    ) -> None:
        goal.status = status
        goal.error_code = error_code
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
        names, transport = self._names, self._transport
        transport.publish(
            names.odom,
            ODOMETRY,
            self._codec.odometry(robot.pose, robot.linear, robot.angular, stamp),
        )
        transport.publish(names.tf, TF, self._codec.transform(robot.pose, stamp))
        goal = self._active
        if goal is not None and tick % FEEDBACK_EVERY == 0:
            transport.publish(
                names.navigate("feedback"),
                NAVIGATE_FEEDBACK,
                self._codec.feedback(
                    goal.goal_id,
                    robot.pose,
                    goal.controller.distance_remaining(robot.pose),
                    self.sim_time() - goal.started_at,
                    stamp_s=stamp,
                ),
            )
        if tick % CAMERA_EVERY == 0:
            camera = self._config.camera_type.ros_type
            transport.publish(names.camera_image, camera, self._camera_message(stamp))
        if tick % MAP_EVERY == 0:
            transport.publish(names.map, OCCUPANCY_GRID, self._map)

    def _publish_status(self) -> None:
        goals = [*self._finished, *([self._active] if self._active else [])]
        payload = self._codec.goal_status_array([(g.goal_id, g.status) for g in goals])
        self._transport.publish(self._names.navigate("status"), STATUS, payload)

    def _camera_message(self, stamp: float) -> bytes:
        width, height = CAMERA_SIZE
        frame = self._camera_frame()
        if self._config.camera_type is CameraType.COMPRESSED:
            # What image_transport's compressed plugin sends for an rgb8 camera.
            encoded = io.BytesIO()
            PilImage.frombytes("RGB", CAMERA_SIZE, frame).save(encoded, format="JPEG")
            return self._codec.compressed_image(
                "rgb8; jpeg compressed bgr8", encoded.getvalue(), stamp_s=stamp
            )
        return self._codec.image(width, height, "rgb8", frame, stamp_s=stamp)

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

    def _on_speed_limit(self, limit: tuple[float, bool]) -> None:
        """Nav2's controller held to a top linear speed, from this goal on (0: its own)."""
        speed, percentage = limit
        top = self._config.limits.max_linear
        if math.isfinite(speed) and speed > 0.0:
            top = min(top, top * min(speed, 100.0) / 100.0 if percentage else speed)
        self._navigation_limits = dataclasses.replace(self._config.limits, max_linear=top)
        if self._active is not None:  # the goal under way too, as Nav2's controller does
            self._active.controller.limits = self._navigation_limits
        _LOGGER.info("navigation held to %g m/s (speed_limit)", top)

    def _on_cmd_vel(self, velocity: tuple[float, float]) -> None:
        if self._active is not None:
            _LOGGER.debug("cmd_vel ignored while a goal is active")
            return
        self._robot.set_cmd_vel(*velocity, now=self.sim_time())

    async def _on_send_goal(self, raw: bytes) -> bytes:
        request = self._codec.read_send_goal_request(raw)
        robot = self._robot
        relative = None
        if request.frame in WORLD_FRAMES:
            target = request.pose
        elif request.frame == ROBOT_FRAME:
            target = compose(robot.pose, request.pose)
            if self._codec.distro is RosDistro.HUMBLE:
                relative = request.pose
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
            controller=GoToPose(target, self._navigation_limits),
            started_at=self.sim_time(),
            accepted_stamp=stamp,
            relative=relative,
            planned_at=self.sim_time(),
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

    async def _on_get_result(self, raw: bytes) -> bytes | None:
        goal = self._find(self._codec.read_get_result_request(raw))
        if goal is None:  # what an rclcpp action server answers for a goal it does not know
            return self._codec.get_result_response(GoalStatus.UNKNOWN)
        goal.result_asks += 1
        faults = self._config.faults
        if SimFault.RESULT_LOST in faults or (
            SimFault.RESULT_LOST_ONCE in faults and goal.result_asks == 1
        ):
            _LOGGER.info("get_result of goal %s lost (fault)", goal.goal_id.hex()[:8])
            return None
        self._waiting += 1
        self._drained.clear()
        try:
            await goal.ended.wait()
        finally:
            self._waiting -= 1
            if self._waiting == 0:
                self._drained.set()
        return self._codec.get_result_response(
            goal.status, error_code=goal.error_code, error_msg=goal.error_msg
        )

    async def _on_cancel_goal(self, raw: bytes) -> bytes | None:
        request = self._codec.read_cancel_goal_request(raw)
        if SimFault.CANCEL_UNANSWERED in self._config.faults:
            _LOGGER.info("cancel_goal left unanswered (fault)")
            return None
        if request.goal_id != CANCEL_ALL:
            goal = self._find(request.goal_id)
            if goal is None:
                return self._codec.cancel_goal_response(CancelCode.UNKNOWN_GOAL_ID)
            if goal.status.terminal and request.stamp_s == 0:
                return self._codec.cancel_goal_response(CancelCode.GOAL_TERMINATED)
        active = self._active
        if active is None and request.goal_id == CANCEL_ALL:
            return self._codec.cancel_goal_response(CancelCode.NONE)
        if active is None or not self._cancels(request.goal_id, request.stamp_s, active):
            return self._codec.cancel_goal_response(CancelCode.REJECTED)
        if SimFault.CANCEL_REJECTED in self._config.faults:
            _LOGGER.info("cancel of goal %s rejected (fault)", active.goal_id.hex()[:8])
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
