"""`mbgoal`: drive to the order's target pose with Nav2's NavigateToPose action.

Progress and results are said as a person would say them: "2.1 m to go", "45° to turn",
"reached kitchen", "turned left 90°", with the frame's numbers after them as a detail.
"""

from __future__ import annotations

import math

from voicectl.shared.errors import OrderFailed
from voicectl.shared.geometry import compose, normalize_angle
from voicectl.shared.messages import Order, TargetPose
from voicectl.shared.ros2 import Pose2D

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
        return done_words(order, target)


def motion_words(order: Order, target: TargetPose) -> str:
    """Where the order goes, in words: 'kitchen', 'left 90°', '2 m forward'."""
    if target.frame != ROBOT_FRAME:
        return order.case or f"({target.x:g}, {target.y:g})"
    move, turn = _relative_words(target)
    return " then ".join(part for part in (move, turn) if part) or "where it stands"


def done_words(order: Order, target: TargetPose) -> str:
    """What the order did, in words: 'reached kitchen', 'turned left 90°', 'moved 2 m forward'."""
    if target.frame != ROBOT_FRAME:
        return f"reached {motion_words(order, target)}"
    move, turn = _relative_words(target)
    said = [f"moved {move}"] if move else []
    said += [f"turned {turn}"] if turn else []
    return ", then ".join(said) or "stayed where it stood"


def _relative_words(target: TargetPose) -> tuple[str, str]:
    """A base_link target's move ('2 m forward') and turn ('left 90°'); '' for none."""
    distance = math.hypot(target.x, target.y)
    way = "forward" if target.x >= 0 else "back"
    move = f"{distance:g} m {way}" if distance >= TURN_ONLY else ""
    degrees = round(math.degrees(abs(target.yaw)))
    if abs(target.yaw) <= math.radians(1):
        return move, ""
    return move, "around" if degrees == 180 else f"{_side(target.yaw)} {degrees}°"


def _side(yaw: float) -> str:
    return "left" if yaw > 0 else "right"
