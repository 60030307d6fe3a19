"""`mul`: the smallest executor, the seed's multiply tutorial."""

from __future__ import annotations

import msgspec

from voicectl.shared.messages import Order

from ..framework import ExecutionContext, Executor


class Factors(msgspec.Struct):
    """The seed tutorial's two numbers."""

    first: float
    second: float


class Multiply(Executor):
    labels = ("mul",)
    params_type = Factors

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        factors: Factors = ctx.params
        first, second = factors.first, factors.second
        ctx.progress(f"multiplying {first:g} by {second:g}")
        return f"{first:g} x {second:g} = {first * second:g}"
