"""The last word on what reaches a motor, whoever sends it: a velocity command (a Twist or
TwistStamped) with an axis that is not a finite number never leaves on any transport.

Every transport's `publish` asks `unsafe_velocity` before the bytes go (transport.py); the
executor decides earlier, and also holds orders to the speed limits
(services/executor/speed.py). This check is the one no sender can skip: NaN is false in
every comparison, so a clamp passes it and a test for zero misses it, and a robot's base
may read it as its top speed.
"""

from __future__ import annotations

import functools
import math

from ..kinds import CmdVelType, RosDistro
from ..ros2 import CdrError, Ros2Codec

AXES = ("linear.x", "linear.y", "linear.z", "angular.x", "angular.y", "angular.z")


@functools.cache
def _codec() -> Ros2Codec:
    """A velocity's layout is the same in every distribution voicectl speaks."""
    return Ros2Codec(RosDistro.JAZZY)


def unsafe_velocity(ros_type: str, payload: bytes) -> str | None:
    """Why message `payload` of `ros_type` must not reach the robot: a velocity command
    with an axis that is NaN or infinite, said in one line; None for a velocity whose axes
    are all finite, for any other type, and for bytes no robot reads as a velocity."""
    kind = CmdVelType.of(ros_type)
    if kind is None:
        return None
    try:
        axes = _codec().velocity_axes(kind, payload)
    except CdrError:
        return None  # not a velocity at all: the robot drops it as voicectl would
    named = zip(AXES, axes, strict=True)
    wrong = [f"{axis} {value}" for axis, value in named if not math.isfinite(value)]
    if not wrong:
        return None
    return f"a velocity with {', '.join(wrong)}: every axis must be a finite number"


def stilled(ros_type: str, payload: bytes) -> bytes:
    """The velocity command `payload` of `ros_type` with every axis zero (a stamped one's
    header kept): what goes out instead of one `unsafe_velocity` refuses."""
    kind = CmdVelType.of(ros_type)
    if kind is None:
        raise ValueError(f"{ros_type} is not a velocity command")
    return _codec().stilled(kind, payload)
