"""Stand-in until shared/answers.py lands (helper branch issue-34-voice)."""

from __future__ import annotations

from shared.messages import OrderRecord, OrderStatus, Proposal


def proposal_words(proposal: Proposal) -> str:
    if proposal.rejected or not proposal.orders:
        return "I did not catch that"
    return ", then ".join(order.description for order in proposal.orders)


def outcome_words(record: OrderRecord) -> str | None:
    if record.status is OrderStatus.SUCCEEDED:
        return f"done: {record.order.description}"
    if record.status is OrderStatus.FAILED:
        return f"{record.order.description} failed: {record.message}"
    return None


def stopped_words() -> str:
    return "stopped"


def refused_words(reason: str) -> str:
    return f"not sent: {reason}"
