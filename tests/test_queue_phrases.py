"""The queue's phrases on the converter's side (orders/queue.yaml; refer.py, amend.py, the
parser): names of queued orders spelled out from the other orders, an edit beside an
order, a correction folded into the order said before it, and files that are wrong
refused with their line."""

from __future__ import annotations

import json

import pytest

from voicectl.services.converter.amend import AmendRefused
from voicectl.services.converter.grammar import build_grammar
from voicectl.services.converter.orders import OrderSet, OrdersInvalid
from voicectl.services.converter.parser import Parser
from voicectl.shared.edits import ReplaceEdit, is_edit, read_edit

from .conftest import REPO, voicectl
from .test_docs import block_after

ORDERS = OrderSet.load(REPO / "orders")
PARSER = Parser(ORDERS)


def made(text: str) -> list[tuple[str, dict[str, object]]]:
    result = PARSER.parse(text)
    assert not result.errors, result.errors
    return [(order.description, order.params) for order in result.orders]


@pytest.mark.parametrize(
    ("said", "params"),
    [
        ("cancel the last one", {"edit": "cancel", "which": "last"}),
        ("cancel the kitchen", {"edit": "cancel", "which": "kitchen"}),
        ("drop take a picture", {"edit": "cancel", "which": "take_photo"}),
        ("remove the left", {"edit": "cancel", "which": "left"}),
        ("no cancel that", {"edit": "cancel", "which": "last"}),
        ("clear the queue", {"edit": "clear"}),
        ("do the bathroom first", {"edit": "first", "which": "bathroom"}),
        ("skip this one", {"edit": "skip"}),
        ("pause", {"edit": "pause"}),
        ("go on", {"edit": "resume"}),
        ("undo", {"edit": "undo"}),
        ("no three", {"edit": "replace", "which": "last", "value": 3.0}),
        ("no, 2.5 meters", {"edit": "replace", "which": "last", "value": 2.5, "unit": "length"}),
        ("no the bathroom", {"edit": "replace", "which": "last", "instead": "bathroom"}),
        (
            "not the kitchen, the bathroom",
            {"edit": "replace", "which": "kitchen", "instead": "bathroom"},
        ),
        ("no not the left but right", {"edit": "replace", "which": "left", "instead": "right"}),
        ("what are you doing", {"edit": "ask", "question": "doing"}),
        ("What's next?", {"edit": "ask", "question": "next"}),
        ("how many more", {"edit": "ask", "question": "left"}),
        ("how far is it", {"edit": "ask", "question": "far"}),
        ("where are you", {"edit": "ask", "question": "where"}),
        ("where are you going", {"edit": "ask", "question": "going"}),
        ("why did it fail", {"edit": "ask", "question": "why"}),
    ],
)
def test_each_phrase_makes_its_edit(said: str, params: dict[str, object]) -> None:
    ((_, got),) = made(said)
    assert got == params
    read_edit(PARSER.parse(said).orders[0])  # what the supervisor decodes


def test_a_correction_names_two_cases_of_one_order_only() -> None:
    """ "not the kitchen, left" is no phrase: left is a turn, the kitchen a place."""
    assert PARSER.parse("not the kitchen the left").errors
    assert PARSER.parse("not the kitchen the bathroom").orders


def test_names_come_from_the_other_orders_and_follow_them() -> None:
    """A place added to the orders can be named at once; the queue's file is unchanged."""
    text = (REPO / "orders" / "demo.yaml").read_text()
    text = text.replace(
        "        kitchen: {",
        "        garage: {voice_alias: garage, x: 9.0, y: 9.0}\n        kitchen: {",
    )
    queue = OrderSet.from_yaml((REPO / "orders" / "queue.yaml").read_text(), "queue.yaml")
    demo = OrderSet.from_yaml(text, "demo.yaml")
    parser = Parser(OrderSet.merge([demo, queue]))
    [cancel] = parser.parse("cancel the garage").orders
    assert cancel.params == {"edit": "cancel", "which": "garage"}
    alone = Parser(queue)  # the queue's file alone names nothing
    assert alone.parse("cancel the garage").errors
    assert alone.parse("cancel the last one").orders


def test_an_edit_stands_beside_an_order_without_the_separator() -> None:
    assert made("after that go to base") == [
        ("after that", {"edit": "after"}),
        ("reach base", {}),
    ]
    assert made("turn left then after that take a picture") == [
        ("turn left", {}),
        ("after that", {"edit": "after"}),
        ("take picture", {"wait": 5}),
    ]
    # two orders without the separator stay an error, as before
    assert PARSER.parse("turn left reach kitchen").errors


@pytest.mark.parametrize(
    ("said", "becomes"),
    [
        ("go forward two meters no three", "move forward 3 m"),
        ("Go forward 2 meters. No, 3.", "move forward 3 m"),
        ("move back one meter, no, two meters", "move back 2 m"),
        ("go to the kitchen no the bathroom", "reach bathroom"),
        ("turn left 45 degrees, no, the right", "turn right 45 degrees"),
        ("wait five seconds no ten", "wait 10 s"),
        ("turn left then reach kitchen not kitchen bathroom", "turn left; reach bathroom"),
    ],
)
def test_a_correction_in_the_same_breath_replaces_never_adds(said: str, becomes: str) -> None:
    result = PARSER.parse(said)
    assert not result.errors, result.errors
    assert "; ".join(order.description for order in result.orders) == becomes
    assert not any(is_edit(order) for order in result.orders)


@pytest.mark.parametrize(
    ("said", "why"),
    [
        ("go forward two meters no thirty", "distance 30 is out of range: 0.1 to 10 m"),
        ("go forward two meters no three degrees", "takes a length, not an angle"),
        ("turn left no three", "'turn left' has no number to change"),
        ("reach the kitchen no the left", "'reach kitchen' has no left"),
    ],
)
def test_a_correction_that_does_not_fit_is_an_error_and_sends_nothing(said: str, why: str) -> None:
    result = PARSER.parse(said)
    assert result.orders == []
    (error,) = result.errors
    assert why in error.reason


def test_amend_makes_an_order_sent_before_again_with_its_other_values() -> None:
    [turn] = PARSER.parse("turn left 45 degrees").orders
    right = ReplaceEdit(instead="right")
    assert PARSER.amender.amend(turn, right).description == "turn right 45 degrees"
    [drive] = PARSER.parse("move back 2.5 meters").orders
    again = PARSER.amender.amend(drive, ReplaceEdit(value=1.5))
    assert again == PARSER.parse("move back 1.5 meters").orders[0]
    with pytest.raises(AmendRefused, match="not an order of these orders files"):
        PARSER.amender.amend(drive.__class__(order="x", label="y", description="z"), right)


@pytest.mark.parametrize(
    ("yaml", "problem"),
    [
        (
            "orders:\n  c: {voice_alias: 'cancel', label: queue, edit: cancle}\n",
            "not an edit of the queue",
        ),
        (
            "orders:\n  c: {voice_alias: 'cancel', label: queue, edit: cancel}\n",
            "missing required field `which`",
        ),
        (
            "orders:\n  c:\n    voice_alias: 'stop {o}'\n    label: mbgoal\n"
            "    slots: {o: {type: order}}\n",
            "only orders of label 'queue' have one",
        ),
        (
            "orders:\n  c:\n    voice_alias: 'not {a} {b}'\n    label: queue\n    edit: replace\n"
            "    slots: {a: {type: order, to: which}, b: {type: order, to: instead}}\n",
            "with 'like: <the first>'",
        ),
        (
            "orders:\n  c:\n    voice_alias: 'drop {a}'\n    label: queue\n    edit: cancel\n"
            "    slots: {a: {type: order, to: which, min: 1}}\n",
            "unknown key(s) min for a slot of type order",
        ),
    ],
)
def test_a_wrong_queue_order_is_refused_with_its_line(yaml: str, problem: str) -> None:
    with pytest.raises(OrdersInvalid) as refused:
        OrderSet.from_yaml(yaml, "q.yaml")
    assert problem in str(refused.value)
    assert "(line " in refused.value.errors[0]


def test_edits_get_no_suggestions_and_non_commands_stay_errors() -> None:
    for said in ("kitchen", "what is the weather today", "no", "cancel", "go"):
        result = PARSER.parse(said)
        assert result.orders == [], said
        assert not any(
            candidate.startswith(("no ", "cancel "))
            for e in result.errors
            for candidate in e.candidates
        )


def test_the_grammar_lets_an_edit_stand_next_to_an_order() -> None:
    grammar = build_grammar(ORDERS)
    assert "after that" in grammar.phrases
    assert "cancel kitchen" in grammar.phrases
    assert "do bathroom first" in grammar.phrases
    assert "<edit>" in grammar.jsgf


def test_the_docs_parse_example_prints_what_it_shows() -> None:
    """docs/orders.md's example of an edit beside an order and a correction, run."""
    doc = REPO / "docs" / "orders.md"
    command = block_after(doc, "Try them without a robot", "sh").strip()
    shown = json.loads(block_after(doc, "Try them without a robot", "json"))
    text = json.loads(command.removeprefix(".venv/bin/voicectl parse "))
    done = voicectl("parse", text)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == shown
