"""What voicectl says aloud (shared/answers.py): short, in the panel's words, people's
words where the panel shows an engineer's. The cases are also the table that the panel's
answers.js is held to (tests/test_panel_voice.py)."""

from __future__ import annotations

import pytest

from voicectl.shared.answers import outcome_words, proposal_words, short, spoken, stopped_words
from voicectl.shared.messages import (
    Doubt,
    Order,
    OrderRecord,
    OrderStatus,
    ParseProblem,
    Proposal,
    Stopped,
)


def order(description: str) -> Order:
    return Order(order="o", label="mbgoal", description=description)


def record(description: str, status: OrderStatus, message: str = "") -> OrderRecord:
    return OrderRecord(id="1", order=order(description), status=status, message=message)


LEFT_KITCHEN = [order("turn left"), order("reach kitchen")]

PROPOSALS = [
    (Proposal(transcript="turn left then reach kitchen", orders=LEFT_KITCHEN),
     "turn left, then reach kitchen"),
    (Proposal(transcript="go forward two meters", orders=[order("move forward 2 m")]),
     "move forward 2 metres"),
    (Proposal(transcript="go back one meter", orders=[order("move back 1 m")]),
     "move back 1 metre"),
    (Proposal(transcript="what is the weather", rejected=True,
              errors=[ParseProblem(text="what is the weather",
                                   reason="I heard 'what is the weather': not a command")]),
     "I did not catch that"),
    (Proposal(transcript="go forward ten meters", orders=[order("move forward 10 m")],
              doubts=[Doubt(position=2, words="ten", alternatives=["two"])]),
     "ten or two meters?"),
    (Proposal(transcript="wait ten", doubts=[Doubt(position=1, words="ten",
                                                  alternatives=["two", "tan"])]),
     "ten, two or tan?"),
    (Proposal(transcript="turn left then dance", orders=[order("turn left")],
              errors=[ParseProblem(text="dance", reason="no order matches")]),
     "turn left; I did not catch 'dance'"),
    (Proposal(transcript="dance", errors=[ParseProblem(text="dance", reason="no order matches")]),
     "I did not catch that"),
    (Proposal(transcript=""), "I did not catch that"),
]  # fmt: skip

OUTCOMES = [
    (record("reach kitchen", OrderStatus.SUCCEEDED), "reached kitchen"),
    (record("turn right 90 degrees", OrderStatus.SUCCEEDED), "turned right 90 degrees"),
    (record("wait 1 s", OrderStatus.SUCCEEDED), "waited 1 second"),
    (record("wait 10 s", OrderStatus.SUCCEEDED), "waited 10 seconds"),
    (record("move forward 0.1 m", OrderStatus.SUCCEEDED), "moved forward 0.1 metres"),
    (record("take picture", OrderStatus.SUCCEEDED), "done: take picture"),
    (record("reach kitchen", OrderStatus.FAILED, "navigation ended ABORTED: no path; retried"),
     "reach kitchen failed: navigation ended ABORTED: no path"),
    (record("reach kitchen", OrderStatus.FAILED, "navigation unavailable (no action server " +
            "answered within 5 s on 'navigate_to_pose')"),
     "reach kitchen failed: navigation unavailable"),
    (record("turn left", OrderStatus.FAILED, "no progress for 10 s, 0.52 short of the goal " +
            "that the controller was given by the planner at the start"),
     "turn left failed: no progress for 10 s, 0.52 short of the goal that the"),
    (record("turn left", OrderStatus.FAILED), "turn left failed"),
    (record("wait 2 s", OrderStatus.CANCELLED), "wait 2 seconds cancelled"),
    (record("dance", OrderStatus.REJECTED, "no executor serves 'dance'."),
     "dance refused: no executor serves 'dance'"),
    (record("turn left", OrderStatus.INTERRUPTED), "turn left interrupted"),
    (record("turn left", OrderStatus.QUEUED), None),
    (record("turn left", OrderStatus.RUNNING), None),
]  # fmt: skip

STOPS = [
    (Stopped(confirmed=True, detail="navigation and executor stopped"), "stopped"),
    (Stopped(confirmed=False, detail="navigation did not answer"), "stop sent, not confirmed"),
]


@pytest.mark.parametrize(("proposal", "said"), PROPOSALS)
def test_proposals(proposal: Proposal, said: str) -> None:
    assert proposal_words(proposal) == said


@pytest.mark.parametrize(("finished", "said"), OUTCOMES)
def test_outcomes(finished: OrderRecord, said: str | None) -> None:
    assert outcome_words(finished) == said


@pytest.mark.parametrize(("stopped", "said"), STOPS)
def test_stops(stopped: Stopped, said: str) -> None:
    assert stopped_words(stopped) == said


def test_every_sentence_is_short_enough_to_speak() -> None:
    said = [proposal_words(p) for p, _ in PROPOSALS] + [outcome_words(r) for r, _ in OUTCOMES]
    assert all(len(s or "") <= 120 for s in said)


@pytest.mark.parametrize(
    ("written", "said"),
    [
        ("move forward 21 m", "move forward 21 metres"),
        ("turn 45°", "turn 45 degrees"),
        ("wait 1.5 s", "wait 1.5 seconds"),
        ("reach sm kitchen", "reach sm kitchen"),  # no number: not a unit
    ],
)
def test_units_are_said_in_full(written: str, said: str) -> None:
    assert spoken(written) == said


def test_a_reason_without_spaces_is_cut_at_the_limit() -> None:
    assert short("x" * 100) == "x" * 60
