"""The converter on the bus: parse requests, transcripts to proposals, grammar, hot reload."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass
from pathlib import Path

from voicectl.shared.bus import Bus, Latest, json_decoder
from voicectl.shared.edits import ReplaceEdit, read_edit
from voicectl.shared.errors import OrdersFileError
from voicectl.shared.keys import ConverterKeys, RobotKeys, robot_of
from voicectl.shared.messages import (
    Amend,
    Amended,
    ConverterRequest,
    Failed,
    GetGrammar,
    Grammar,
    Message,
    Order,
    OrdersStatus,
    ParseReply,
    ParseRequest,
    Places,
    Proposal,
    Transcript,
    excerpt,
)
from voicectl.shared.process import Service

from .amend import AmendRefused
from .decide import decide, problem, readings
from .grammar import build_grammar
from .orders import OrderSet, OrdersInvalid
from .parser import Parser
from .places import places_of
from .watch import Signature, signature

_LOGGER = logging.getLogger(__name__)

POLL_SECONDS = 0.25
"""How often the orders files are checked for changes; a change applies within a second."""


@dataclass(frozen=True)
class Loaded:
    """One consistent configuration: the orders, their parser and their grammar."""

    orders: OrderSet
    parser: Parser
    grammar: Grammar
    signature: Signature
    """The files' metadata as it was just before they were read."""


def load(path: Path, before: Signature) -> Loaded:
    """Read, validate and compile the orders at `path` (blocking: run it in a thread).

    `before` is the files' signature taken just before. Raises OrdersFileError; nothing is
    half-loaded.
    """
    orders = OrderSet.load(path)
    return Loaded(orders, Parser(orders), build_grammar(orders), before)


def errors_of(exc: OrdersFileError) -> list[str]:
    return list(exc.errors) if isinstance(exc, OrdersInvalid) else [str(exc)]


class ConverterService(Service):
    """Answers parse and grammar queries, turns final transcripts into proposals, and
    reloads the orders when their files change, keeping the last good ones on errors.

    A service (shared/process.py): `start()` serves and announces it, `run()` watches the
    files, `stop()` undeclares its publishers.
    """

    def __init__(
        self, bus: Bus, path: Path, loaded: Loaded, poll_seconds: float = POLL_SECONDS
    ) -> None:
        self._bus = bus
        self._path = path
        self._loaded = loaded
        self._poll_seconds = poll_seconds
        self._keys = ConverterKeys()
        self._failed: Signature | None = None
        """The signature of files that did not load, so that they are not re-read each poll."""
        self._closers = contextlib.ExitStack()
        self._grammar: Latest | None = None
        self._status: Latest | None = None
        self._places: Latest | None = None

    @property
    def loaded(self) -> Loaded:
        return self._loaded

    async def start(self) -> None:
        self._grammar = self._closers.enter_context(
            contextlib.closing(self._bus.latest(self._keys.grammar))
        )
        self._status = self._closers.enter_context(
            contextlib.closing(self._bus.latest(self._keys.status))
        )
        self._places = self._closers.enter_context(
            contextlib.closing(self._bus.latest(self._keys.places))
        )
        self._bus.serve(self._keys.parse, json_decoder(ConverterRequest), self._on_request)
        self._bus.subscribe(
            self._keys.all_transcripts, json_decoder(Transcript), self._on_transcript
        )
        self._publish_loaded()
        self._bus.announce(self._keys.alive())
        loaded = self._loaded
        _LOGGER.info(
            "converter ready with %d orders from %s; grammar %s (%d phrases)",
            len(loaded.orders.orders),
            self._path,
            loaded.grammar.version,
            len(loaded.grammar.phrases),
        )

    async def stop(self) -> None:
        self._closers.close()

    async def run(self) -> None:
        """Reload whenever the files' signature changes; runs until cancelled."""
        while True:
            await asyncio.sleep(self._poll_seconds)
            current = await asyncio.to_thread(signature, self._path)
            if current not in (self._loaded.signature, self._failed):
                await self.reload(current)

    async def reload(self, current: Signature) -> None:
        """Load the files as they are now (`current`); on errors keep the previous orders."""
        try:
            loaded = await asyncio.to_thread(load, self._path, current)
        except OrdersFileError as exc:
            self._failed = current
            errors = errors_of(exc)
            _LOGGER.warning("orders not reloaded, keeping the previous ones: %s", errors[0])
            self._publish_status(
                OrdersStatus(
                    ok=False,
                    sources=list(self._loaded.orders.sources),
                    errors=errors,
                    orders=len(self._loaded.orders.orders),
                )
            )
            return
        self._loaded = loaded
        self._failed = None
        _LOGGER.info("orders reloaded: %d orders from %s", len(loaded.orders.orders), self._path)
        self._publish_loaded()

    def _publish_loaded(self) -> None:
        orders = self._loaded.orders
        assert self._grammar is not None, "publishing before the service started"
        assert self._places is not None
        self._grammar.publish(self._loaded.grammar)
        self._places.publish(Places(places=places_of(orders)))
        self._publish_status(
            OrdersStatus(ok=True, sources=list(orders.sources), orders=len(orders.orders))
        )

    def _publish_status(self, status: OrdersStatus) -> None:
        assert self._status is not None, "publishing before the service started"
        self._status.publish(status)

    async def _on_request(self, request: ConverterRequest) -> Message:
        match request:
            case ParseRequest(text=text):
                return ParseReply(result=self._loaded.parser.parse(text))
            case GetGrammar():
                return self._loaded.grammar
            case Amend(order=order, change=change):
                return self._amend(order, change)

    def _amend(self, order: Order, change: Order) -> Message:
        """`order` made again as the correction `change` says, or why not."""
        try:
            edit = read_edit(change)
        except ValueError as exc:
            return Failed(reason=f"not a correction: {exc}")
        if not isinstance(edit, ReplaceEdit):
            return Failed(reason=f"not a correction: '{change.description}' is another edit")
        try:
            return Amended(order=self._loaded.parser.amender.amend(order, edit))
        except AmendRefused as exc:
            return Failed(reason=str(exc))

    def _on_transcript(self, key: str, transcript: Transcript) -> None:
        """The one decision on what was said (decide.py): the grammar's result, and what
        the recogniser's second ear heard, read by this converter's parser. Speech must make
        whole orders: unlike typed text, a part that did not parse is a sign the rest was
        misheard too. Speech that is not a command never becomes orders."""
        robot = robot_of(key)
        decision = decide(*readings(transcript, self._loaded.parser))
        proposal = Proposal(
            transcript=decision.text,
            orders=decision.orders,
            errors=[problem(decision)] if decision.rejected else [],
            session=transcript.session,
            utterance=transcript.utterance,
            rejected=decision.rejected,
            doubts=decision.doubts,
            hearings=decision.hearings if len(decision.hearings) > 1 else [],
            decision=decision.reason,
        )
        _LOGGER.info(
            "%s: %s -> %s",
            robot,
            " / ".join(f"{h.ear} {excerpt(h.text)}" for h in decision.hearings),
            f"nothing ({decision.reason})" if decision.rejected else decision.reason,
        )
        self._bus.publish(RobotKeys(robot).proposal, proposal)
