"""One robot's orders as a plain state machine: no I/O, so every rule is testable alone."""

from __future__ import annotations

import time
import uuid
from collections import deque
from collections.abc import Callable

import msgspec

from shared.messages import Order, OrderRecord, OrderStatus, Progress, State

FINAL = frozenset(
    {OrderStatus.SUCCEEDED, OrderStatus.FAILED, OrderStatus.CANCELLED, OrderStatus.REJECTED}
)


class RobotQueue:
    """Queue, current order and history of one robot.

    The failure policy lives here: when an order fails or is rejected, the orders queued
    from the same utterance are cancelled, since later steps usually assume earlier ones
    happened (`continue_on_failure` turns that off).
    """

    def __init__(
        self,
        robot: str,
        *,
        clock: Callable[[], float] = time.time,
        history_limit: int = 200,
        continue_on_failure: bool = False,
    ) -> None:
        self.robot = robot
        self.executor_online = False
        self.current: OrderRecord | None = None
        self.queue: deque[OrderRecord] = deque()
        self.history: deque[OrderRecord] = deque(maxlen=history_limit)
        self._clock = clock
        self._continue_on_failure = continue_on_failure
        self._requests: dict[str, list[str]] = {}

    def submit(self, request_id: str, orders: list[Order], transcript: str) -> list[str]:
        """Queue `orders`; the same `request_id` again returns the first answer, queues nothing."""
        if request_id in self._requests:
            return self._requests[request_id]
        now = self._clock()
        records = [
            OrderRecord(
                id=uuid.uuid4().hex[:12],
                order=order,
                status=OrderStatus.QUEUED,
                transcript=transcript,
                request_id=request_id,
                submitted_at=now,
            )
            for order in orders
        ]
        self.queue.extend(records)
        ids = [r.id for r in records]
        self._requests[request_id] = ids
        return ids

    def start_next(self) -> OrderRecord | None:
        """The next order to hand to the executor, now marked running; None if not now."""
        if self.current is not None or not self.queue or not self.executor_online:
            return None
        record = self.queue.popleft()
        self.current = msgspec.structs.replace(
            record, status=OrderStatus.RUNNING, started_at=self._clock()
        )
        return self.current

    def progress(self, order_id: str, progress: Progress) -> bool:
        if self.current is None or self.current.id != order_id:
            return False
        self.current = msgspec.structs.replace(self.current, progress=progress)
        return True

    def finish(self, order_id: str, status: OrderStatus, message: str = "") -> bool:
        """End the current order; False if `order_id` is not the current one (stale event)."""
        if status not in FINAL:
            raise ValueError(f"{status} is not a final status")
        if self.current is None or self.current.id != order_id:
            return False
        record = self.current
        self.current = None
        self._to_history(record, status, message)
        if status in (OrderStatus.FAILED, OrderStatus.REJECTED) and not self._continue_on_failure:
            for sibling in [r for r in self.queue if r.request_id == record.request_id]:
                self.queue.remove(sibling)
                self._to_history(
                    sibling, OrderStatus.CANCELLED, f"an earlier order failed: {record.id}"
                )
        return True

    def remove_queued(self, order_id: str, message: str) -> bool:
        for record in self.queue:
            if record.id == order_id:
                self.queue.remove(record)
                self._to_history(record, OrderStatus.CANCELLED, message)
                return True
        return False

    def clear_queue(self, message: str) -> int:
        count = len(self.queue)
        while self.queue:
            self._to_history(self.queue.popleft(), OrderStatus.CANCELLED, message)
        return count

    def snapshot(self, history: int = 20) -> State:
        return State(
            robot=self.robot,
            executor_online=self.executor_online,
            current=self.current,
            queue=list(self.queue),
            history=list(self.history)[:history],
        )

    def _to_history(self, record: OrderRecord, status: OrderStatus, message: str) -> None:
        ended = msgspec.structs.replace(
            record, status=status, message=message, ended_at=self._clock()
        )
        self.history.appendleft(ended)
