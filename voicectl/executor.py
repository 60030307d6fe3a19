"""What a behaviour is written with, in one import:

    from voicectl.executor import ExecutionContext, Executor, Order, OrderFailed

An `Executor` subclass names the labels it carries out and, optionally, the msgspec
Struct its parameters decode into; `execute(order, ctx)` does the work through
`ctx.robot`, reports with `ctx.progress(...)`, returns its result in words or raises
`OrderFailed` with the reason (docs/executors.md). This module is the stable surface;
the packages behind it may move.
"""

from voicectl.services.executor.fence import OrderRobot
from voicectl.services.executor.framework import ExecutionContext, Executor
from voicectl.shared.errors import OrderFailed
from voicectl.shared.messages import Order, TargetPose
from voicectl.shared.ros2 import Pose2D

__all__ = [
    "ExecutionContext",
    "Executor",
    "Order",
    "OrderFailed",
    "OrderRobot",
    "Pose2D",
    "TargetPose",
]
