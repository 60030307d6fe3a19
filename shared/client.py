"""The one client of voicectl's request/reply services: the converter and a robot's
supervisor. `voicectl` commands, the panel's API and the tests ask through it, so a
request is built, sent and its reply decoded in one place, with one timeout.

A service that cannot be reached raises `Unreachable`; one that answers `Failed` raises
`Refused`; both name the service. Anything else comes back typed.

STOP is the exception: it never waits on one process (`stop`).
"""

from __future__ import annotations

import asyncio
import contextlib
import uuid
from collections.abc import Coroutine
from typing import Any, TypeVar

import msgspec

from .bus import Bus, Decode, json_decoder
from .edits import requests
from .errors import BusError, VoicectlError
from .keys import ConverterKeys, RobotKeys, robot_of
from .messages import (
    Amend,
    Amended,
    Answered,
    Asked,
    Edit,
    EmergencyStop,
    ExecutorInfo,
    ExecutorReply,
    Failed,
    GetPhoto,
    Message,
    Order,
    ParseReply,
    ParseRequest,
    ParseResult,
    Photo,
    PhotoReply,
    Stopped,
    Submit,
    Submitted,
    SupervisorReply,
)
from .robot.stop import ExecutorLatch, RobotStop, StopProcedure, prepare

T = TypeVar("T")

TIMEOUT = 10.0
"""Seconds a service has to answer. Each answers at once (a submit once it is stored);
the margin is for a loaded machine, not for slow work."""
STOP_ANSWER = 1.5
"""Seconds the supervisor has to answer a STOP (it answers within a third of a second)
before the robot is stopped from here instead."""
INFO_WAIT = 0.5
"""Seconds a STOP waits to learn the robot's keys (what its executor last announced)."""


class Refused(VoicectlError):
    """A service answered the request with `Failed`."""

    def __init__(self, service: str, reason: str) -> None:
        super().__init__(f"{service}: {reason}")
        self.service = service
        self.reason = reason


class SayRefused(Refused):
    """A service refused what `VoicectlClient.say` asked: the text's orders, if the
    converter made them, come with the refusal (`result`, None when the converter itself
    refused)."""

    def __init__(self, refused: Refused, result: ParseResult | None) -> None:
        super().__init__(refused.service, refused.reason)
        self.result = result


class Unreachable(BusError):
    """No answer from a service: no router, the service is not up, or (on a secured
    bus) the router does not let this user ask it."""

    def __init__(self, service: str, cause: BusError) -> None:
        super().__init__(str(cause))
        self.service = service


class Said(msgspec.Struct, frozen=True):
    """What a text became, and the ids of the orders submitted for it (none when nothing
    was submitted), with the answers to its edits and questions."""

    result: ParseResult
    order_ids: list[str]
    answers: list[Answered] = msgspec.field(default_factory=list)


class Sent(msgspec.Struct, frozen=True):
    """What sending orders did: the ids of those queued, and the supervisor's answer to
    each edit and question among them, in order."""

    order_ids: list[str]
    answers: list[Answered]

    @property
    def done(self) -> bool:
        """Whether anything happened: orders queued, the queue changed, or a question
        answered (an edit refused did nothing)."""
        return bool(self.order_ids) or any(a.changed or not a.edit_id for a in self.answers)


class VoicectlClient:
    """Ask the converter and the supervisors over one bus."""

    def __init__(self, bus: Bus, timeout: float = TIMEOUT) -> None:
        self.bus = bus
        self.timeout = timeout
        self._parse_decode = json_decoder(ParseReply | Failed)
        self._amend_decode = json_decoder(Amended | Failed)
        self._supervisor_decode = json_decoder(SupervisorReply)
        self._executor_decode = json_decoder(ExecutorReply)
        self._photo_decode = json_decoder(PhotoReply)
        self._robots: dict[str, ExecutorInfo] = {}
        """What each robot's executor last said about reaching it: how to stop it
        without any other voicectl process."""
        self._announced = asyncio.Event()
        self._pending: set[asyncio.Future[Any]] = set()
        bus.subscribe(
            RobotKeys.any_robot().executor_info,
            json_decoder(ExecutorInfo),
            self._on_info,
            history=True,
        )

    def _on_info(self, key: str, info: ExecutorInfo) -> None:
        self._robots[robot_of(key)] = info
        self._announced.set()
        prepare(info, self.bus)

    async def _robot_stop(self, robot: str) -> RobotStop | None:
        """How to stop `robot`, once its executor's announcement is in (waiting at most
        `INFO_WAIT`); None if no executor ever announced it."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + INFO_WAIT
        while robot not in self._robots and loop.time() < deadline:
            self._announced.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout_at(deadline):
                    await self._announced.wait()
        info = self._robots.get(robot)
        return None if info is None else RobotStop.of(info, self.bus)

    async def stop(self, robot: str) -> Stopped:
        """Emergency stop that waits on no other process. The stop's procedure runs from
        here at once (`StopProcedure`: zero velocity, the executor latched, every
        navigation goal cancelled), while the supervisor is asked to stop, latch and
        clear; its answer is the answer. If it gives none within `STOP_ANSWER`, the
        answer is what the procedure from here did, and that the supervisor did not.
        Raises only when nothing at all could be done: no supervisor answered and no
        executor ever announced the robot, so that its keys are unknown."""
        asked = asyncio.ensure_future(self.request(robot, EmergencyStop()))
        direct = await self._robot_stop(robot)
        stopping = None
        if direct is not None:
            # The executor is latched from here too, as the supervisor will: the goal's
            # cancel can reach the robot, end the running order and let the supervisor
            # start the next one before the supervisor has heard of the stop.
            executor = ExecutorLatch(self.bus, RobotKeys(robot), self._executor_decode, STOP_ANSWER)
            stopping = self._keep(StopProcedure.begin(direct, executor).outcome())
        try:
            async with asyncio.timeout(STOP_ANSWER):
                reply = await asyncio.shield(asked)
        except (TimeoutError, Unreachable) as exc:
            asked.cancel()
            why = str(exc) or f"no answer in {STOP_ANSWER:g} s"
        else:
            match reply:
                case Stopped():
                    return reply
                case Failed(reason=reason):
                    why = reason
                case other:
                    why = f"answered {type(other).__name__}"
        if stopping is None:
            raise Unreachable(
                "supervisor",
                BusError(f"{why}; and no executor has announced robot '{robot}': nothing stopped"),
            )
        outcome = await stopping
        detail = (
            f"SUPERVISOR DID NOT STOP IT ({why}); stopped from here: {outcome.detail}; "
            "not latched: start the supervisor before new orders"
        )
        return Stopped(confirmed=outcome.confirmed, detail=detail)

    def _keep(self, work: Coroutine[Any, Any, T]) -> asyncio.Future[T]:
        """`work` running on its own, kept until done (the loop keeps only weak references)."""
        future = asyncio.ensure_future(work)
        self._pending.add(future)
        future.add_done_callback(self._pending.discard)
        return future

    async def parse(self, text: str, language: str = "") -> ParseResult:
        """What the converter makes of `text`, written in `language` (empty: its default)."""
        request = ParseRequest(text=text, language=language)
        reply: ParseReply = await self._converter(request, self._parse_decode)
        return reply.result

    async def amend(self, order: Order, change: Order) -> Order:
        """`order` made again as the correction `change` says ("no, three"); Refused, with
        the converter's reason, when it does not fit."""
        request = Amend(order=order, change=change)
        reply: Amended = await self._converter(request, self._amend_decode)
        return reply.order

    async def _converter(self, request: Message, decode: Decode[T | Failed]) -> T:
        """The converter's answer to `request`; Unreachable, or Refused with its reason."""
        try:
            reply = await self.bus.request(ConverterKeys().parse, request, decode, self.timeout)
        except BusError as exc:
            raise Unreachable("converter", exc) from exc
        if isinstance(reply, Failed):
            raise Refused("converter", reply.reason)
        return reply

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

    async def send(
        self,
        robot: str,
        orders: list[Order],
        transcript: str = "",
        asked: Asked | None = None,
        request_id: str | None = None,
    ) -> Sent:
        """Send what a text became to `robot`'s supervisor, in order: its orders queued,
        its edits of the queue applied and its questions answered (shared/edits.py cuts
        them into requests). Refused at the first request the supervisor refuses."""
        queued: list[str] = []
        answers: list[Answered] = []
        for made in requests(orders, transcript, asked, request_id or uuid.uuid4().hex):
            reply = await self.ask(robot, made)
            match reply:
                case Submitted(order_ids=ids) if isinstance(made, Submit):
                    queued += ids
                case Answered() if isinstance(made, Edit):
                    answers.append(reply)
                    queued += reply.order_ids
                case _:
                    raise Refused("supervisor", f"answered {type(reply).__name__}")
        return Sent(order_ids=queued, answers=answers)

    async def photo(self, robot: str, order_id: str) -> Photo:
        """The photo order `order_id` took on `robot`, from its executor; Refused when
        there is none."""
        try:
            reply: PhotoReply = await self.bus.request(
                RobotKeys(robot).executor_photo,
                GetPhoto(order_id=order_id),
                self._photo_decode,
                self.timeout,
            )
        except BusError as exc:
            raise Unreachable("executor", exc) from exc
        if isinstance(reply, Failed):
            raise Refused("executor", reply.reason)
        return reply

    async def say(
        self,
        robot: str,
        text: str,
        partial: bool = False,
        asked: Asked | None = None,
        language: str = "",
    ) -> Said:
        """Parse `text` (in `language`) and send its orders, edits and questions (`send`):
        only when every part of it made one, unless `partial`, which sends what was
        understood. A refusal is `SayRefused`, with what the text made."""
        try:
            result = await self.parse(text, language)
        except Refused as exc:
            raise SayRefused(exc, None) from exc
        sending = result.orders if partial or not result.errors else []
        try:
            sent = await self.send(robot, sending, text, asked) if sending else None
        except Refused as exc:
            raise SayRefused(exc, result) from exc
        if sent is None:
            return Said(result=result, order_ids=[])
        return Said(result=result, order_ids=sent.order_ids, answers=sent.answers)
