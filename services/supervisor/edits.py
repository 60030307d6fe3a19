# msgspec subclasses inherit frozen=True; mypy's dataclass_transform does not know that.
# mypy: disable-error-code="misc"
"""Edits of one robot's queue as plain functions of it: no I/O, so every rule is testable
alone (tests/test_edits.py).

Each edit returns what it did in one sentence for a person (shared/answers.py's words),
whether it changed anything, and how to undo it. An edit never guesses: an order named
that is not in the queue, or is there twice, is answered and nothing changes. Stopping the
running order needs its executor: the edit says which order to stop, and the supervisor
asks (robot.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import msgspec

from voicectl.shared.answers import left_words, spoken
from voicectl.shared.edits import (
    LAST,
    UNDONE,
    AfterEdit,
    CancelEdit,
    ClearEdit,
    FirstEdit,
    PauseEdit,
    ResumeEdit,
    SkipEdit,
    cancelled_by,
    replaced_by,
)
from voicectl.shared.messages import Asked, Order, OrderRecord, OrderStatus

from .queue import PAUSED_ASKED, QueueFull, RobotQueue

UNDO_DEPTH = 10
"""Edits that "undo" can take back, one after the other."""


class Reopened(msgspec.Struct, frozen=True):
    """An order an edit ended, as it was before, and where it stood."""

    record: OrderRecord
    position: float
    ran: bool = False
    """It was running: it is queued first again, to run from its start."""


class Moved(msgspec.Struct, frozen=True):
    order_id: str
    position: float
    """Where it stood before the edit moved it."""


class Undo(msgspec.Struct, frozen=True):
    """How to take one edit back: kept on disk with the robot's queue."""

    edit_id: str
    description: str
    """The edit as said ("cancel kitchen")."""
    reopen: list[Reopened] = msgspec.field(default_factory=list)
    remove: list[str] = msgspec.field(default_factory=list)
    """The orders it added."""
    moves: list[Moved] = msgspec.field(default_factory=list)
    paused: str | None = None
    """The queue's pause before the edit, when it changed it."""


@dataclass
class Applied:
    """What an edit did, or why nothing."""

    answer: str
    changed: bool = False
    undo: Undo | None = None
    stop: list[str] = field(default_factory=list)
    """Running orders to stop (their executor must be asked); they are ended by then."""
    added: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Request:
    """The edit request as the queue's functions need it."""

    edit_id: str
    request_id: str
    edit: Order
    orders: list[Order]
    transcript: str
    asked: Asked | None = None


def name_of(which: str) -> str:
    """A name's key as said in an answer: 'take_photo' is 'take photo'."""
    return which.replace("_", " ")


def named(record: OrderRecord, which: str) -> bool:
    """Whether `record` is an order of the name `which` (its case's or its order's)."""
    order = record.order
    return order.case == which if order.case is not None else order.order == which


def find(queue: RobotQueue, which: str, running: bool = True) -> OrderRecord | str:
    """The open order `which` names (`last`: the one added last), or what to answer when
    there is none or more than one."""
    records = queue.open_records() if running else list(queue.queue)
    if which == LAST:
        if not records:
            return "there is nothing in the queue"
        return max(records, key=lambda r: (r.submitted_at, queue.position_of(r.id)))
    found = [record for record in records if named(record, which)]
    if not found:
        return f"there is no {name_of(which)} in the queue"
    if len(found) > 1:
        return f"{len(found)} orders in the queue are {name_of(which)}: say which in the panel"
    return found[0]


def cancel(queue: RobotQueue, edit: CancelEdit, request: Request) -> Applied:
    target = find(queue, edit.which)
    if isinstance(target, str):
        return Applied(target)
    undo = Undo(request.edit_id, request.edit.description)
    what = spoken(target.order.description)
    if queue.current is not None and target.id == queue.current.id:
        undo.reopen.append(Reopened(target, queue.head_position(), ran=True))
        queue.stopping[target.id] = cancelled_by(request.edit)
        return Applied(
            f"cancelled {what}; {left_words(len(queue.queue))}", True, undo, stop=[target.id]
        )
    position = queue.position_of(target.id)
    queue.remove_queued(target.id, cancelled_by(request.edit))
    undo.reopen.append(Reopened(target, position))
    return Applied(f"cancelled {what}; {_left(queue)}", True, undo)


def _left(queue: RobotQueue) -> str:
    return left_words(len(queue.queue) + (queue.current is not None))


def clear(queue: RobotQueue, _edit: ClearEdit, request: Request) -> Applied:
    if not queue.queue:
        return Applied("the queue is empty already")
    undo = Undo(request.edit_id, request.edit.description)
    for record in list(queue.queue):
        undo.reopen.append(Reopened(record, queue.position_of(record.id)))
    count = queue.clear_queue(cancelled_by(request.edit))
    cleared = f"cleared {count} order{'s' if count != 1 else ''}"
    current = queue.current
    still = f"; still {spoken(current.order.description)}" if current is not None else ""
    return Applied(cleared + still, True, undo)


def first(queue: RobotQueue, edit: FirstEdit, request: Request) -> Applied:
    target = find(queue, edit.which, running=False)
    if isinstance(target, str):
        current = queue.current
        if current is not None and (edit.which == LAST or named(current, edit.which)):
            return Applied(f"{spoken(current.order.description)} is running already")
        return Applied(target)
    what = spoken(target.order.description)
    if queue.queue[0].id == target.id:
        return Applied(f"{what} is next already")
    undo = Undo(request.edit_id, request.edit.description)
    undo.moves.append(Moved(target.id, queue.position_of(target.id)))
    queue.reorder(target.id, 0)
    queue.touched = target.id
    return Applied(f"{what} is next; {_left(queue)}", True, undo)


def after(queue: RobotQueue, _edit: AfterEdit, request: Request) -> Applied:
    if not request.orders:
        return Applied("after what? say it with an order: after that, go to base")
    if queue.stopped:
        return Applied("the emergency stop is on: release it first")
    that = next((r for r in queue.queue if r.id == queue.touched), None)
    index = list(queue.queue).index(that) + 1 if that is not None else 0
    try:
        ids = queue.submit(
            brought(request), request.orders, request.transcript, request.asked, at=index
        )
    except QueueFull as exc:
        return Applied(str(exc))
    what = ", then ".join(spoken(order.description) for order in request.orders)
    undo = Undo(request.edit_id, request.edit.description, remove=ids)
    if that is not None:
        answer = f"{what} {'come' if len(ids) > 1 else 'comes'} after "
        answer += spoken(that.order.description)
    else:
        answer = f"{what} {'are' if len(ids) > 1 else 'is'} next"
    return Applied(answer, True, undo, added=ids)


def skip(queue: RobotQueue, _edit: SkipEdit, request: Request) -> Applied:
    current = queue.current
    if current is None:
        return Applied("nothing is running")
    undo = Undo(request.edit_id, request.edit.description)
    undo.reopen.append(Reopened(current, queue.head_position(), ran=True))
    following = (
        f"next: {spoken(queue.queue[0].order.description)}" if queue.queue else "nothing left"
    )
    answer = f"skipped {spoken(current.order.description)}; {following}"
    queue.stopping[current.id] = cancelled_by(request.edit)
    return Applied(answer, True, undo, stop=[current.id])


def pause(queue: RobotQueue, _edit: PauseEdit, request: Request) -> Applied:
    if queue.paused == PAUSED_ASKED:
        return Applied("I am paused already: say go on")
    undo = Undo(request.edit_id, request.edit.description, paused=queue.paused)
    queue.paused = PAUSED_ASKED
    waiting = f"{len(queue.queue)} waiting"
    current = queue.current
    if current is not None:
        answer = f"pausing after {spoken(current.order.description)}; {waiting}"
        return Applied(answer, True, undo)
    return Applied(f"paused; {waiting}", True, undo)


def resume(queue: RobotQueue, _edit: ResumeEdit, request: Request) -> Applied:
    if not queue.paused:
        return Applied("I was not paused")
    undo = Undo(request.edit_id, request.edit.description, paused=queue.paused)
    queue.paused = ""
    return Applied(f"going on; {_left(queue)}", True, undo)


def replace(queue: RobotQueue, target: OrderRecord, new: Order, request: Request) -> Applied:
    """`target` becomes `new` where it stands (first, when it was running: it is stopped)."""
    undo = Undo(request.edit_id, request.edit.description)
    running = queue.current is not None and queue.current.id == target.id
    if running:
        undo.reopen.append(Reopened(target, queue.head_position(), ran=True))
        queue.stopping[target.id] = replaced_by(new)
        index = 0
    else:
        index = list(queue.queue).index(target)
        undo.reopen.append(Reopened(target, queue.position_of(target.id)))
        queue.remove_queued(target.id, replaced_by(new))
    ids = queue.submit(brought(request), [new], request.transcript, request.asked, at=index)
    undo.remove.extend(ids)
    answer = f"now {spoken(new.description)}, not {spoken(target.order.description)}"
    return Applied(answer, True, undo, stop=[target.id] if running else [], added=ids)


def brought(request: Request) -> str:
    """The request id of the orders an edit queues: the edit's own is its record's."""
    return f"{request.request_id}:orders"


def revert(queue: RobotQueue, undo: Undo) -> Applied:
    """Take `undo`'s edit back: the orders it added out, those it ended queued again at
    their positions, those it moved back, its pause turned back."""
    stop = []
    for order_id in undo.remove:
        if queue.remove_queued(order_id, UNDONE):
            continue
        if queue.current is not None and queue.current.id == order_id:
            queue.stopping[order_id] = UNDONE
            stop.append(order_id)
    for reopened in undo.reopen:
        record = reopened.record
        if any(r.id == record.id for r in queue.open_records()):
            continue  # open again already
        position = queue.head_position() if reopened.ran else reopened.position
        queue.reopen(record, position)
    for moved in undo.moves:
        queue.move_to(moved.order_id, moved.position)
    if undo.paused is not None:
        queue.paused = undo.paused
    return Applied(f"undone: {undo.description}", True, stop=stop)


def edit_record(request: Request, applied: Applied, now: float) -> OrderRecord:
    """The edit as the history keeps it: what was said, by whom, and what came of it."""
    return OrderRecord(
        id=request.edit_id,
        order=request.edit,
        status=OrderStatus.SUCCEEDED if applied.changed else OrderStatus.REJECTED,
        transcript=request.transcript,
        request_id=request.request_id,
        message=applied.answer,
        submitted_at=now,
        started_at=now,
        ended_at=now,
        asked=request.asked,
    )
