"""User executors loaded by the tests with `--executor tests.executors_for_tests:...`,
the way an integrator binds their own module."""

from __future__ import annotations

import asyncio

from services.executor import ExecutionContext, Executor
from shared.errors import OrderFailed
from shared.messages import Order


class Boom(Executor):
    """Raises like buggy user code does."""

    labels = ("boom",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        raise RuntimeError("kaboom")


class Refuse(Executor):
    labels = ("refuse",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        raise OrderFailed("door is closed")


class Slow(Executor):
    """Reports progress for `seconds` (default 30), honouring cancellation."""

    labels = ("slow",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        seconds = float(order.params.get("seconds", 30))
        steps = int(seconds / 0.1)
        for step in range(steps):
            ctx.progress(f"step {step}", percent=100.0 * step / steps)
            await asyncio.sleep(0.1)
        return "slept"


class Stubborn(Executor):
    """Ignores cancellation for a long time, as a badly written executor might."""

    labels = ("stubborn",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        ctx.progress("running, deaf to cancel")
        for _ in range(600):
            try:
                await asyncio.sleep(0.1)
            except asyncio.CancelledError:
                continue
        return "finally"
