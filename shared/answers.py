"""What voicectl says aloud: the project's messages as one short sentence for a person,
in the words the panel shows and in its language (services/web/static/answers.js says the
same in the browser; tests/test_panel_voice.py holds the two to one table). The words come
from the catalogue of the language (shared/words.py); a proposal says its own language."""

from __future__ import annotations

import re

from .messages import Doubt, OrderRecord, OrderStatus, Proposal, Stopped
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
    orders = word(language, "answer.then").join(
        spoken(order.description, language) for order in proposal.orders
    )
    missed = word(language, "answer.and").join(
        f"'{problem.text}'" for problem in proposal.errors if problem.text
    )
    if not orders:
        return not_caught
    if missed:
        return word(language, "answer.notCaughtSome", orders=orders, missed=missed)
    return orders


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
