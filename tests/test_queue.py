"""The supervisor's per-robot state machine, without any I/O."""

from __future__ import annotations

import itertools

import pytest

from voicectl.services.supervisor import queue as queue_module
from voicectl.services.supervisor.queue import RequestConflict, RobotQueue
from voicectl.shared.messages import Order, OrderStatus, Progress


def order(name: str) -> Order:
    return Order(order=name, label="mul", description=name)


@pytest.fixture
def queue() -> RobotQueue:
    ticks = itertools.count(100)
    q = RobotQueue("r1", clock=lambda: float(next(ticks)))
    q.executor_online = True
    return q


def test_orders_run_one_at_a_time_in_order(queue: RobotQueue) -> None:
    ids = queue.submit("req-1", [order("a"), order("b")], "a then b")
    first = queue.start_next()
    assert first is not None
    assert first.id == ids[0]
    assert first.status == OrderStatus.RUNNING
    assert queue.start_next() is None  # one at a time
    assert queue.finish(ids[0], OrderStatus.SUCCEEDED, "ok")
    second = queue.start_next()
    assert second is not None
    assert second.id == ids[1]
    assert [r.status for r in queue.history] == [OrderStatus.SUCCEEDED]
    assert queue.history[0].transcript == "a then b"


def test_resubmitting_a_request_id_is_a_no_op(queue: RobotQueue) -> None:
    first = queue.submit("req-1", [order("a")], "")
    again = queue.submit("req-1", [order("a")], "")
    assert first == again
    assert len(queue.queue) == 1


def test_request_ids_are_remembered_for_retries_not_forever(
    queue: RobotQueue, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(queue_module, "RECENT_REQUESTS", 3)
    first = queue.submit("req-0", [order("a")], "")
    with pytest.raises(RequestConflict):
        queue.submit("req-0", [order("b")], "")
    for n in range(1, 4):
        queue.submit(f"req-{n}", [order("a")], "")
    assert queue.submit("req-3", [order("a")], "") != first  # recent: a retry
    assert len(queue.queue) == 4
    # the oldest is forgotten: the same id is taken as new
    assert queue.submit("req-0", [order("b")], "") != first
    assert len(queue.queue) == 5


def test_nothing_is_dispatched_while_the_executor_is_offline(queue: RobotQueue) -> None:
    queue.executor_online = False
    queue.submit("req", [order("a")], "")
    assert queue.start_next() is None
    assert len(queue.queue) == 1
    queue.executor_online = True
    assert queue.start_next() is not None


def test_a_failure_cancels_the_rest_of_its_utterance_only(queue: RobotQueue) -> None:
    a, b = queue.submit("req-1", [order("a"), order("b")], "")
    (c,) = queue.submit("req-2", [order("c")], "")
    queue.start_next()
    queue.finish(a, OrderStatus.FAILED, "blocked")
    assert [r.id for r in queue.queue] == [c]
    assert [(r.id, r.status) for r in queue.history] == [
        (b, OrderStatus.CANCELLED),
        (a, OrderStatus.FAILED),
    ]
    # Why, in words a person knows the order by: what it does, never its id.
    assert queue.history[0].message == "cancelled because “a” before it failed"


@pytest.mark.parametrize(
    ("status", "said"),
    [
        (OrderStatus.REJECTED, "was refused"),
        (OrderStatus.INTERRUPTED, "was interrupted"),
    ],
)
def test_the_reason_of_a_cancelled_sibling_names_the_order_before_it(
    queue: RobotQueue, status: OrderStatus, said: str
) -> None:
    a, _b = queue.submit("req-1", [order("move forward 10 m"), order("b")], "")
    queue.start_next()
    queue.finish(a, status, "no")
    assert queue.history[0].message == f"cancelled because “move forward 10 m” before it {said}"
    assert a not in queue.history[0].message


def test_continue_on_failure_keeps_the_rest() -> None:
    q = RobotQueue("r", continue_on_failure=True)
    q.executor_online = True
    a, b = q.submit("req", [order("a"), order("b")], "")
    q.start_next()
    q.finish(a, OrderStatus.FAILED, "x")
    assert [r.id for r in q.queue] == [b]


def test_stale_events_change_nothing(queue: RobotQueue) -> None:
    (a,) = queue.submit("req", [order("a")], "")
    assert not queue.finish("nope", OrderStatus.SUCCEEDED)
    assert not queue.progress(a, Progress(text="x"))  # queued, not running
    queue.start_next()
    assert queue.progress(a, Progress(text="half", percent=50))
    assert queue.current is not None
    assert queue.current.progress == Progress(text="half", percent=50)
    assert queue.finish(a, OrderStatus.SUCCEEDED)
    assert not queue.finish(a, OrderStatus.FAILED)  # finished twice: ignored
    assert len(queue.history) == 1


def test_cancel_queued_and_clear(queue: RobotQueue) -> None:
    a, b, c = queue.submit("req", [order("a"), order("b"), order("c")], "")
    assert queue.remove_queued(b, "by user")
    assert not queue.remove_queued(b, "by user")
    assert queue.clear_queue("stop") == 2
    assert {r.id for r in queue.history} == {a, b, c}
    assert all(r.status == OrderStatus.CANCELLED for r in queue.history)


def test_a_stop_ends_the_running_order_at_once_and_waits_for_its_executors_word(
    queue: RobotQueue,
) -> None:
    """The state never says stopped beside a running order; no other order starts until
    the executor has said how the stopped one ended, even once the stop is released."""
    running, later = queue.submit("req", [order("a"), order("b")], "")
    queue.start_next()
    queue.stopped = True
    queue.clear_queue("emergency stop")
    ended = queue.stop_current("emergency stop")
    assert ended is not None
    assert ended.id == running
    state = queue.snapshot()
    assert (state.stopped, state.current) == (True, None)
    assert [(r.id, r.status, r.message) for r in state.history[:1]] == [
        (running, OrderStatus.CANCELLED, "emergency stop")
    ]
    queue.release()
    (after,) = queue.submit("req-2", [order("c")], "")
    assert queue.start_next() is None  # the executor may still be ending it
    assert queue.finish(running, OrderStatus.CANCELLED, "emergency stop")
    assert queue.history[0].message == "emergency stop"
    started = queue.start_next()
    assert started is not None
    assert started.id == after
    assert later in {r.id for r in queue.history}


def test_the_executors_word_on_a_stopped_order_is_what_it_keeps(queue: RobotQueue) -> None:
    """It finished just before the stop reached it: the record says so."""
    (running,) = queue.submit("req", [order("a")], "")
    queue.start_next()
    queue.stopped = True
    queue.stop_current("emergency stop")
    queue.take_changes()
    assert queue.finish(running, OrderStatus.SUCCEEDED, "6")
    assert (queue.history[0].status, queue.history[0].message) == (OrderStatus.SUCCEEDED, "6")
    records, _ = queue.take_changes()
    assert [(r.id, r.status) for r, _ in records] == [(running, OrderStatus.SUCCEEDED)]
    assert len(queue.history) == 1


def test_word_that_never_comes_holds_nothing_back_once_given_up(queue: RobotQueue) -> None:
    (running,) = queue.submit("req", [order("a")], "")
    queue.start_next()
    queue.stopped = True
    queue.stop_current("emergency stop")
    queue.release()
    (after,) = queue.submit("req-2", [order("b")], "")
    assert queue.start_next() is None
    assert not queue.stop_waiting("another")
    assert queue.stop_waiting(running)
    started = queue.start_next()
    assert started is not None
    assert started.id == after
    assert not queue.finish(running, OrderStatus.CANCELLED)  # late: nothing to change


def test_snapshot_lists_history_most_recent_first(queue: RobotQueue) -> None:
    ids = queue.submit("req", [order(str(i)) for i in range(3)], "")
    for order_id in ids:
        queue.start_next()
        queue.finish(order_id, OrderStatus.SUCCEEDED)
    state = queue.snapshot()
    assert [r.id for r in state.history] == list(reversed(ids))
    assert state.executor_online
    assert state.current is None


def test_a_submit_that_could_not_be_stored_is_withdrawn(queue: RobotQueue) -> None:
    (kept,) = queue.submit("req-1", [order("a")], "")
    queue.submit("req-2", [order("b"), order("c")], "")
    queue.withdraw("req-2")
    assert [r.id for r in queue.queue] == [kept]
    again = queue.submit("req-2", [order("b")], "")  # the retry is a new submit
    assert len(again) == 1
    assert [r.id for r in queue.queue] == [kept, *again]


def test_an_order_whose_start_was_not_recorded_goes_back_to_the_head(queue: RobotQueue) -> None:
    a, b = queue.submit("req-1", [order("a"), order("b")], "")
    started = queue.start_next()
    assert started is not None
    assert started.id == a
    assert not queue.unstart(b)  # not the current one: nothing changes
    assert queue.unstart(a)
    assert queue.current is None
    assert [(r.id, r.status, r.started_at) for r in queue.queue] == [
        (a, OrderStatus.QUEUED, None),
        (b, OrderStatus.QUEUED, None),
    ]
    again = queue.start_next()
    assert again is not None
    assert again.id == a


def test_withdrawing_a_submit_also_drops_its_order_whose_start_is_being_written(
    queue: RobotQueue,
) -> None:
    (kept,) = queue.submit("req-0", [order("k")], "")
    queue.start_next()
    queue.finish(kept, OrderStatus.SUCCEEDED)
    a, _ = queue.submit("req-1", [order("a"), order("b")], "")
    started = queue.start_next()
    assert started is not None
    assert started.id == a
    queue.withdraw("req-1")
    assert queue.current is None
    assert not queue.queue
    assert not queue.unstart(a)


def test_an_order_ended_by_a_loss_cancels_the_rest_of_its_utterance_whatever_its_status(
    queue: RobotQueue,
) -> None:
    """After the supervisor's loss the executor ends an order that moved the robot as
    cancelled; after the executor's loss the supervisor ends it as failed. Either way the
    rest of the utterance is cancelled: one rule, the safe one."""
    a, b = queue.submit("req-1", [order("a"), order("b")], "")
    c, d = queue.submit("req-2", [order("c"), order("d")], "")
    queue.start_next()
    queue.finish(a, OrderStatus.CANCELLED, "supervisor lost", lost=True)
    assert [r.id for r in queue.queue] == [c, d]
    assert queue.history[0].id == b
    assert queue.history[0].status == OrderStatus.CANCELLED
    queue.start_next()
    queue.finish(c, OrderStatus.SUCCEEDED, "done while away", lost=True)  # it did happen
    assert [r.id for r in queue.queue] == [d]
