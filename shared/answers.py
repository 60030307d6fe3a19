"""What voicectl says aloud: the project's messages as one short sentence for a person,
in the words the panel shows (services/web/static/answers.js says the same in the browser;
tests/test_panel_voice.py holds the two to one table)."""

from __future__ import annotations

import re

from .messages import Doubt, OrderRecord, OrderStatus, Proposal, Stopped

NOT_CAUGHT = "I did not catch that"
SHORT_REASON = 60
"""Characters of an executor's reason that are read out: its first clause, cut at a word."""

_UNITS = [
    (re.compile(r"(?<![\d.])1 m\b"), "1 metre"),
    (re.compile(r"(\d) m\b"), r"\1 metres"),
    (re.compile(r"(?<![\d.])1 s\b"), "1 second"),
    (re.compile(r"(\d) s\b"), r"\1 seconds"),
    (re.compile(r"(\d) ?°"), r"\1 degrees"),
]
"""The panel's abbreviations ('move forward 2 m') as people say them ('2 metres')."""

_DONE = {"reach": "reached", "turn": "turned", "move": "moved", "go": "went", "wait": "waited"}
"""Orders whose first word has a past tense to say they are done ('reached kitchen');
any other is 'done: take picture'."""


def spoken(description: str) -> str:
    """An order's description as it is said rather than written."""
    for pattern, said in _UNITS:
        description = pattern.sub(said, description)
    return description


def proposal_words(proposal: Proposal) -> str:
    """What the recogniser made of an utterance: its orders, the question it asks, or that
    it did not catch it (never the engineer's reason the panel shows beside it)."""
    if proposal.rejected:
        return NOT_CAUGHT
    if proposal.doubts:
        asked = [doubt_words(proposal.transcript, doubt) for doubt in proposal.doubts]
        return ", and ".join(question.removesuffix("?") for question in asked) + "?"
    orders = ", then ".join(spoken(order.description) for order in proposal.orders)
    missed = " and ".join(f"'{problem.text}'" for problem in proposal.errors if problem.text)
    if not orders:
        return NOT_CAUGHT
    return f"{orders}; I did not catch {missed}" if missed else orders


def doubt_words(transcript: str, doubt: Doubt) -> str:
    """The question the panel asks with buttons, aloud: 'ten or two meters?' (the doubtful
    words, what they may have been, and the word after them, usually the unit)."""
    choices = [doubt.words, *doubt.alternatives]
    asked = choices[0] if len(choices) == 1 else f"{', '.join(choices[:-1])} or {choices[-1]}"
    after = transcript.split()[doubt.position + len(doubt.words.split()) :][:1]
    return f"{' '.join([asked, *after])}?"


def outcome_words(record: OrderRecord) -> str | None:
    """How an order ended, or None while it has not (queued, running)."""
    what = spoken(record.order.description)
    match record.status:
        case OrderStatus.SUCCEEDED:
            verb, _, rest = what.partition(" ")
            return f"{_DONE[verb]} {rest}".strip() if verb in _DONE else f"done: {what}"
        case OrderStatus.FAILED:
            return f"{what} failed" + (f": {short(record.message)}" if record.message else "")
        case OrderStatus.CANCELLED:
            return f"{what} cancelled"
        case OrderStatus.REJECTED:
            return f"{what} refused" + (f": {short(record.message)}" if record.message else "")
        case OrderStatus.INTERRUPTED:
            return f"{what} interrupted"
        case _:
            return None


def short(reason: str) -> str:
    """An executor's reason cut to what an ear takes in: its first clause, at most
    SHORT_REASON characters ending on a whole word."""
    clause = re.split(r"[;(\n]", reason, maxsplit=1)[0].strip().rstrip(".,:")
    if len(clause) <= SHORT_REASON:
        return clause
    return clause[:SHORT_REASON].rsplit(" ", 1)[0]


def stopped_words(stopped: Stopped) -> str:
    """The emergency stop's answer: 'stopped', or that the robot did not confirm it."""
    return "stopped" if stopped.confirmed else "stop sent, not confirmed"
