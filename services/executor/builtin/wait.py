"""`wait`: pause the sequence for `seconds` ("wait ten seconds" in orders/spoken.yaml)."""

from __future__ import annotations

import asyncio

from shared.errors import OrderFailed
from shared.messages import Order

from ..framework import ExecutionContext, Executor


class Wait(Executor):
    labels = ("wait",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        seconds = order.params.get("seconds", 1)
        if isinstance(seconds, bool) or not isinstance(seconds, int | float) or seconds < 0:
            raise OrderFailed(f"'{order.description}': 'seconds' must be a number >= 0")
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        while (left := end - loop.time()) > 0:
            ctx.progress(f"{left:.0f} s left", percent=100.0 * (1 - left / seconds))
            await asyncio.sleep(min(1.0, left))
        return f"waited {seconds:g} s"
