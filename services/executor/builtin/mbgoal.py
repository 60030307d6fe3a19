"""`mbgoal`: drive to the order's target pose with Nav2's NavigateToPose action.

Progress and results are said as a person would say them: "2.1 m to go", "45° to turn",
"reached kitchen", "turned left 90°", with the frame's numbers after them as a detail.
"""

from __future__ import annotations

import math

from shared.errors import OrderFailed
from shared.geometry import compose, normalize_angle
from shared.messages import Order, TargetPose
from shared.ros2 import Pose2D

from ..framework import ExecutionContext, Executor

ROBOT_FRAME = "base_link"
TURN_ONLY = 0.05
"""Metres: a relative goal nearer than this is a turn in place."""


class NavigateToPose(Executor):
    labels = ("mbgoal",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        target = order.target_pose
        if target is None:
            raise OrderFailed(f"'{order.description}' has no target pose (frame, x, y, yaw)")
        start = ctx.robot.pose
        relative = target.frame == ROBOT_FRAME
        turning = relative and math.hypot(target.x, target.y) < TURN_ONLY
        heading = None
        if turning and start is not None:
            heading = compose(start, Pose2D(0.0, 0.0, target.yaw)).yaw
        first: list[float] = []

        def on_feedback(pose: Pose2D, remaining: float) -> None:
            if heading is not None:
                left = abs(normalize_angle(heading - pose.yaw))
                done = 100.0 * (1.0 - left / abs(target.yaw)) if target.yaw else None
                ctx.progress(
                    f"{math.degrees(left):.0f}° to turn", distance_angular=left, percent=done
                )
                return
            if not first:
                first.append(remaining)
            done = 100.0 * (1.0 - remaining / first[0]) if first[0] > 0 else None
            ctx.progress(f"{remaining:.1f} m to go", distance_linear=remaining, percent=done)

        ctx.progress(f"on the way: {motion_words(order, target)}")
        await ctx.robot.navigate(target, on_feedback)
        return f"{done_words(order, target)} ({_numbers(target)})"


def motion_words(order: Order, target: TargetPose) -> str:
    """Where the order goes, in words: 'kitchen', 'left 90°', '2 m forward'."""
    if target.frame != ROBOT_FRAME:
        return order.case or f"({target.x:g}, {target.y:g})"
    parts = []
    distance = math.hypot(target.x, target.y)
    if distance >= TURN_ONLY:
        parts.append(f"{distance:g} m {'forward' if target.x >= 0 else 'back'}")
    if abs(target.yaw) > math.radians(1):
        degrees = round(math.degrees(abs(target.yaw)))
        parts.append("around" if degrees == 180 else f"{_side(target.yaw)} {degrees}°")
    return " then ".join(parts) or "where it stands"


def done_words(order: Order, target: TargetPose) -> str:
    """What the order did, in words: 'reached kitchen', 'turned left 90°', 'moved 2 m forward'."""
    if target.frame != ROBOT_FRAME:
        return f"reached {order.case}" if order.case else f"reached ({target.x:g}, {target.y:g})"
    said = []
    distance = math.hypot(target.x, target.y)
    if distance >= TURN_ONLY:
        said.append(f"moved {distance:g} m {'forward' if target.x >= 0 else 'back'}")
    if abs(target.yaw) > math.radians(1):
        degrees = round(math.degrees(abs(target.yaw)))
        turn = "around" if degrees == 180 else f"{_side(target.yaw)} {degrees}°"
        said.append(f"turned {turn}")
    return ", then ".join(said) or "stayed where it stood"


def _side(yaw: float) -> str:
    return "left" if yaw > 0 else "right"


def _numbers(target: TargetPose) -> str:
    return f"{target.frame} {target.x:g}, {target.y:g}, yaw {target.yaw:g}"
