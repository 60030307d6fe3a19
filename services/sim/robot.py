"""A planar robot base and a go-to-pose controller: pure kinematics, no I/O, no clock.

Time is whatever the caller passes in (simulated seconds), so that tests can drive the model
step by step and the node can run it faster than real time.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from voicectl.shared.geometry import normalize_angle
from voicectl.shared.ros2 import Pose2D

CMD_VEL_TIMEOUT = 0.5
"""Seconds after which a velocity command counts as zero, like a real base's watchdog."""


@dataclass(frozen=True)
class SpeedLimits:
    max_linear: float = 0.5
    """Metres per second, forwards or backwards."""
    max_angular: float = 1.5
    """Radians per second, either way."""

    def __post_init__(self) -> None:
        if self.max_linear <= 0 or self.max_angular <= 0:
            raise ValueError(
                f"speed limits must be positive, not {self.max_linear} m/s "
                f"and {self.max_angular} rad/s"
            )


@dataclass(frozen=True)
class Bounds:
    """The rectangle of the world that goals must lie in."""

    xmin: float = -10.0
    ymin: float = -10.0
    xmax: float = 10.0
    ymax: float = 10.0

    def __post_init__(self) -> None:
        if not (self.xmin < self.xmax and self.ymin < self.ymax):
            raise ValueError(
                f"bounds {self.xmin},{self.ymin},{self.xmax},{self.ymax} are empty; "
                "expected XMIN,YMIN,XMAX,YMAX with XMIN < XMAX and YMIN < YMAX"
            )

    @staticmethod
    def parse(text: str) -> Bounds:
        """Bounds from 'XMIN,YMIN,XMAX,YMAX' ('-10,-10,10,10')."""
        parts = text.split(",")
        try:
            values = [float(part) for part in parts]
        except ValueError:
            values = []
        if len(values) != 4:
            raise ValueError(f"bounds {text!r} must be four numbers: XMIN,YMIN,XMAX,YMAX")
        return Bounds(*values)

    def contains(self, x: float, y: float) -> bool:
        return self.xmin <= x <= self.xmax and self.ymin <= y <= self.ymax


def integrate(pose: Pose2D, linear: float, angular: float, dt: float) -> Pose2D:
    """Where constant velocities take `pose` in `dt` seconds (exact arc, not Euler)."""
    yaw = pose.yaw + angular * dt
    if abs(angular) < 1e-9:
        x = pose.x + linear * dt * math.cos(pose.yaw)
        y = pose.y + linear * dt * math.sin(pose.yaw)
    else:
        radius = linear / angular
        x = pose.x + radius * (math.sin(yaw) - math.sin(pose.yaw))
        y = pose.y - radius * (math.cos(yaw) - math.cos(pose.yaw))
    return Pose2D(x=x, y=y, yaw=normalize_angle(yaw))


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


class Robot:
    """A differential-drive base: a pose, the velocity it last moved at, a cmd_vel watchdog."""

    def __init__(self, limits: SpeedLimits, pose: Pose2D | None = None) -> None:
        self.limits = limits
        self.pose = pose or Pose2D()
        self.linear = 0.0
        self.angular = 0.0
        self._cmd = (0.0, 0.0)
        self._cmd_at = -math.inf

    def set_cmd_vel(self, linear: float, angular: float, now: float) -> None:
        """Remember a velocity command received at sim time `now`; a value that is not a
        finite number (NaN, infinity) means stop, never full speed."""
        self._cmd = (
            linear if math.isfinite(linear) else 0.0,
            angular if math.isfinite(angular) else 0.0,
        )
        self._cmd_at = now

    def cmd_vel(self, now: float) -> tuple[float, float]:
        """The last command if it is fresh at `now`, else standstill."""
        if now - self._cmd_at > CMD_VEL_TIMEOUT:
            return 0.0, 0.0
        return self._cmd

    def clear_cmd_vel(self) -> None:
        self._cmd_at = -math.inf

    def step(self, linear: float, angular: float, dt: float) -> None:
        """Move for `dt` seconds at the given velocities, clamped to the limits."""
        self.linear = _clamp(linear, self.limits.max_linear)
        self.angular = _clamp(angular, self.limits.max_angular)
        self.pose = integrate(self.pose, self.linear, self.angular, dt)

    def stop(self) -> None:
        self.linear = 0.0
        self.angular = 0.0


class Phase(enum.Enum):
    TURN_TO_GOAL = enum.auto()
    DRIVE = enum.auto()
    TURN_TO_YAW = enum.auto()
    DONE = enum.auto()


class GoToPose:
    """Rotate toward the target, drive straight to it, then rotate to its yaw.

    Each command is limited so that one step never overshoots: the last step of each phase
    lands on the target within the tolerances, whatever the step length.
    """

    DRIFT = 0.2
    """Radians off the bearing at which driving stops and the robot turns again."""

    def __init__(
        self,
        target: Pose2D,
        limits: SpeedLimits,
        position_tolerance: float = 0.02,
        yaw_tolerance: float = 0.01,
    ) -> None:
        self.target = target
        self.limits = limits
        self.position_tolerance = position_tolerance
        self.yaw_tolerance = yaw_tolerance
        self.phase = Phase.TURN_TO_GOAL

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    def distance_remaining(self, pose: Pose2D) -> float:
        return math.hypot(self.target.x - pose.x, self.target.y - pose.y)

    def command(self, pose: Pose2D, dt: float) -> tuple[float, float]:
        """(linear, angular) for the next `dt` seconds from `pose`; (0, 0) once done."""
        # A phase that is already satisfied hands over at once, so this loops at most 3 times.
        while True:
            distance = self.distance_remaining(pose)
            bearing_error = normalize_angle(
                math.atan2(self.target.y - pose.y, self.target.x - pose.x) - pose.yaw
            )
            match self.phase:
                case Phase.TURN_TO_GOAL:
                    if distance <= self.position_tolerance:
                        self.phase = Phase.TURN_TO_YAW
                    elif abs(bearing_error) <= self.yaw_tolerance:
                        self.phase = Phase.DRIVE
                    else:
                        return 0.0, self._turn(bearing_error, dt)
                case Phase.DRIVE:
                    if distance <= self.position_tolerance:
                        self.phase = Phase.TURN_TO_YAW
                    elif abs(bearing_error) > self.DRIFT:
                        self.phase = Phase.TURN_TO_GOAL
                    else:
                        linear = min(self.limits.max_linear, distance / dt)
                        return linear, self._turn(bearing_error, dt)
                case Phase.TURN_TO_YAW:
                    yaw_error = normalize_angle(self.target.yaw - pose.yaw)
                    if abs(yaw_error) <= self.yaw_tolerance:
                        self.phase = Phase.DONE
                    else:
                        return 0.0, self._turn(yaw_error, dt)
                case Phase.DONE:
                    return 0.0, 0.0

    def _turn(self, error: float, dt: float) -> float:
        return _clamp(error / dt, self.limits.max_angular)
