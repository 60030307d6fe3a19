"""The supervisor on the bus: answers requests, dispatches to the executor, publishes state."""

from __future__ import annotations

import asyncio
import contextlib
import logging

from shared.bus import Bus, json_decoder
from shared.errors import BusError
from shared.keys import RobotKeys
from shared.messages import (
    Accepted,
    Cancel,
    CancelAll,
    CancelOrder,
    Done,
    EmergencyStop,
    Execute,
    ExecutorEvent,
    ExecutorReply,
    Failed,
    GetState,
    Halt,
    Message,
    OrderFinished,
    OrderProgress,
    OrderStatus,
    Rejected,
    StateReply,
    StateUpdate,
    Submit,
    Submitted,
    SupervisorRequest,
)

from .queue import RobotQueue

_LOGGER = logging.getLogger(__name__)

EXECUTOR_TIMEOUT = 5.0
"""How long the executor may take to accept an order or a cancel."""


class RobotSupervisor:
    """Everything one robot's supervisor does; one instance per robot, one process for all."""

    def __init__(self, bus: Bus, queue: RobotQueue) -> None:
        self._bus = bus
        self._queue = queue
        self._keys = RobotKeys(queue.robot)
        self._wake = asyncio.Event()
        self._reply_decode = json_decoder(ExecutorReply)

    async def run(self) -> None:
        """Serve until cancelled."""
        self._bus.serve(self._keys.supervisor, json_decoder(SupervisorRequest), self.handle)
        self._bus.subscribe(self._keys.executor_events, json_decoder(ExecutorEvent), self._on_event)
        self._bus.watch(self._keys.alive("executor"), self._on_executor_presence)
        self._bus.announce(self._keys.alive("supervisor"))
        self._changed()
        while True:
            await self._wake.wait()
            self._wake.clear()
            record = self._queue.start_next()
            if record is not None:
                self._changed()
                await self._dispatch(record.id, Execute(order_id=record.id, order=record.order))

    async def handle(self, request: SupervisorRequest) -> Message:
        match request:
            case Submit(request_id=request_id, orders=orders, transcript=transcript):
                if not request_id:
                    return Failed(reason="submit needs a non-empty request_id")
                ids = self._queue.submit(request_id, orders, transcript)
                _LOGGER.info("%s: request %s -> orders %s", self._queue.robot, request_id, ids)
                self._changed()
                return Submitted(order_ids=ids)
            case Cancel(order_id=order_id):
                return await self._cancel(order_id)
            case CancelAll():
                cleared = self._queue.clear_queue("cancelled by user")
                if self._queue.current is not None:
                    await self._cancel(self._queue.current.id)
                self._changed()
                return Done(detail=f"cancelled {cleared} queued order(s) and the current one")
            case EmergencyStop():
                # Clear the queue first (in memory, instant) so that nothing is dispatched
                # when the current order ends; then the halt goes straight to the executor,
                # outside any queue.
                cleared = self._queue.clear_queue("emergency stop")
                self._changed()
                halted = await self._send_control(Halt())
                if isinstance(halted, Failed):
                    return halted
                return Done(detail=f"halted; cancelled {cleared} queued order(s)")
            case GetState():
                return StateReply(state=self._queue.snapshot())

    async def _cancel(self, order_id: str) -> Message:
        if self._queue.remove_queued(order_id, "cancelled by user"):
            self._changed()
            return Done(detail=f"removed {order_id} from the queue")
        current = self._queue.current
        if current is None or current.id != order_id:
            return Failed(reason=f"order '{order_id}' is neither queued nor running")
        reply = await self._send_control(CancelOrder(order_id=order_id))
        if isinstance(reply, Failed) and self._queue.finish(
            order_id, OrderStatus.CANCELLED, f"cancelled; executor: {reply.reason}"
        ):
            self._changed()
        return Done(detail=f"cancelling {order_id}")

    async def _send_control(self, request: CancelOrder | Halt) -> Message:
        try:
            return await self._bus.request(
                self._keys.executor_control, request, self._reply_decode, EXECUTOR_TIMEOUT
            )
        except BusError as exc:
            return Failed(reason=f"executor unreachable: {exc}")

    async def _dispatch(self, order_id: str, execute: Execute) -> None:
        try:
            reply = await self._bus.request(
                self._keys.executor_execute, execute, self._reply_decode, EXECUTOR_TIMEOUT
            )
        except BusError as exc:
            self._finish(order_id, OrderStatus.FAILED, f"executor did not take it: {exc}")
            return
        match reply:
            case Accepted():
                _LOGGER.info("%s: %s started", self._queue.robot, order_id)
            case Rejected(reason=reason):
                self._finish(order_id, OrderStatus.REJECTED, reason)
            case Failed(reason=reason):
                self._finish(order_id, OrderStatus.FAILED, reason)
            case Done():
                self._finish(order_id, OrderStatus.FAILED, "executor answered out of protocol")

    def _on_event(self, _key: str, event: ExecutorEvent) -> None:
        match event:
            case OrderProgress(order_id=order_id, progress=progress):
                if self._queue.progress(order_id, progress):
                    self._publish()
            case OrderFinished(order_id=order_id, status=status, message=message):
                if status not in (
                    OrderStatus.SUCCEEDED,
                    OrderStatus.FAILED,
                    OrderStatus.CANCELLED,
                ):
                    _LOGGER.warning("ignored result %s for %s", status, order_id)
                    return
                self._finish(order_id, status, message)

    def _on_executor_presence(self, _key: str, alive: bool) -> None:
        _LOGGER.info("%s: executor %s", self._queue.robot, "online" if alive else "lost")
        self._queue.executor_online = alive
        current = self._queue.current
        if not alive and current is not None:
            self._queue.finish(current.id, OrderStatus.FAILED, "executor lost")
        self._changed()

    def _finish(self, order_id: str, status: OrderStatus, message: str) -> None:
        if self._queue.finish(order_id, status, message):
            _LOGGER.info("%s: %s %s %s", self._queue.robot, order_id, status, message)
            self._changed()

    def _changed(self) -> None:
        self._publish()
        self._wake.set()

    def _publish(self) -> None:
        self._bus.publish(self._keys.state, StateUpdate(state=self._queue.snapshot()))


async def run_supervisors(supervisors: list[RobotSupervisor]) -> None:
    """Run every robot's supervisor until cancelled."""
    tasks = [asyncio.create_task(s.run()) for s in supervisors]
    try:
        await asyncio.gather(*tasks)
    finally:
        for task in tasks:
            task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.gather(*tasks, return_exceptions=True)
