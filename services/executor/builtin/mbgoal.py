"""`mbgoal`: drive to the order's target pose with Nav2's NavigateToPose action."""

from __future__ import annotations

from shared.errors import OrderFailed
from shared.messages import Order
from shared.ros2 import Pose2D

from ..framework import ExecutionContext, Executor


class NavigateToPose(Executor):
    labels = ("mbgoal",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        target = order.target_pose
        if target is None:
            raise OrderFailed(f"'{order.description}' has no target pose (frame, x, y, yaw)")

        def on_feedback(_pose: Pose2D, remaining: float) -> None:
            ctx.progress(f"{remaining:.2f} m to go", distance_linear=remaining)

        ctx.progress(f"navigating to {target.frame} ({target.x:g}, {target.y:g})")
        await ctx.robot.navigate(target, on_feedback)
        return f"reached {target.frame} ({target.x:g}, {target.y:g}, yaw {target.yaw:g})"
