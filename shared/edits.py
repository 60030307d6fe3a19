# msgspec subclasses inherit frozen=True; mypy's dataclass_transform does not know that.
# mypy: disable-error-code="misc"
"""Edits of a robot's queue and questions about it: orders of the reserved label `queue`.

An orders file writes them as orders (orders/queue.yaml; docs/orders.md, "Talking about
the queue"), so that they are heard, parsed and judged exactly as orders are. What each
one does is in its parameters, `edit: cancel`, `which: kitchen`; `read_edit` decodes them
once, into one of the Structs below, where they arrive (the converter checks them when a
file loads, the supervisor when it carries one out).
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum
from typing import Annotated

import msgspec

from .messages import Asked, Edit, Order, OrderRecord, OrderStatus, Submit

QUEUE_LABEL = "queue"
"""The label of the supervisor's own orders: never handed to an executor."""
LAST = "last"
"""`which: last`: the order added last that is still queued or running."""
MAX_VALUE = 1_000_000.0


class Question(StrEnum):
    DOING = "doing"
    """What are you doing?"""
    GOING = "going"
    """Where are you going?"""
    NEXT = "next"
    """What is next?"""
    LEFT = "left"
    """How many are left?"""
    FAR = "far"
    """How far is it?"""
    WHERE = "where"
    """Where are you?"""
    WHY = "why"
    """Why did that fail?"""


class UnitKind(StrEnum):
    """The kind of number a correction says ("no, three meters"): what it may replace."""

    ANY = ""
    LENGTH = "length"
    ANGLE = "angle"
    TIME = "time"


Which = Annotated[str, msgspec.Meta(min_length=1, max_length=200)]
"""`last`, or the name of a case (or of an order without cases), as a `type: order` slot
writes it."""


class EditBase(
    msgspec.Struct,
    tag_field="edit",
    tag=lambda name: name.removesuffix("Edit").lower(),
    kw_only=True,
    frozen=True,
    forbid_unknown_fields=True,
):
    """What an order of label `queue` asks for, read from its parameters."""


class CancelEdit(EditBase):
    which: Which


class ClearEdit(EditBase):
    pass


class FirstEdit(EditBase):
    which: Which


class AfterEdit(EditBase):
    pass


class SkipEdit(EditBase):
    pass


class PauseEdit(EditBase):
    pass


class ResumeEdit(EditBase):
    pass


class UndoEdit(EditBase):
    pass


class ReplaceEdit(EditBase):
    """A correction: the order named becomes itself with another number or another case."""

    which: Which = LAST
    value: Annotated[float, msgspec.Meta(ge=-MAX_VALUE, le=MAX_VALUE)] | None = None
    instead: Which | None = None
    """The name of the case it becomes ("bathroom")."""
    unit: UnitKind = UnitKind.ANY
    """What kind of number `value` is, when the person said its unit."""

    def __post_init__(self) -> None:
        if (self.value is None) == (self.instead is None):
            raise ValueError("a replace edit needs 'value' or 'instead', and not both")


class AskEdit(EditBase):
    question: Question


QueueEdit = (
    CancelEdit
    | ClearEdit
    | FirstEdit
    | AfterEdit
    | SkipEdit
    | PauseEdit
    | ResumeEdit
    | UndoEdit
    | ReplaceEdit
    | AskEdit
)
EDITS = ", ".join(
    kind.__struct_config__.tag
    for kind in (
        CancelEdit,
        ClearEdit,
        FirstEdit,
        AfterEdit,
        SkipEdit,
        PauseEdit,
        ResumeEdit,
        UndoEdit,
        ReplaceEdit,
        AskEdit,
    )
    if isinstance(kind.__struct_config__.tag, str)
)
"""The `edit:` values there are, for error messages."""


UNDONE = "undone"
"""Why an order an edit added ended when the edit was undone."""


def cancelled_by(edit: Order) -> str:
    """Why an order an edit ended ended, as its record says."""
    return f"cancelled by “{edit.description}”"


def replaced_by(order: Order) -> str:
    return f"replaced by “{order.description}”"


def ended_by_edit(record: OrderRecord) -> bool:
    """Whether an edit of the queue ended `record` (its answer said so already)."""
    message = record.message
    return record.status is OrderStatus.CANCELLED and (
        message.startswith(("cancelled by “", "replaced by “")) or message == UNDONE
    )


def is_edit(order: Order) -> bool:
    """Whether `order` is the supervisor's own (an edit or a question)."""
    return order.label == QUEUE_LABEL


def read_edit(order: Order) -> QueueEdit:
    """The edit an order of label `queue` asks for; ValueError in one line saying what is
    wrong with its parameters and what is allowed."""
    try:
        edit: QueueEdit = msgspec.convert(order.params, QueueEdit)
    except msgspec.ValidationError as exc:
        raise ValueError(f"{exc} (edits: {EDITS})") from None
    return edit


def is_question(order: Order) -> bool:
    return is_edit(order) and order.params.get("edit") == "ask"


def edit_order(edit: QueueEdit, description: str) -> Order:
    """An order of label `queue` for `edit`, as a panel's button or a script makes one."""
    params = msgspec.to_builtins(edit)
    return Order(order=params["edit"], label=QUEUE_LABEL, description=description, params=params)


def requests(
    orders: Sequence[Order], transcript: str, asked: Asked | None, request_id: str
) -> list[Submit | Edit]:
    """What a text's orders ask of the supervisor, in order: the orders next to each other
    are one submit, each edit an edit request (an `after` edit brings the orders said
    after it, up to the next edit). The request ids are `request_id`, numbered when there
    are several, so that a retry of the whole is harmless too."""
    groups: list[tuple[Order | None, list[Order]]] = []
    for order in orders:
        if is_edit(order):
            groups.append((order, []))
            continue
        last = groups[-1][0] if groups else order
        if last is None or (last is not order and isinstance(_kind(last), AfterEdit)):
            groups[-1][1].append(order)
        else:
            groups.append((None, [order]))
    made: list[Submit | Edit] = []
    for number, (edit, brought) in enumerate(groups):
        named = request_id if len(groups) == 1 else f"{request_id}-{number}"
        if edit is None:
            made.append(
                Submit(request_id=named, orders=brought, transcript=transcript, asked=asked)
            )
        else:
            made.append(
                Edit(
                    request_id=named, edit=edit, orders=brought, transcript=transcript, asked=asked
                )
            )
    return made


def _kind(order: Order) -> QueueEdit | None:
    try:
        return read_edit(order)
    except ValueError:
        return None
