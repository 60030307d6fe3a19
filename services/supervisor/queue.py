"""One robot's orders as a plain state machine: no I/O, so every rule is testable alone.

Every mutation also records what changed (`take_changes`), which the service writes to
the store; the queue itself never touches a file or the bus.
"""

from __future__ import annotations

import hashlib
import itertools
import random
import time
from collections import deque
from collections.abc import Callable

import msgspec

from voicectl.shared.errors import VoicectlError
from voicectl.shared.messages import Asked, Order, OrderRecord, OrderStatus, Progress, State

FINAL = frozenset(
    {
        OrderStatus.SUCCEEDED,
        OrderStatus.FAILED,
        OrderStatus.CANCELLED,
        OrderStatus.REJECTED,
        OrderStatus.INTERRUPTED,
    }
)
BREAKS_SEQUENCE = frozenset({OrderStatus.FAILED, OrderStatus.REJECTED, OrderStatus.INTERRUPTED})
_ENDED = {
    OrderStatus.SUCCEEDED: "succeeded",
    OrderStatus.FAILED: "failed",
    OrderStatus.CANCELLED: "was cancelled",
    OrderStatus.REJECTED: "was refused",
    OrderStatus.INTERRUPTED: "was interrupted",
}
"""How an order ended, after its description ("turn left was refused")."""
"""Results after which the rest of the same utterance is cancelled (unless configured not to).
An order ended by a loss (of its executor, or of the supervisor while it ran) breaks it too,
whatever its status says: see `finish`."""
SNAPSHOT_QUEUE = 20
SNAPSHOT_HISTORY = 20


RECENT_REQUESTS = 10_000
"""Request ids remembered in memory to answer retries; older ones are forgotten, so that a
long-running supervisor does not grow with every submit it ever took."""


PAUSED_ASKED = "paused when asked: say go on, or press Resume"
"""Why the queue waits after a person said "pause": unlike a restart's pause, it holds
until someone lets it go, even once the queue has run empty."""


MAX_QUEUE = 1000
"""Orders queued at most per robot (`--max-queue`): a robot works through a few orders a
minute, and every queued one costs memory and a row in each state snapshot's count."""


class RequestConflict(VoicectlError):
    """A submit whose request id was already used for other orders."""


class QueueFull(VoicectlError):
    """A submit whose orders would take the queue past its cap: none of them is queued."""


class RobotQueue:
    """Queue, current order and recent history of one robot.

    The failure policy lives here: when an order fails, is rejected or is interrupted, the
    orders queued from the same utterance are cancelled, since later steps usually assume
    earlier ones happened (`continue_on_failure` turns that off).
    """

    def __init__(
        self,
        robot: str,
        *,
        clock: Callable[[], float] = time.time,
        history_limit: int = 50,
        continue_on_failure: bool = False,
        max_queue: int = MAX_QUEUE,
    ) -> None:
        self.robot = robot
        self._max_queue = max_queue
        self.executor_online = False
        self.current: OrderRecord | None = None
        self.current_verified = True
        """False while a current order restored from the store awaits the executor's word."""
        self.stopped = False
        """The emergency stop is latched: no order starts, none is accepted."""
        self.ending: str | None = None
        """The order an emergency stop ended here whose end its executor has not reported
        yet: none starts before it does (`finish`), or before `stop_waiting`."""
        self.stop_detail = ""
        """What answered the last emergency stop, as it came in."""
        self.paused = ""
        """Why queued orders wait (restored after a restart); '' when they run."""
        self.queue: deque[OrderRecord] = deque()
        self.history: deque[OrderRecord] = deque(maxlen=history_limit)
        self._clock = clock
        self._continue_on_failure = continue_on_failure
        self._requests: dict[str, list[str]] = {}
        self._digests: dict[str, bytes] = {}
        """What each request id of this run carried, to tell a retry from a conflict."""
        self._positions: dict[str, float] = {}
        self._next_position = 0.0
        self._changed: dict[str, OrderRecord] = {}
        self._new_requests: list[tuple[str, list[str]]] = []
        self.touched: str | None = None
        """The order last added or moved, which "after that" puts the next ones after."""
        self.stopping: dict[str, str] = {}
        """Running orders an edit is stopping, and what their record will say ended them."""
        self.undo_words = ""
        """The edit an "undo" would take back now, as said; '' when none."""
        # Order ids: 64 random bits from a generator seeded once by the OS; uuid4 asks the
        # OS for every id, which showed up in profiles of submit bursts.
        self._ids = random.Random()

    # --- restoring --------------------------------------------------------------------------

    def restore(
        self,
        open_orders: list[tuple[OrderRecord, float]],
        history: list[OrderRecord],
        requests: dict[str, list[str]],
    ) -> None:
        """Take back what the store held: queued orders in order, a running one as current
        (unverified until the executor says whether it still runs it)."""
        for record, position in open_orders:
            self._positions[record.id] = position
            self._next_position = max(self._next_position, position + 1.0)
            if record.status == OrderStatus.RUNNING and self.current is None:
                self.current = record
                self.current_verified = False
            else:
                self.queue.append(record)
        self.history.extend(history)
        self._requests.update(requests)
        if self.queue:
            # Nothing moves at start-up unasked: orders from before the restart wait.
            self.paused = (
                f"{len(self.queue)} order(s) restored after a restart: resume or cancel them"
            )

    # --- changes ------------------------------------------------------------------------------

    def submit(
        self,
        request_id: str,
        orders: list[Order],
        transcript: str,
        asked: Asked | None = None,
        at: int | None = None,
    ) -> list[str]:
        """Queue `orders` (at the end, or from index `at` of the queue on); the same
        `request_id` again returns the first answer, queues nothing. The same id with
        other orders is a RequestConflict: never dropped quietly. Orders past the queue's
        cap are a QueueFull, and none of them is queued."""
        digest = hashlib.blake2b(msgspec.json.encode(orders), digest_size=16).digest()
        if request_id in self._requests:
            if self._digests.get(request_id, digest) != digest:
                raise RequestConflict(
                    f"request id '{request_id}' was used for other orders; send these "
                    "with a new request id"
                )
            return self._requests[request_id]
        if len(self.queue) + len(orders) > self._max_queue:
            raise QueueFull(
                f"robot '{self.robot}' has {len(self.queue)} orders queued and takes at most "
                f"{self._max_queue} (--max-queue): none of these {len(orders)} was queued; "
                "cancel some, or wait for them to run"
            )
        self._digests[request_id] = digest
        now = self._clock()
        records = [
            OrderRecord(
                id=self.new_id(),
                order=order,
                status=OrderStatus.QUEUED,
                transcript=transcript,
                request_id=request_id,
                submitted_at=now,
                asked=asked,
            )
            for order in orders
        ]
        if at is None or at >= len(self.queue):
            for record in records:
                self._positions[record.id] = self._next_position
                self._next_position += 1.0
                self.queue.append(record)
                self._changed[record.id] = record
        else:
            self._insert(records, at)
        ids = [r.id for r in records]
        self.remember(request_id, ids)
        if ids:
            self.touched = ids[-1]
        return ids

    def now(self) -> float:
        return self._clock()

    def new_id(self) -> str:
        return f"{self._ids.getrandbits(64):016x}"

    def remember(self, request_id: str, ids: list[str]) -> None:
        """What `request_id` did (the orders it queued, or an edit's record), to answer its
        retries; kept on disk too."""
        self._requests[request_id] = ids
        self._new_requests.append((request_id, ids))
        while len(self._requests) > RECENT_REQUESTS:  # a retry comes within seconds
            oldest = next(iter(self._requests))
            del self._requests[oldest]
            self._digests.pop(oldest, None)

    def answered(self, request_id: str) -> list[str] | None:
        """What `request_id` did, if it was taken before."""
        return self._requests.get(request_id)

    def _insert(self, records: list[OrderRecord], at: int) -> None:
        """`records` into the queue from index `at` on, at positions between their new
        neighbours' (the whole queue numbered afresh when the gap runs out)."""
        before = self._positions[self.queue[at - 1].id] if at > 0 else None
        after = self._positions[self.queue[at].id]
        if before is None:
            before = after - len(records) - 1.0
        step = (after - before) / (len(records) + 1)
        for offset, record in enumerate(records):
            self.queue.insert(at + offset, record)
            self._positions[record.id] = before + step * (offset + 1)
            self._changed[record.id] = record
        spaced = [self._positions[r.id] for r in self.queue]
        if any(a >= b for a, b in itertools.pairwise(spaced)):
            self._renumber()

    def open_records(self) -> list[OrderRecord]:
        """The running order, then the queued ones, in dispatch order."""
        return ([self.current] if self.current is not None else []) + list(self.queue)

    def position_of(self, order_id: str) -> float:
        return self._positions.get(order_id, 0.0)

    def head_position(self) -> float:
        """A position before every queued order's."""
        return (self._positions[self.queue[0].id] if self.queue else self._next_position) - 1.0

    def reopen(self, record: OrderRecord, position: float) -> OrderRecord:
        """Queue `record` again at `position` (an edit that ended it is undone): queued, as
        it was before it started or ended, with its id; out of the history."""
        for index, old in enumerate(self.history):
            if old.id == record.id:
                del self.history[index]
                break
        again = msgspec.structs.replace(
            record,
            status=OrderStatus.QUEUED,
            message="",
            progress=None,
            started_at=None,
            ended_at=None,
        )
        self._place(again, position)
        return again

    def move_to(self, order_id: str, position: float) -> bool:
        """Put a queued order back at the `position` it had; False if it is not queued."""
        record = next((r for r in self.queue if r.id == order_id), None)
        if record is None:
            return False
        self.queue.remove(record)
        self._place(record, position)
        return True

    def _place(self, record: OrderRecord, position: float) -> None:
        index = next(
            (i for i, r in enumerate(self.queue) if self._positions[r.id] > position),
            len(self.queue),
        )
        self.queue.insert(index, record)
        self._positions[record.id] = position
        self._next_position = max(self._next_position, position + 1.0)
        self._changed[record.id] = record

    def note(self, record: OrderRecord) -> None:
        """A finished record that never queued (an edit of the queue) into the history."""
        self.history.appendleft(record)
        self._changed[record.id] = record

    def knows(self, request_id: str) -> bool:
        """Whether `request_id` was taken before (a submit with it again is a retry)."""
        return request_id in self._requests

    def withdraw(self, request_id: str) -> None:
        """Undo a submit whose orders could not be stored: they were never accepted. One
        of them may be current, its start being written: it was never sent, and is not
        current any more."""
        self._digests.pop(request_id, None)
        ids = set(self._requests.pop(request_id, []))
        for record in [r for r in self.queue if r.id in ids]:
            self.queue.remove(record)
            self._positions.pop(record.id, None)
        if self.current is not None and self.current.id in ids:
            self._positions.pop(self.current.id, None)
            self._changed.pop(self.current.id, None)
            self.current = None

    def unstart(self, order_id: str) -> bool:
        """Put the current order `order_id` back at the head of the queue, as queued: its
        start could not be recorded, so it was never sent. False if it is not current."""
        if self.current is None or self.current.id != order_id:
            return False
        record = msgspec.structs.replace(
            self.current, status=OrderStatus.QUEUED, started_at=None, progress=None
        )
        self.current = None
        self._changed.pop(order_id, None)  # the store still has it queued
        self.queue.appendleft(record)
        return True

    def start_next(self) -> OrderRecord | None:
        """The next order to hand to the executor, now marked running; None if not now."""
        if self.current is not None or not self.queue or not self.executor_online:
            return None
        if self.ending is not None:
            return None
        if self.stopped or self.paused:
            return None
        record = self.queue.popleft()
        self.current = msgspec.structs.replace(
            record, status=OrderStatus.RUNNING, started_at=self._clock()
        )
        self.current_verified = True
        self._changed[record.id] = self.current
        return self.current

    def progress(self, order_id: str, progress: Progress) -> bool:
        """Fold progress into the current order (not persisted: it changes too often)."""
        if self.current is None or self.current.id != order_id:
            return False
        self.current = msgspec.structs.replace(self.current, progress=progress)
        return True

    def finish(
        self, order_id: str, status: OrderStatus, message: str = "", lost: bool = False
    ) -> bool:
        """End the current order; False if `order_id` is not the current one (stale event).
        One that failed, was rejected or interrupted, or that ended by a loss (`lost`: its
        executor, or this supervisor, went while it ran; the executor then ends an order
        that moved the robot as cancelled) cancels the rest of its utterance: later steps
        assume earlier ones happened, and nobody saw how this one ended. One rule, the safe
        one, whichever side was lost."""
        if status not in FINAL:
            raise ValueError(f"{status} is not a final status")
        if order_id == self.ending:
            self.ending = None
            self._amend(order_id, status, message)
            return True
        if self.current is None or self.current.id != order_id:
            return False
        record = self.current
        self.current = None
        self.current_verified = True
        edited = self.stopping.pop(order_id, None)
        if edited is not None and status is OrderStatus.CANCELLED:
            message = edited  # the executor's "cancelled" says less than the edit that did
        self._to_history(record, status, message)
        broken = status in BREAKS_SEQUENCE or (lost and status is not OrderStatus.SUCCEEDED)
        if broken and not self._continue_on_failure:
            # Said for a person, who knows the order by what it does: the request id ties
            # them together for a program.
            why = f"cancelled because “{record.order.description}” before it {_ENDED[status]}"
            for sibling in [r for r in self.queue if r.request_id == record.request_id]:
                self.queue.remove(sibling)
                self._to_history(sibling, OrderStatus.CANCELLED, why)
        return True

    def stop_current(self, message: str) -> OrderRecord | None:
        """End the running order for an emergency stop, at once: from the stop on it may
        not command the robot, so it runs no more, and the state never says stopped
        beside it. Its executor's word on how it ended, when it comes, is taken
        (`finish`); until then no other order starts."""
        record = self.current
        if record is None:
            return None
        self.current = None
        self.current_verified = True
        self.ending = record.id
        self._to_history(record, OrderStatus.CANCELLED, message)
        return record

    def stop_waiting(self, order_id: str) -> bool:
        """Start orders again without the executor's word on `order_id`, which an
        emergency stop ended; False if that was not awaited."""
        if self.ending != order_id:
            return False
        self.ending = None
        return True

    def _amend(self, order_id: str, status: OrderStatus, message: str) -> None:
        """An ended order's record as its executor says it ended (it may have finished
        just before the stop reached it)."""
        for index, record in enumerate(self.history):
            if record.id == order_id:
                if (record.status, record.message) != (status, message):
                    amended = msgspec.structs.replace(record, status=status, message=message)
                    self.history[index] = amended
                    self._changed[order_id] = amended
                return

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

    def reorder(self, order_id: str, position: int) -> int | None:
        """Move a queued order to `position` (clamped to the queue); returns the position
        it got, or None if it is not queued."""
        record = next((r for r in self.queue if r.id == order_id), None)
        if record is None:
            return None
        self.queue.remove(record)
        position = max(0, min(position, len(self.queue)))
        self.queue.insert(position, record)
        # A position between the neighbours': only the moved order changes in the store.
        before = self._positions[self.queue[position - 1].id] if position > 0 else None
        after = (
            self._positions[self.queue[position + 1].id] if position + 1 < len(self.queue) else None
        )
        if before is None and after is None:
            new = self._positions[order_id]
        elif before is None:
            assert after is not None
            new = after - 1.0
        elif after is None:
            new = before + 1.0
            self._next_position = max(self._next_position, new + 1.0)
        else:
            new = (before + after) / 2.0
            if not before < new < after:
                # Halving the gap again and again runs out of floats (about 50 times):
                # number the whole queue afresh instead.
                self._renumber()
                return position
        self._positions[order_id] = new
        self._changed[order_id] = record
        return position

    def _renumber(self) -> None:
        start = self._positions[self.queue[0].id] if self.queue else self._next_position
        for offset, record in enumerate(self.queue):
            self._positions[record.id] = start + offset
            self._changed[record.id] = record
        self._next_position = max(self._next_position, start + len(self.queue))

    def take_changes(self) -> tuple[list[tuple[OrderRecord, float]], list[tuple[str, list[str]]]]:
        """What changed since the last call: records with their positions, and new requests."""
        records = [(r, self._positions.get(r.id, 0.0)) for r in self._changed.values()]
        requests = self._new_requests
        self._changed = {}
        self._new_requests = []
        return records, requests

    def snapshot(self) -> State:
        return State(
            robot=self.robot,
            executor_online=self.executor_online,
            current=self.current,
            queue=[self.queue[i] for i in range(min(SNAPSHOT_QUEUE, len(self.queue)))],
            queue_length=len(self.queue),
            history=[self.history[i] for i in range(min(SNAPSHOT_HISTORY, len(self.history)))],
            stopped=self.stopped,
            paused=self.paused,
            stop_detail=self.stop_detail if self.stopped else "",
            undo=self.undo_words,
        )

    def release(self) -> None:
        """Let the latched emergency stop go."""
        self.stopped = False
        self.stop_detail = ""

    def _to_history(self, record: OrderRecord, status: OrderStatus, message: str) -> None:
        ended = msgspec.structs.replace(
            record, status=status, message=message, ended_at=self._clock()
        )
        self.history.appendleft(ended)
        self._positions.pop(record.id, None)
        self._changed[record.id] = ended
        if not self.queue and self.paused != PAUSED_ASKED:
            self.paused = ""  # nothing left to resume
