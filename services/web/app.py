"""The panel's HTTP API: typed or spoken text in, orders out, live state back.

Every /api route but /api/health needs ``Authorization: Bearer <token>``: the panel
drives a machine. The live stream (/api/events) is server-sent events read with fetch,
so the token travels in a header and never in a URL that a log could keep.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import msgspec
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Route

from shared.bus import Bus, json_decoder
from shared.errors import BusError
from shared.keys import ConverterKeys, RobotKeys
from shared.messages import (
    Cancel,
    CancelAll,
    Done,
    EmergencyStop,
    Failed,
    GetHistory,
    GetState,
    Message,
    Order,
    ParseReply,
    ParseRequest,
    Proposal,
    Reorder,
    StateReply,
    StateUpdate,
    Submit,
    Submitted,
    SupervisorReply,
)

_LOGGER = logging.getLogger(__name__)
STATIC = Path(__file__).parent / "static"
MAX_BODY = 64 * 1024
BUS_TIMEOUT = 5.0


class SubmitBody(msgspec.Struct, forbid_unknown_fields=True):
    orders: list[Order]
    transcript: str = ""
    request_id: str = msgspec.field(default_factory=lambda: uuid.uuid4().hex)


class TextBody(msgspec.Struct, forbid_unknown_fields=True):
    text: str


class CancelBody(msgspec.Struct, forbid_unknown_fields=True):
    order_id: str


class ReorderBody(msgspec.Struct, forbid_unknown_fields=True):
    order_id: str
    position: int


class ApiError(Exception):
    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


class Panel:
    """One robot's panel backend: bus requests for the API, a fan-out for live events."""

    def __init__(self, bus: Bus, robot: str, token: str) -> None:
        self._bus = bus
        self._keys = RobotKeys(robot)
        self._token = token.encode()
        self._listeners: set[asyncio.Queue[bytes]] = set()
        self._parse_decode = json_decoder(ParseReply | Failed)
        self._supervisor_decode = json_decoder(SupervisorReply)
        self._encoder = msgspec.json.Encoder()

    def start(self) -> None:
        self._bus.subscribe(self._keys.state, json_decoder(StateUpdate), self._on_event)
        self._bus.subscribe(self._keys.proposal, json_decoder(Proposal), self._on_event)

    def _on_event(self, _key: str, message: StateUpdate | Proposal) -> None:
        frame = b"data: " + self._encoder.encode(message) + b"\n\n"
        for queue in self._listeners:
            if queue.qsize() < 100:  # a stalled browser loses old frames, not the server
                queue.put_nowait(frame)

    def app(self) -> Starlette:
        def api(
            handler: Callable[[Request], Awaitable[object]],
        ) -> Callable[[Request], Awaitable[Response]]:
            async def endpoint(request: Request) -> Response:
                try:
                    self._check_token(request)
                    result = await handler(request)
                except ApiError as exc:
                    return JSONResponse({"error": str(exc)}, status_code=exc.status)
                if isinstance(result, Response):
                    return result
                return Response(self._encoder.encode(result), media_type="application/json")

            return endpoint

        routes = [
            Route("/", self._index),
            Route("/static/{name}", self._static),
            Route("/api/health", self._health),
            Route("/api/parse", api(self._parse), methods=["POST"]),
            Route("/api/submit", api(self._submit), methods=["POST"]),
            Route("/api/say", api(self._say), methods=["POST"]),
            Route("/api/cancel", api(self._cancel), methods=["POST"]),
            Route("/api/cancel_all", api(self._cancel_all), methods=["POST"]),
            Route("/api/stop", api(self._stop), methods=["POST"]),
            Route("/api/reorder", api(self._reorder), methods=["POST"]),
            Route("/api/state", api(self._state)),
            Route("/api/history", api(self._history)),
            Route("/api/events", api(self._events)),
        ]
        return Starlette(routes=routes)

    # --- pages -------------------------------------------------------------------------------

    async def _index(self, _request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    async def _static(self, request: Request) -> Response:
        name = request.path_params["name"]
        path = STATIC / name
        if "/" in name or name.startswith(".") or not path.is_file():
            return JSONResponse({"error": f"no static file {name!r}"}, status_code=404)
        return FileResponse(path)

    async def _health(self, _request: Request) -> Response:
        return JSONResponse({"ok": True, "robot": self._keys.robot})

    # --- API -----------------------------------------------------------------------------------

    def _check_token(self, request: Request) -> None:
        header = request.headers.get("authorization", "")
        scheme, _, given = header.partition(" ")
        if scheme.lower() != "bearer" or not hmac.compare_digest(given.encode(), self._token):
            raise ApiError(401, "missing or wrong token (Authorization: Bearer <token>)")

    async def _body(self, request: Request, kind: type[msgspec.Struct]) -> msgspec.Struct:
        raw = await request.body()
        if len(raw) > MAX_BODY:
            raise ApiError(413, f"request body over {MAX_BODY} bytes")
        try:
            return msgspec.json.decode(raw, type=kind)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise ApiError(400, f"bad request body: {exc}") from exc

    async def _ask_converter(self, text: str) -> ParseReply:
        try:
            reply: ParseReply | Failed = await self._bus.request(
                ConverterKeys().parse, ParseRequest(text=text), self._parse_decode, BUS_TIMEOUT
            )
        except BusError as exc:
            raise ApiError(503, f"converter unavailable: {exc}") from exc
        if isinstance(reply, Failed):
            raise ApiError(400, reply.reason)
        return reply

    async def _ask_supervisor(self, request: Message) -> SupervisorReply:
        try:
            reply: SupervisorReply = await self._bus.request(
                self._keys.supervisor, request, self._supervisor_decode, BUS_TIMEOUT
            )
        except BusError as exc:
            raise ApiError(503, f"supervisor unavailable: {exc}") from exc
        if isinstance(reply, Failed):
            raise ApiError(409, reply.reason)
        return reply

    async def _parse(self, request: Request) -> object:
        body = await self._body(request, TextBody)
        assert isinstance(body, TextBody)
        return (await self._ask_converter(body.text)).result

    async def _submit(self, request: Request) -> object:
        body = await self._body(request, SubmitBody)
        assert isinstance(body, SubmitBody)
        if not body.orders:
            raise ApiError(400, "nothing to submit: 'orders' is empty")
        reply = await self._ask_supervisor(
            Submit(request_id=body.request_id, orders=body.orders, transcript=body.transcript)
        )
        assert isinstance(reply, Submitted)
        return {"order_ids": reply.order_ids}

    async def _say(self, request: Request) -> object:
        """Parse and submit in one go; what parsed is queued, errors come back beside it."""
        body = await self._body(request, TextBody)
        assert isinstance(body, TextBody)
        result = (await self._ask_converter(body.text)).result
        order_ids: list[str] = []
        if result.orders:
            reply = await self._ask_supervisor(
                Submit(request_id=uuid.uuid4().hex, orders=result.orders, transcript=body.text)
            )
            assert isinstance(reply, Submitted)
            order_ids = reply.order_ids
        return {"orders": result.orders, "errors": result.errors, "order_ids": order_ids}

    async def _cancel(self, request: Request) -> object:
        body = await self._body(request, CancelBody)
        assert isinstance(body, CancelBody)
        return await self._done(Cancel(order_id=body.order_id))

    async def _cancel_all(self, _request: Request) -> object:
        return await self._done(CancelAll())

    async def _stop(self, _request: Request) -> object:
        return await self._done(EmergencyStop())

    async def _done(self, request: Message) -> object:
        reply = await self._ask_supervisor(request)
        return {"detail": reply.detail if isinstance(reply, Done) else ""}

    async def _reorder(self, request: Request) -> object:
        body = await self._body(request, ReorderBody)
        assert isinstance(body, ReorderBody)
        return await self._done(Reorder(order_id=body.order_id, position=body.position))

    async def _history(self, request: Request) -> object:
        try:
            offset = int(request.query_params.get("offset", "0"))
            limit = int(request.query_params.get("limit", "50"))
        except ValueError as exc:
            raise ApiError(400, "offset and limit must be integers") from exc
        return await self._ask_supervisor(GetHistory(offset=offset, limit=limit))

    async def _state(self, _request: Request) -> object:
        reply = await self._ask_supervisor(GetState())
        assert isinstance(reply, StateReply)
        return reply.state

    async def _events(self, _request: Request) -> Response:
        queue: asyncio.Queue[bytes] = asyncio.Queue()
        self._listeners.add(queue)
        with contextlib.suppress(ApiError):
            first = await self._ask_supervisor(GetState())
            if isinstance(first, StateReply):
                queue.put_nowait(
                    b"data: " + self._encoder.encode(StateUpdate(state=first.state)) + b"\n\n"
                )

        async def stream() -> AsyncIterator[bytes]:
            try:
                while True:
                    try:
                        yield await asyncio.wait_for(queue.get(), timeout=15.0)
                    except TimeoutError:
                        yield b": keep-alive\n\n"
            finally:
                self._listeners.discard(queue)

        return StreamingResponse(stream(), media_type="text/event-stream")
