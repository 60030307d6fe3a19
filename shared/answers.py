"""What voicectl says aloud: the project's messages as one short sentence for a person,
in the words the panel shows and in its language (services/web/static/answers.js says the
same in the browser; tests/test_panel_voice.py holds the two to one table). The words come
from the catalogue of the language (shared/words.py); a proposal says its own language."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from .edits import QUEUE_LABEL
from .messages import (
    Doubt,
    Order,
    OrderRecord,
    OrderStatus,
    Place,
    Proposal,
    RobotPose,
    State,
    Stopped,
)
from .words import ENGLISH, table, word

NOT_CAUGHT = "I did not catch that"
"""English `answer.notCaught`."""
SHORT_REASON = 60
"""Characters of an executor's reason that are read out: its first clause, cut at a word."""

_UNITS = [
    (re.compile(r"(?<![\d.])1 m\b"), "answer.metre", False),
    (re.compile(r"(\d+(?:\.\d+)?) m\b"), "answer.metres", True),
    (re.compile(r"(?<![\d.])1 s\b"), "answer.second", False),
    (re.compile(r"(\d+(?:\.\d+)?) s\b"), "answer.seconds", True),
    (re.compile(r"(\d+(?:\.\d+)?) ?°"), "answer.degrees", True),
]
"""The panel's abbreviations ('move forward 2 m') as people say them ('2 metres')."""


def spoken(description: str, language: str = ENGLISH) -> str:
    """An order's description as it is said rather than written."""
    for pattern, key, counted in _UNITS:
        said = word(language, key, n=r"\1") if counted else word(language, key)
        description = pattern.sub(said, description)
    return description


def proposal_words(proposal: Proposal, language: str = "") -> str:
    """What the recogniser made of an utterance: its orders, the question it asks, or that
    it did not catch it (never the engineer's reason the panel shows beside it), in the
    proposal's language unless `language` says otherwise."""
    language = language or proposal.language
    not_caught = word(language, "answer.notCaught")
    if proposal.rejected:
        return not_caught
    if proposal.doubts:
        asked = [doubt_words(proposal.transcript, d, language) for d in proposal.doubts]
        joined = word(language, "answer.andAsk").join(q.removesuffix("?") for q in asked)
        return f"{joined}?"
    orders = orders_words(proposal.orders, language)
    missed = word(language, "answer.and").join(
        f"'{problem.text}'" for problem in proposal.errors if problem.text
    )
    if not orders:
        return not_caught
    if missed:
        return word(language, "answer.notCaughtSome", orders=orders, missed=missed)
    return orders


def orders_words(orders: Sequence[Order], language: str = ENGLISH) -> str:
    """Orders read back: 'turn left, then reach kitchen'."""
    return word(language, "answer.then").join(
        spoken(order.description, language) for order in orders
    )


def doubt_words(transcript: str, doubt: Doubt, language: str = ENGLISH) -> str:
    """The question the panel asks with buttons, aloud: 'ten or two meters?' (the doubtful
    words, what they may have been, and the word after them, usually the unit)."""
    choices = [doubt.words, *doubt.alternatives]
    either = word(language, "answer.or")
    asked = choices[0] if len(choices) == 1 else f"{', '.join(choices[:-1])}{either}{choices[-1]}"
    after = transcript.split()[doubt.position + len(doubt.words.split()) :][:1]
    return f"{' '.join([asked, *after])}?"


def outcome_words(record: OrderRecord, language: str = ENGLISH) -> str | None:
    """How an order ended, or None while it has not (queued, running)."""
    what = spoken(record.order.description, language)
    why = short(record.message) if record.message else ""
    match record.status:
        case OrderStatus.SUCCEEDED:
            verb, _, rest = what.partition(" ")
            past = table(language, "answer.past").get(verb)
            return f"{past} {rest}".strip() if past else word(language, "answer.done", what=what)
        case OrderStatus.FAILED:
            key = "answer.failedWhy" if why else "answer.failed"
            return word(language, key, what=what, why=why)
        case OrderStatus.CANCELLED:
            return word(language, "answer.cancelled", what=what)
        case OrderStatus.REJECTED:
            key = "answer.refusedWhy" if why else "answer.refused"
            return word(language, key, what=what, why=why)
        case OrderStatus.INTERRUPTED:
            return word(language, "answer.interrupted", what=what)
        case _:
            return None


def short(reason: str) -> str:
    """An executor's reason cut to what an ear takes in: its first clause, at most
    SHORT_REASON characters ending on a whole word."""
    clause = re.split(r"[;(\n]", reason, maxsplit=1)[0].strip().rstrip(".,:")
    if len(clause) <= SHORT_REASON:
        return clause
    return clause[:SHORT_REASON].rsplit(" ", 1)[0]


def stopped_words(stopped: Stopped, language: str = ENGLISH) -> str:
    """The emergency stop's answer: 'stopped', or that the robot did not confirm it."""
    return word(language, "answer.stopped" if stopped.confirmed else "answer.stopUnconfirmed")


# --- questions about the queue ---------------------------------------------------------

AT_PLACE = 0.5
"""Metres from a place within which the robot is "at" it rather than "near" it."""
SAME_PLACE = 0.01
"""Metres between an order's goal and a place for the order to go to that place."""
_DOING = {
    "reach": "going to",
    "go": "going",
    "turn": "turning",
    "rotate": "turning",
    "move": "moving",
    "drive": "driving",
    "wait": "waiting",
    "take": "taking",
}
"""An order's first word as what the robot is doing ('turn left': 'turning left'); any
other is 'doing: multiply primes'."""
_PLAIN = [
    (re.compile(r"^navigation unavailable"), "my navigation is not running"),
    (re.compile(r"^navigation ended (?:ABORTED|CANCELED)"), "navigation gave up on the way"),
    (re.compile(r"^navigation was cancelled on the robot"), "it was cancelled on the robot"),
    (re.compile(r"^navigation result lost"), "I lost touch with navigation"),
    (re.compile(r"^no progress for"), "I got stuck on the way"),
    (re.compile(r"^no odometry"), "I could not tell where I was"),
    (re.compile(r"^executor lost"), "my driver stopped answering"),
    (re.compile(r"^executor did not take it"), "my driver did not take it"),
    (re.compile(r"^executor unreachable"), "my driver did not answer"),
    (re.compile(r"restarted while it ran"), "I was restarted while doing it"),
    (re.compile(r"^emergency stop"), "the emergency stop ended it"),
    (re.compile(r"no executor serves|no executor for"), "nothing here can do that"),
    (re.compile(r"^busy with order"), "I was busy with another order"),
]
"""Executors' and the supervisor's reasons as a person says them; others are cut short."""


def plain_reason(message: str) -> str:
    """Why an order ended, in plain words ("I got stuck on the way")."""
    for pattern, said in _PLAIN:
        if pattern.search(message):
            return said
    return short(message)


def question_words(
    question: str,
    state: State,
    pose: RobotPose | None = None,
    places: Sequence[Place] = (),
) -> str:
    """The answer to a question about the robot's work (shared/edits.py's `Question`),
    from its state now: it stays true for as long as the state does."""
    current = state.current
    waiting = state.queue_length
    match question:
        case "doing":
            if current is None:
                return f"nothing: {_idle(state)}"
            after = f", {waiting} more after it" if waiting else ""
            far = distance_words(current)
            return f"I am {doing_words(current, places)}{f', {far}' if far else ''}{after}"
        case "going":
            if current is None:
                return f"nowhere: {_idle(state)}"
            place = place_of(current, places)
            if place is None:
                return f"I am {doing_words(current, places)}"
            far = distance_words(current)
            return f"to the {place.name}{f', {far}' if far else ''}"
        case "next":
            if not state.queue:
                return "nothing next: the queue is empty"
            more = f", then {waiting - 1} more" if waiting > 1 else ""
            return f"next: {spoken(state.queue[0].order.description)}{more}"
        case "left":
            if current is None:
                return f"{waiting} waiting{_until(state)}" if waiting else "nothing left"
            now = spoken(current.order.description)
            return f"{waiting + 1} left: {now} now" + (f", then {waiting} more" if waiting else "")
        case "far":
            if current is None:
                return f"I am not going anywhere: {_idle(state)}"
            return distance_words(current) or "I do not know yet"
        case "where":
            return where_words(pose, places)
        case "why":
            return why_words(state)
    return NOT_CAUGHT


def _idle(state: State) -> str:
    """Why nothing runs, in a few words."""
    if state.stopped:
        return "the emergency stop is on"
    if state.queue_length and state.paused:
        verb = "waits" if state.queue_length == 1 else "wait"
        return f"{_orders(state.queue_length)} {verb} until you say go on"
    if state.queue_length:
        return f"{_orders(state.queue_length)} waiting"
    return "the queue is empty"


def _until(state: State) -> str:
    return " until you say go on" if state.paused else ""


def _orders(count: int) -> str:
    return f"{count} order{'s' if count != 1 else ''}"


def doing_words(record: OrderRecord, places: Sequence[Place] = ()) -> str:
    """What the robot does for `record`: 'going to the kitchen', 'turning left'."""
    place = place_of(record, places)
    if place is not None:
        return f"going to the {place.name}"
    what = spoken(record.order.description)
    verb, _, rest = what.partition(" ")
    if verb in _DOING:
        return f"{_DOING[verb]} {rest}".strip()
    return f"doing: {what}"


def place_of(record: OrderRecord, places: Sequence[Place]) -> Place | None:
    """The named place an order goes to, if its goal is one."""
    pose = record.order.target_pose
    if pose is None or pose.frame != "map":
        return None
    for place in places:
        if math.hypot(place.pose.x - pose.x, place.pose.y - pose.y) <= SAME_PLACE:
            return place
    return None


def distance_words(record: OrderRecord) -> str:
    """How far the running order still has to go, as its executor last said: '3 m to go',
    '45 degrees to turn'; '' when it has not said."""
    progress = record.progress
    if progress is None:
        return ""
    if progress.distance_linear is not None:
        return f"{metres(progress.distance_linear)} to go"
    if progress.distance_angular is not None:
        degrees = math.floor(math.degrees(abs(progress.distance_angular)) + 0.5)
        return f"{degrees} degrees to turn"
    return ""


def metres(distance: float) -> str:
    """A distance as people say it: '3 metres', '2.5 metres', '1 metre'."""
    rounded = math.floor(abs(distance) * 10 + 0.5) / 10  # halves up, as the panel rounds
    shown = f"{rounded:g}"
    return f"{shown} metre" if shown == "1" else f"{shown} metres"


def where_words(pose: RobotPose | None, places: Sequence[Place]) -> str:
    """Where the robot is, in the words of the map's places."""
    if pose is None:
        return "I do not know: the robot has not said where it is"
    if not places:
        return f"at x {pose.x:.1f}, y {pose.y:.1f}: no places are named"
    nearest = min(places, key=lambda p: math.hypot(p.pose.x - pose.x, p.pose.y - pose.y))
    away = math.hypot(nearest.pose.x - pose.x, nearest.pose.y - pose.y)
    if away <= AT_PLACE:
        return f"at the {nearest.name}"
    return f"near the {nearest.name}, {metres(away)} from it"


def why_words(state: State) -> str:
    """Why the last order that failed failed, in plain words."""
    for record in state.history:
        if record.order.label == QUEUE_LABEL:
            continue
        if record.status in (OrderStatus.FAILED, OrderStatus.REJECTED, OrderStatus.INTERRUPTED):
            what = spoken(record.order.description)
            ended = {OrderStatus.REJECTED: "was refused", OrderStatus.INTERRUPTED: "stopped"}
            verb = ended.get(record.status, "failed")
            why = f": {plain_reason(record.message)}" if record.message else ""
            return f"{what} {verb}{why}"
    return "nothing has failed lately"


# --- what an edit did ----------------------------------------------------------------------


def left_words(count: int) -> str:
    """How many orders are left: 'nothing left', '1 left', '3 left'."""
    return f"{count} left" if count else "nothing left"
