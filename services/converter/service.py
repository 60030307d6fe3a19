"""The converter on the bus: parse requests, transcripts to proposals."""

from __future__ import annotations

import logging

from shared.bus import Bus, json_decoder
from shared.keys import ConverterKeys, RobotKeys, robot_of
from shared.messages import (
    ConverterRequest,
    Failed,
    GetGrammar,
    Message,
    ParseReply,
    ParseRequest,
    Proposal,
    Transcript,
)

from .parser import Parser

_LOGGER = logging.getLogger(__name__)


class ConverterService:
    """Answers parse queries and turns every robot's final transcripts into proposals."""

    def __init__(self, bus: Bus, parser: Parser) -> None:
        self._bus = bus
        self._parser = parser
        self._keys = ConverterKeys()

    def start(self) -> None:
        self._bus.serve(self._keys.parse, json_decoder(ConverterRequest), self._on_request)
        self._bus.subscribe(
            self._keys.all_transcripts, json_decoder(Transcript), self._on_transcript
        )
        self._bus.announce(self._keys.alive)

    async def _on_request(self, request: ConverterRequest) -> Message:
        match request:
            case ParseRequest(text=text):
                return ParseReply(result=self._parser.parse(text))
            case GetGrammar():
                return Failed(reason="this converter does not build grammars yet")

    def _on_transcript(self, key: str, transcript: Transcript) -> None:
        robot = robot_of(key)
        result = self._parser.parse(transcript.text)
        _LOGGER.info(
            "%s: %r -> %d order(s), %d error(s)",
            robot,
            transcript.text,
            len(result.orders),
            len(result.errors),
        )
        proposal = Proposal(transcript=transcript.text, orders=result.orders, errors=result.errors)
        self._bus.publish(RobotKeys(robot).proposal, proposal)
