"""`drive` and `rotate`: closed loops on cmd_vel and odometry, for robots without Nav2.

Distances come from the order's `distance` / `angle` parameters, or else from a
`base_link` target pose (x for drive, yaw for rotate), so the seed's "move forward" and
"turn left" orders work with either label. Speeds can be set per order (`speed` in m/s,
`angular_speed` in rad/s). Each odometry message (20 Hz on the simulator) paces one
command, well inside a base's cmd_vel watchdog.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Annotated

import msgspec

from voicectl.shared.errors import OrderFailed
from voicectl.shared.messages import Order
from voicectl.shared.ros2 import Pose2D

from ..framework import ExecutionContext, Executor

STALL_S = 3.0
"""No progress for this long while commanding motion: the robot is blocked."""
TOLERANCE = 0.02
"""Close enough: metres of a drive, radians of a turn."""


class Straight(msgspec.Struct):
    distance: float | None = None
    """Metres, negative backwards; None: the x of a base_link target pose."""
    speed: Annotated[float, msgspec.Meta(gt=0)] = 0.3

    def __post_init__(self) -> None:
        _finite(distance=self.distance, speed=self.speed)


class Turn(msgspec.Struct):
    angle: float | None = None
    """Radians, positive counter-clockwise; None: the yaw of a base_link target pose."""
    angular_speed: Annotated[float, msgspec.Meta(gt=0)] = 1.0

    def __post_init__(self) -> None:
        _finite(angle=self.angle, angular_speed=self.angular_speed)


def _finite(**values: float | None) -> None:
    """ValueError (a refused order, at once) for a parameter that is not a finite number."""
    for name, value in values.items():
        if value is not None and not math.isfinite(value):
            raise ValueError(f"'{name}' must be a finite number, not {value}")


class Drive(Executor):
    """Drive straight by `distance` metres (negative: backwards)."""

    labels = ("drive",)
    params_type = Straight

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        params: Straight = ctx.params
        distance = _relative_target(order, params.distance, "distance", "x")
        start = await ctx.robot.next_pose()

        def travelled(pose: Pose2D) -> float:
            dx, dy = pose.x - start.x, pose.y - start.y
            return dx * math.cos(start.yaw) + dy * math.sin(start.yaw)

        await _close_loop(ctx, distance, travelled, params.speed, gain=1.5, angular=False)
        return f"drove {distance:g} m"


class Rotate(Executor):
    """Turn in place by `angle` radians (positive: counter-clockwise)."""

    labels = ("rotate",)
    params_type = Turn

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        params: Turn = ctx.params
        angle = _relative_target(order, params.angle, "angle", "yaw")
        turned = _Unwrapped((await ctx.robot.next_pose()).yaw)
        await _close_loop(ctx, angle, turned.update, params.angular_speed, gain=2.0, angular=True)
        side = "left" if angle > 0 else "right"
        return f"turned {side} {math.degrees(abs(angle)):.0f}° ({angle:g} rad)"


async def _close_loop(
    ctx: ExecutionContext,
    goal: float,
    measure: Callable[[Pose2D], float],
    max_speed: float,
    gain: float,
    angular: bool,
) -> None:
    """Command a proportional, capped velocity (angular: a turn in place) until `measure`
    reaches `goal`, reporting what is left; always leave the robot stopped, whether it
    arrived, failed or was cancelled."""
    best = math.inf
    last_progress = asyncio.get_running_loop().time()
    try:
        while True:
            remaining = goal - measure(await ctx.robot.next_pose())
            if not math.isfinite(remaining):
                raise OrderFailed(
                    f"odometry gave a pose that is not finite numbers ({remaining} to go): "
                    "the robot cannot be steered by it"
                )
            if abs(remaining) <= TOLERANCE:
                return
            now = asyncio.get_running_loop().time()
            if abs(remaining) < best - TOLERANCE / 2:
                best, last_progress = abs(remaining), now
            elif now - last_progress > STALL_S:
                raise OrderFailed(f"no progress for {STALL_S:g} s, {abs(remaining):.2f} short")
            speed = max(min(max_speed, gain * abs(remaining)), 0.05 * max_speed)
            velocity = math.copysign(speed, remaining)
            left = abs(remaining)
            done = 100.0 * (1.0 - left / abs(goal)) if goal else None
            if angular:
                ctx.robot.drive(0.0, velocity)
                words = f"{math.degrees(left):.0f}° to turn"
                ctx.progress(words, distance_angular=left, percent=done)
            else:
                ctx.robot.drive(velocity, 0.0)
                ctx.progress(f"{left:.1f} m to go", distance_linear=left, percent=done)
    finally:
        ctx.robot.drive(0.0, 0.0)


class _Unwrapped:
    """Total angle turned since the start, across the ±π wrap."""

    def __init__(self, start_yaw: float) -> None:
        self._last = start_yaw
        self._total = 0.0

    def update(self, pose: Pose2D) -> float:
        step = pose.yaw - self._last
        self._total += math.atan2(math.sin(step), math.cos(step))
        self._last = pose.yaw
        return self._total


def _relative_target(order: Order, explicit: float | None, key: str, pose_field: str) -> float:
    if explicit is not None:
        return explicit
    pose = order.target_pose
    if pose is not None and pose.frame == "base_link":
        return float(getattr(pose, pose_field))
    raise OrderFailed(f"'{order.description}' needs a '{key}' parameter or a base_link target pose")
