"""The tests' side of the supervisor protocol, shared by the supervisor test files."""

from __future__ import annotations

import asyncio
import uuid
from collections.abc import Callable
from typing import Any

from shared.bus import Bus, json_decoder
from shared.errors import BusError
from shared.keys import RobotKeys
from shared.messages import (
    GetHistory,
    GetState,
    HistoryPage,
    Message,
    Order,
    OrderRecord,
    State,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
)


def order(label: str, **params: Any) -> Order:
    return Order(order=label, label=label, description=f"do {label}", params=params)


class Client:
    """The test's side of the supervisor protocol."""

    def __init__(self, bus: Bus, robot: str) -> None:
        self.bus = bus
        self.keys = RobotKeys(robot)
        self._decode = json_decoder(SupervisorReply)

    async def ask(self, request: Message) -> SupervisorReply:
        reply: SupervisorReply = await self.bus.request(
            self.keys.supervisor, request, self._decode, timeout=10.0
        )
        return reply

    async def ask_submit(self, *orders: Order) -> SupervisorReply:
        """Submit and return whatever the supervisor answers (a refusal too)."""
        return await self.ask(Submit(request_id=uuid.uuid4().hex, orders=list(orders)))

    async def submit(self, *orders: Order, request_id: str | None = None) -> list[str]:
        reply = await self.ask(
            Submit(request_id=request_id or uuid.uuid4().hex, orders=list(orders))
        )
        assert isinstance(reply, Submitted), reply
        return reply.order_ids

    async def state(self) -> State:
        reply = await self.ask(GetState())
        assert isinstance(reply, StateReply), reply
        return reply.state

    async def history(self, offset: int = 0, limit: int = 500) -> HistoryPage:
        reply = await self.ask(GetHistory(offset=offset, limit=limit))
        assert isinstance(reply, HistoryPage), reply
        return reply

    async def finished(self, order_id: str, timeout: float = 20.0) -> OrderRecord:
        found: list[OrderRecord] = []

        async def check() -> bool:
            found[:] = [r for r in (await self.history()).records if r.id == order_id]
            return bool(found)

        deadline = asyncio.get_running_loop().time() + timeout
        while not await check():
            assert asyncio.get_running_loop().time() < deadline, f"{order_id} never finished"
            await asyncio.sleep(0.05)
        return found[0]

    async def wait_state(self, predicate: Callable[[State], bool], what: str) -> State:
        states: list[State] = []

        async def poll() -> None:
            while True:
                state = await self.state()
                if predicate(state):
                    states.append(state)
                    return
                await asyncio.sleep(0.05)

        try:
            await asyncio.wait_for(poll(), 20.0)
        except TimeoutError:
            raise AssertionError(f"timed out waiting for {what}") from None
        return states[0]


async def client_wait_ready(client: Client, executor: bool = True) -> None:
    """Wait for the supervisor to answer, and (by default) to see its executor."""
    for _ in range(400):
        try:
            if (await client.state()).executor_online or not executor:
                return
        except BusError:
            pass  # supervisor not up yet
        await asyncio.sleep(0.05)
    raise AssertionError("supervisor never saw the executor")
