"""`mul`: the smallest executor, the seed's multiply tutorial."""

from __future__ import annotations

from shared.errors import OrderFailed
from shared.messages import Order

from ..framework import ExecutionContext, Executor


class Multiply(Executor):
    labels = ("mul",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        a, b = order.params.get("a"), order.params.get("b")
        if not isinstance(a, int | float) or not isinstance(b, int | float):
            raise OrderFailed(f"'{order.description}' needs numeric parameters a and b")
        ctx.progress(f"multiplying {a} by {b}")
        return f"{a} x {b} = {a * b}"
