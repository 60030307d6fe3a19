"""`wait`: pause the sequence for `seconds` ("wait ten seconds" in orders/spoken.yaml)."""

from __future__ import annotations

import asyncio
from typing import Annotated

import msgspec

from voicectl.shared.messages import Order

from ..framework import ExecutionContext, Executor


class Pause(msgspec.Struct):
    seconds: Annotated[float, msgspec.Meta(ge=0)] = 1.0


class Wait(Executor):
    labels = ("wait",)
    params_type = Pause

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        seconds = ctx.params.seconds
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        while (left := end - loop.time()) > 0:
            ctx.progress(f"{left:.0f} s left", percent=100.0 * (1 - left / seconds))
            await asyncio.sleep(min(1.0, left))
        return f"waited {seconds:g} s"
