"""The one client of voicectl's request/reply services: the converter and a robot's
supervisor. `voicectl` commands, the panel's API and the tests ask through it, so a
request is built, sent and its reply decoded in one place, with one timeout.

A service that cannot be reached raises `Unreachable`; one that answers `Failed` raises
`Refused`; both name the service. Anything else comes back typed.
"""

from __future__ import annotations

import uuid

import msgspec

from .bus import Bus, json_decoder
from .errors import BusError, VoicectlError
from .keys import ConverterKeys, RobotKeys
from .messages import (
    EmergencyStop,
    Failed,
    Message,
    Order,
    ParseReply,
    ParseRequest,
    ParseResult,
    Submit,
    Submitted,
    SupervisorReply,
)

TIMEOUT = 10.0
"""Seconds a service has to answer. Each answers at once (a submit once it is stored);
the margin is for a loaded machine, not for slow work."""


class Refused(VoicectlError):
    """A service answered the request with `Failed`."""

    def __init__(self, service: str, reason: str) -> None:
        super().__init__(f"{service}: {reason}")
        self.service = service
        self.reason = reason


class Unreachable(BusError):
    """No answer from a service: no router, the service is not up, or (on a secured
    bus) the router does not let this user ask it."""

    def __init__(self, service: str, cause: BusError) -> None:
        super().__init__(str(cause))
        self.service = service


class Said(msgspec.Struct, frozen=True):
    """What a text became, and the ids of the orders submitted for it (none when nothing
    was submitted)."""

    result: ParseResult
    order_ids: list[str]


class VoicectlClient:
    """Ask the converter and the supervisors over one bus."""

    def __init__(self, bus: Bus, timeout: float = TIMEOUT) -> None:
        self.bus = bus
        self.timeout = timeout
        self._parse_decode = json_decoder(ParseReply | Failed)
        self._supervisor_decode = json_decoder(SupervisorReply)

    async def parse(self, text: str) -> ParseResult:
        """What the converter makes of `text`."""
        try:
            reply: ParseReply | Failed = await self.bus.request(
                ConverterKeys().parse, ParseRequest(text=text), self._parse_decode, self.timeout
            )
        except BusError as exc:
            raise Unreachable("converter", exc) from exc
        if isinstance(reply, Failed):
            raise Refused("converter", reply.reason)
        return reply.result

    async def request(self, robot: str, request: Message) -> SupervisorReply:
        """Ask `robot`'s supervisor; its reply as it is, `Failed` included. An emergency
        stop goes first and waits for room rather than being dropped."""
        try:
            reply: SupervisorReply = await self.bus.request(
                RobotKeys(robot).supervisor,
                request,
                self._supervisor_decode,
                self.timeout,
                urgent=isinstance(request, EmergencyStop),
            )
        except BusError as exc:
            raise Unreachable("supervisor", exc) from exc
        return reply

    async def ask(self, robot: str, request: Message) -> SupervisorReply:
        """Ask `robot`'s supervisor; Refused if it answers Failed."""
        reply = await self.request(robot, request)
        if isinstance(reply, Failed):
            raise Refused("supervisor", reply.reason)
        return reply

    async def submit(
        self,
        robot: str,
        orders: list[Order],
        transcript: str = "",
        request_id: str | None = None,
    ) -> list[str]:
        """Queue `orders` on `robot`; their ids. The request id makes a retry harmless."""
        submit = Submit(
            request_id=request_id or uuid.uuid4().hex, orders=orders, transcript=transcript
        )
        reply = await self.ask(robot, submit)
        if not isinstance(reply, Submitted):
            raise Refused("supervisor", f"answered {type(reply).__name__} to a submit")
        return reply.order_ids

    async def say(self, robot: str, text: str, partial: bool = False) -> Said:
        """Parse `text` and submit its orders: only when every part of it made an order,
        unless `partial`, which submits what was understood."""
        result = await self.parse(text)
        sending = result.orders if partial or not result.errors else []
        order_ids = await self.submit(robot, sending, transcript=text) if sending else []
        return Said(result=result, order_ids=order_ids)
