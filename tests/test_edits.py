"""Edits of the queue as plain functions of it (services/supervisor/edits.py), and how a
text's orders become requests (shared/edits.py): each edit does what it says and answers
in one sentence; an order named that is not there changes nothing and says so; undo
restores the queue exactly."""

from __future__ import annotations

import itertools

import msgspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from voicectl.services.supervisor import edits
from voicectl.services.supervisor.queue import PAUSED_ASKED, RobotQueue
from voicectl.shared.edits import (
    AfterEdit,
    CancelEdit,
    ClearEdit,
    FirstEdit,
    PauseEdit,
    ResumeEdit,
    SkipEdit,
    requests,
)
from voicectl.shared.messages import Asked, Edit, Order, OrderRecord, OrderStatus, Submit, Via


def place(case: str) -> Order:
    return Order(order="goal", case=case, label="mbgoal", description=f"reach {case}")


def edit(name: str, **params: str) -> Order:
    return Order(order=name, label="queue", description=name, params={"edit": name, **params})


@pytest.fixture
def queue() -> RobotQueue:
    ticks = itertools.count(100)
    made = RobotQueue("r1", clock=lambda: float(next(ticks)))
    made.executor_online = True
    return made


def request(said: Order, orders: list[Order] | None = None) -> edits.Request:
    return edits.Request(
        edit_id="e1", request_id="r-e1", edit=said, orders=orders or [], transcript=said.description
    )


def layout(queue: RobotQueue) -> list[tuple[str, str, str, float]]:
    """Everything undo must restore: each open order's id, status, words and position."""
    return [
        (r.id, r.status.value, r.order.description, queue.position_of(r.id))
        for r in queue.open_records()
    ]


def three(queue: RobotQueue) -> list[str]:
    return queue.submit("s1", [place("kitchen"), place("bathroom"), place("base")], "")


def test_cancel_names_a_queued_order_or_changes_nothing(queue: RobotQueue) -> None:
    three(queue)
    before = layout(queue)
    missing = edits.cancel(queue, CancelEdit(which="dumpster"), request(edit("cancel")))
    assert (missing.answer, missing.changed) == ("there is no dumpster in the queue", False)
    assert layout(queue) == before
    done = edits.cancel(queue, CancelEdit(which="bathroom"), request(edit("cancel")))
    assert done.answer == "cancelled reach bathroom; 2 left"
    assert [r.order.case for r in queue.queue] == ["kitchen", "base"]
    assert queue.history[0].status is OrderStatus.CANCELLED
    assert done.undo is not None
    edits.revert(queue, done.undo)
    assert layout(queue) == before


def test_a_name_in_the_queue_twice_is_asked_never_guessed(queue: RobotQueue) -> None:
    queue.submit("s1", [place("kitchen"), place("base"), place("kitchen")], "")
    before = layout(queue)
    said = edits.cancel(queue, CancelEdit(which="kitchen"), request(edit("cancel")))
    assert said.answer == "2 orders in the queue are kitchen: say which in the panel"
    assert not said.changed
    assert layout(queue) == before


def test_the_last_one_is_the_one_added_last(queue: RobotQueue) -> None:
    first = three(queue)
    later = queue.submit("s2", [place("dumpster")], "")
    queue.reorder(later[0], 0)  # added last, but next in line
    said = edits.cancel(queue, CancelEdit(which="last"), request(edit("cancel")))
    assert said.answer == "cancelled reach dumpster; 3 left"
    assert [r.id for r in queue.queue] == first


def test_cancelling_the_running_order_stops_it_and_undo_queues_it_first(queue: RobotQueue) -> None:
    ids = three(queue)
    running = queue.start_next()
    assert running is not None
    said = edits.cancel(queue, CancelEdit(which="kitchen"), request(edit("cancel")))
    assert said.stop == [ids[0]]  # the supervisor asks its executor
    assert said.answer == "cancelled reach kitchen; 2 left"
    queue.finish(ids[0], OrderStatus.CANCELLED, "cancelled")
    assert said.undo is not None
    edits.revert(queue, said.undo)
    assert [r.id for r in queue.queue] == ids  # it runs again first, from its start
    assert queue.queue[0].status is OrderStatus.QUEUED


def test_clear_then_undo_restores_the_queue_exactly(queue: RobotQueue) -> None:
    three(queue)
    queue.reorder(queue.queue[2].id, 0)
    before = layout(queue)
    said = edits.clear(queue, ClearEdit(), request(edit("clear")))
    assert said.answer == "cleared 3 orders"
    assert not queue.queue
    assert said.undo is not None
    edits.revert(queue, said.undo)
    assert layout(queue) == before
    empty = RobotQueue("r2")
    assert edits.clear(empty, ClearEdit(), request(edit("clear"))).changed is False


def test_first_moves_a_queued_order_to_the_head_and_undo_moves_it_back(queue: RobotQueue) -> None:
    ids = three(queue)
    before = layout(queue)
    said = edits.first(queue, FirstEdit(which="base"), request(edit("first")))
    assert said.answer == "reach base is next; 3 left"
    assert [r.id for r in queue.queue] == [ids[2], ids[0], ids[1]]
    assert said.undo is not None
    edits.revert(queue, said.undo)
    assert layout(queue) == before
    queue.start_next()
    running = edits.first(queue, FirstEdit(which="kitchen"), request(edit("first")))
    assert (running.answer, running.changed) == ("reach kitchen is running already", False)


def test_after_that_goes_after_the_order_last_added_or_moved(queue: RobotQueue) -> None:
    ids = three(queue)
    edits.first(queue, FirstEdit(which="bathroom"), request(edit("first")))
    said = edits.after(queue, AfterEdit(), request(edit("after"), [place("dumpster")]))
    assert said.answer == "reach dumpster comes after reach bathroom"
    assert [r.order.case for r in queue.queue] == ["bathroom", "dumpster", "kitchen", "base"]
    assert said.undo is not None
    edits.revert(queue, said.undo)
    assert [r.id for r in queue.queue] == [ids[1], ids[0], ids[2]]
    alone = edits.after(queue, AfterEdit(), request(edit("after")))
    assert not alone.changed


def test_skip_stops_the_running_order(queue: RobotQueue) -> None:
    assert edits.skip(queue, SkipEdit(), request(edit("skip"))).answer == "nothing is running"
    ids = three(queue)
    queue.start_next()
    said = edits.skip(queue, SkipEdit(), request(edit("skip")))
    assert said.stop == [ids[0]]
    assert said.answer == "skipped reach kitchen; next: reach bathroom"


def test_pause_holds_the_queue_until_go_on_even_once_it_ran_empty(queue: RobotQueue) -> None:
    [only] = queue.submit("s1", [place("kitchen")], "")
    queue.start_next()
    said = edits.pause(queue, PauseEdit(), request(edit("pause")))
    assert said.answer == "pausing after reach kitchen; 0 waiting"
    queue.finish(only, OrderStatus.SUCCEEDED)
    assert queue.paused == PAUSED_ASKED  # a restart's pause would end here
    queue.submit("s2", [place("base")], "")
    assert queue.start_next() is None
    go = edits.resume(queue, ResumeEdit(), request(edit("resume")))
    assert go.answer == "going on; 1 left"
    assert queue.start_next() is not None
    assert edits.resume(queue, ResumeEdit(), request(edit("resume"))).changed is False


def test_replace_puts_the_new_order_where_the_old_one_stood(queue: RobotQueue) -> None:
    ids = three(queue)
    before = layout(queue)
    target = queue.queue[1]
    said = edits.replace(queue, target, place("dumpster"), request(edit("replace")))
    assert said.answer == "now reach dumpster, not reach bathroom"
    assert [r.order.case for r in queue.queue] == ["kitchen", "dumpster", "base"]
    assert queue.history[0].id == ids[1]
    assert said.undo is not None
    edits.revert(queue, said.undo)
    assert layout(queue) == before


def test_the_orders_an_edit_queues_leave_the_edits_request_id_to_its_record(
    queue: RobotQueue,
) -> None:
    """The supervisor remembers an edit's request id as the edit's record, and a retry,
    also after a restart, answers with that; the orders a correction or "after that"
    queues are remembered under an id of their own (the store keeps an id's first word)."""
    three(queue)
    queue.take_changes()
    edits.after(queue, AfterEdit(), request(edit("after"), [place("dumpster")]))
    correction = edits.Request("e2", "r-e2", edit("replace"), [], "no, the base")
    edits.replace(queue, queue.queue[0], place("base"), correction)
    _, remembered = queue.take_changes()
    assert len(remembered) == 2
    assert not {"r-e1", "r-e2"} & {request_id for request_id, _ in remembered}


def test_an_edit_is_recorded_with_who_asked_and_what_came_of_it() -> None:
    asked = Asked(via=Via.VOICE, spoken=True, by="listen on robot")
    made = edits.Request("e1", "r1", edit("cancel"), [], "cancel the kitchen", asked)
    record = edits.edit_record(made, edits.Applied("there is no kitchen in the queue"), 5.0)
    assert record.status is OrderStatus.REJECTED
    assert record.message == "there is no kitchen in the queue"
    assert record.asked == asked
    assert msgspec.json.decode(msgspec.json.encode(record), type=OrderRecord) == record


@given(
    st.lists(st.sampled_from(["kitchen", "bathroom", "base", "dumpster"]), max_size=6),
    st.lists(
        st.one_of(
            st.builds(CancelEdit, which=st.sampled_from(["last", "kitchen", "base"])),
            st.just(ClearEdit()),
            st.builds(FirstEdit, which=st.sampled_from(["last", "bathroom", "dumpster"])),
            st.just(PauseEdit()),
            st.just(ResumeEdit()),
        ),
        min_size=1,
        max_size=5,
    ),
)
def test_undoing_every_edit_in_turn_restores_the_queue_exactly(
    names: list[str], said: list[object]
) -> None:
    """Any queue, any edits of the waiting orders, then as many undos: as it was."""
    queue = RobotQueue("r1")
    queue.submit("s1", [place(name) for name in names], "")
    before = (layout(queue), queue.paused)
    undos = []
    for number, one in enumerate(said):
        made = request(edit("x"))
        made = edits.Request(f"e{number}", f"r{number}", made.edit, [], "")
        apply = {
            CancelEdit: edits.cancel,
            ClearEdit: edits.clear,
            FirstEdit: edits.first,
            PauseEdit: edits.pause,
            ResumeEdit: edits.resume,
        }[type(one)]
        applied = apply(queue, one, made)  # type: ignore[operator]
        if applied.undo is not None:
            undos.append(applied.undo)
    for undo in reversed(undos):
        edits.revert(queue, undo)
    assert (layout(queue), queue.paused) == before


def test_a_texts_orders_become_submits_and_edits_in_turn() -> None:
    asked = Asked(via=Via.CLI)
    made = requests(
        [place("kitchen"), edit("cancel", which="last"), edit("after"), place("base"), place("x")],
        "said",
        asked,
        "rq",
    )
    assert [type(m) for m in made] == [Submit, Edit, Edit]
    assert [m.request_id for m in made] == ["rq-0", "rq-1", "rq-2"]
    after = made[2]
    assert isinstance(after, Edit)
    assert [o.case for o in after.orders] == ["base", "x"]
    assert requests([place("kitchen")], "", None, "one") == [
        Submit(request_id="one", orders=[place("kitchen")])
    ]
