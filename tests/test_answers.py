"""What voicectl says aloud (shared/answers.py): short, in the panel's words, people's
words where the panel shows an engineer's. The cases are also the table that the panel's
answers.js is held to (tests/test_panel_voice.py)."""

from __future__ import annotations

import pytest

from voicectl.shared.answers import (
    outcome_words,
    plain_reason,
    proposal_words,
    question_words,
    short,
    spoken,
    stopped_words,
)
from voicectl.shared.messages import (
    Doubt,
    Order,
    OrderRecord,
    OrderStatus,
    ParseProblem,
    Place,
    Progress,
    Proposal,
    RobotPose,
    State,
    Stopped,
    TargetPose,
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


# --- questions about the queue (shared/edits.py's Question), from the state ---------------

KITCHEN = Place(
    name="kitchen",
    phrase="reach kitchen",
    description="reach kitchen",
    pose=TargetPose(frame="map", x=3.0, y=5.0, yaw=1.0),
)
BASE = Place(
    name="base", phrase="reach base", description="reach base", pose=TargetPose(frame="map")
)
PLACES = [BASE, KITCHEN]


def going(to: Place, left: float | None = None) -> OrderRecord:
    """A running order to a place, `left` metres from it as its executor last said."""
    said = Progress(text="", distance_linear=left) if left is not None else None
    order = Order(
        order="goal", case=to.name, label="mbgoal", description=to.description, target_pose=to.pose
    )
    return OrderRecord(id="g", order=order, status=OrderStatus.RUNNING, progress=said)


def waiting(*descriptions: str) -> list[OrderRecord]:
    return [record(d, OrderStatus.QUEUED) for d in descriptions]


RUNNING = State(
    robot="r", current=going(KITCHEN, 3.0), queue=waiting("turn left", "reach base"), queue_length=2
)
TURNING = State(
    robot="r",
    current=OrderRecord(
        id="t",
        order=order("turn left"),
        status=OrderStatus.RUNNING,
        progress=Progress(distance_angular=0.785),
    ),
    queue=[],
    queue_length=0,
)
IDLE = State(robot="r")
PAUSED = State(
    robot="r",
    queue=waiting("reach base"),
    queue_length=1,
    paused="paused when asked: say go on, or press Resume",
)
STOPPED = State(robot="r", stopped=True)
FAILED = State(
    robot="r",
    history=[
        record("cancel kitchen", OrderStatus.SUCCEEDED),
        record("reach kitchen", OrderStatus.FAILED, "navigation ended ABORTED: no path"),
        record("turn left", OrderStatus.FAILED, "executor lost; halting the robot"),
    ],
)
NEAR = RobotPose(x=3.0, y=3.0, yaw=0.0)
AT = RobotPose(x=0.2, y=0.1, yaw=0.0)

QUESTIONS = [
    ("doing", RUNNING, None, "I am going to the kitchen, 3 metres to go, 2 more after it"),
    ("doing", TURNING, None, "I am turning left, 45 degrees to turn"),
    ("doing", IDLE, None, "nothing: the queue is empty"),
    ("doing", PAUSED, None, "nothing: 1 order waits until you say go on"),
    ("doing", STOPPED, None, "nothing: the emergency stop is on"),
    ("going", RUNNING, None, "to the kitchen, 3 metres to go"),
    ("going", TURNING, None, "I am turning left"),
    ("going", IDLE, None, "nowhere: the queue is empty"),
    ("next", RUNNING, None, "next: turn left, then 1 more"),
    ("next", IDLE, None, "nothing next: the queue is empty"),
    ("left", RUNNING, None, "3 left: reach kitchen now, then 2 more"),
    ("left", TURNING, None, "1 left: turn left now"),
    ("left", PAUSED, None, "1 waiting until you say go on"),
    ("left", IDLE, None, "nothing left"),
    ("far", RUNNING, None, "3 metres to go"),
    ("far", TURNING, None, "45 degrees to turn"),
    ("far", IDLE, None, "I am not going anywhere: the queue is empty"),
    ("where", IDLE, NEAR, "near the kitchen, 2 metres from it"),
    ("where", IDLE, AT, "at the base"),
    ("where", IDLE, None, "I do not know: the robot has not said where it is"),
    ("why", FAILED, None, "reach kitchen failed: navigation gave up on the way"),
    ("why", IDLE, None, "nothing has failed lately"),
]  # fmt: skip


@pytest.mark.parametrize(("question", "state", "pose", "said"), QUESTIONS)
def test_questions(question: str, state: State, pose: RobotPose | None, said: str) -> None:
    assert question_words(question, state, pose, PLACES) == said


def test_where_without_named_places_says_the_position() -> None:
    assert question_words("where", IDLE, NEAR, []) == "at x 3.0, y 3.0: no places are named"


def test_an_edits_record_is_not_the_failure_asked_about() -> None:
    edit = OrderRecord(
        id="e",
        order=Order(order="cancel", label="queue", description="cancel x"),
        status=OrderStatus.REJECTED,
        message="there is no x in the queue",
    )
    state = State(robot="r", history=[edit, *FAILED.history[1:]])
    assert question_words("why", state) == "reach kitchen failed: navigation gave up on the way"


@pytest.mark.parametrize(
    ("reason", "plain"),
    [
        ("navigation unavailable (no action server answered within 5 s)",
         "my navigation is not running"),
        ("no progress for 10 s, 0.52 short", "I got stuck on the way"),
        ("executor lost; halting the robot", "my driver stopped answering"),
        ("the supervisor restarted while it ran and no executor was there",
         "I was restarted while doing it"),
        ("the camera's 'yuv' frame does not open: bad",
         "the camera's 'yuv' frame does not open: bad"),
    ],
)  # fmt: skip
def test_reasons_in_plain_words(reason: str, plain: str) -> None:
    assert plain_reason(reason) == plain
