# msgspec subclasses inherit frozen=True; mypy's dataclass_transform does not know that.
# mypy: disable-error-code="misc"
"""The messages voicectl services exchange, as msgspec Structs encoded as JSON.

Each key expression carries one tagged union; a receiver builds one typed decoder for it
once and dispatches on the decoded type with ``match``. New fields always get defaults so
that older and newer services can talk.
"""

from __future__ import annotations

from enum import StrEnum

import msgspec

ParamValue = str | int | float | bool


class Message(msgspec.Struct, tag_field="type", tag=str.lower, kw_only=True, frozen=True):
    """Base of every message on the bus; the tag names its type in the JSON."""


class Data(msgspec.Struct, kw_only=True, frozen=True):
    """Base of values nested inside messages (no tag)."""


# --- orders -----------------------------------------------------------------------------


class TargetPose(Data):
    """A planar goal pose; `frame` is a ROS frame id such as 'map' or 'base_link'."""

    frame: str
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    """Heading in radians, counter-clockwise."""


class Order(Data, kw_only=True):
    """One thing for the robot to do, as the converter made it from words."""

    order: str
    """Name of the order in the orders file ('rotation')."""
    case: str | None = None
    """Name of the matched case ('left'), or None for an order without cases."""
    label: str
    """Which executor runs it ('mbgoal')."""
    description: str
    """Human wording of what will happen ('turn left')."""
    params: dict[str, ParamValue] = msgspec.field(default_factory=dict)
    """Every key of the order and its case that is not a known one."""
    target_pose: TargetPose | None = None


class ParseError(Data, omit_defaults=True):
    """A piece of text that did not become an order, and why."""

    text: str
    reason: str
    candidates: list[str] = msgspec.field(default_factory=list)
    """Orders the text could have meant, for the user to pick from; never dispatched alone."""


class ParseResult(Data):
    """What the converter made of a text: orders in spoken order, plus errors."""

    orders: list[Order] = msgspec.field(default_factory=list)
    errors: list[ParseError] = msgspec.field(default_factory=list)


class Transcript(Message):
    """A final transcript from the speech recogniser."""

    text: str
    confidence: float | None = None


class Proposal(Message):
    """The converter's reading of a transcript, for the panel to show and confirm."""

    transcript: str
    orders: list[Order] = msgspec.field(default_factory=list)
    errors: list[ParseError] = msgspec.field(default_factory=list)


class ParseRequest(Message):
    text: str


class GetGrammar(Message):
    """Ask for the current recogniser grammar (a recogniser that starts late does this)."""


ConverterRequest = ParseRequest | GetGrammar


class ParseReply(Message):
    result: ParseResult


class Grammar(Message):
    """Everything a speech recogniser needs to listen only for valid commands.

    Published on every change of the orders and answered on request.
    """

    jsgf: str
    """A JSGF grammar whose public rule accepts every phrase the orders can produce."""
    phrases: list[str] = msgspec.field(default_factory=list)
    """Every single-order phrase, expanded (sequences join them with the separator)."""
    words: list[str] = msgspec.field(default_factory=list)
    """Every word that can occur in a command, sorted."""
    separator_phrases: list[str] = msgspec.field(default_factory=list)
    unexpandable: list[str] = msgspec.field(default_factory=list)
    """Orders whose alias cannot be expanded to a finite set, one line each saying why."""
    version: str = ""
    """Changes whenever the orders change (a digest of the phrases)."""


class OrdersStatus(Message):
    """Whether the last (re)load of the orders files worked; errors keep the previous orders."""

    ok: bool
    sources: list[str] = msgspec.field(default_factory=list)
    errors: list[str] = msgspec.field(default_factory=list)
    orders: int = 0
    """How many orders are loaded (the previous set when the reload failed)."""


# --- supervisor ---------------------------------------------------------------------------


class OrderStatus(StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELLED = "cancelled"
    REJECTED = "rejected"
    INTERRUPTED = "interrupted"
    """It was running when the supervisor stopped, and the executor no longer runs it."""


class Progress(Data):
    """How far the current order has come, as much as the executor knows."""

    text: str = ""
    distance_linear: float | None = None
    """Metres still to go."""
    distance_angular: float | None = None
    """Radians still to turn."""
    percent: float | None = None


class OrderRecord(Data):
    """An order as the supervisor tracks it, from acceptance to its result."""

    id: str
    order: Order
    status: OrderStatus
    transcript: str = ""
    request_id: str = ""
    message: str = ""
    """The executor's last word on it (why it failed, what it did)."""
    progress: Progress | None = None
    submitted_at: float = 0.0
    started_at: float | None = None
    ended_at: float | None = None


class State(Data):
    """Everything a panel needs to show a robot's orders at a glance."""

    robot: str
    executor_online: bool = False
    current: OrderRecord | None = None
    queue: list[OrderRecord] = msgspec.field(default_factory=list)
    """The head of the queue, in dispatch order (at most a page; see `queue_length`)."""
    queue_length: int = 0
    history: list[OrderRecord] = msgspec.field(default_factory=list)
    """Recent history, most recent first; GetHistory pages through all of it."""


class Submit(Message):
    """Queue a batch of orders (one utterance); `request_id` makes retries harmless."""

    request_id: str
    orders: list[Order]
    transcript: str = ""


class Cancel(Message):
    order_id: str


class CancelAll(Message):
    pass


class EmergencyStop(Message):
    pass


class GetState(Message):
    pass


class Reorder(Message):
    """Move a queued order to `position` (0 is next)."""

    order_id: str
    position: int


class GetHistory(Message):
    """A page of finished orders, most recent first."""

    offset: int = 0
    limit: int = 50


SupervisorRequest = Submit | Cancel | CancelAll | EmergencyStop | GetState | Reorder | GetHistory


class Submitted(Message):
    order_ids: list[str]


class Done(Message):
    """A request that needs no answer beyond 'it happened'."""

    detail: str = ""


class Failed(Message):
    """A request that could not be carried out; `reason` says why in one line."""

    reason: str


class StateReply(Message):
    state: State


class HistoryPage(Message):
    records: list[OrderRecord]
    total: int
    """How many finished orders the robot has in all."""
    offset: int = 0


class StateUpdate(Message):
    """Published on the state key whenever anything changes."""

    state: State


SupervisorReply = Submitted | Done | Failed | StateReply | HistoryPage

ConverterReply = ParseReply | Grammar | Failed


# --- executor ------------------------------------------------------------------------------


class Execute(Message):
    """Run one order; the reply only says whether the executor took it."""

    order_id: str
    order: Order


class CancelOrder(Message):
    order_id: str


class Halt(Message):
    """Stop all motion now, outside any order."""


class GetRunning(Message):
    """Which order is the executor running? Asked by a supervisor that restarted."""


ExecutorRequest = Execute | CancelOrder | Halt | GetRunning


class Accepted(Message):
    order_id: str


class Rejected(Message):
    order_id: str
    reason: str


class Running(Message):
    order_id: str | None = None
    """None when idle."""


class OrderProgress(Message):
    order_id: str
    progress: Progress


class OrderFinished(Message):
    order_id: str
    status: OrderStatus
    """succeeded, failed or cancelled."""
    message: str = ""


ExecutorEvent = OrderProgress | OrderFinished


ExecutorReply = Accepted | Rejected | Done | Failed | Running | OrderFinished
"""A cancel for an order that has just finished is answered with its OrderFinished, so
the supervisor records what really happened."""
