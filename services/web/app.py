"""The panel's HTTP API: speech and text in, orders out, every robot's live state back.

Every /api route but /api/health needs ``Authorization: Bearer <token>``: the panel drives
a machine. The live stream (/api/events) is server-sent events read with fetch, so the
token travels in a header and never in a URL that a log could keep; the microphone's
WebSocket (/api/audio, audio.py) sends it in its first message and must come from the
panel's own origin. Every route takes ``?robot=NAME`` (default: the one the service was
started for). A refused request changes nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import logging
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, TypeVar

import msgspec
from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.requests import ClientDisconnect, Request
from starlette.responses import FileResponse, JSONResponse, Response, StreamingResponse
from starlette.routing import Route, WebSocketRoute
from starlette.types import ASGIApp, Receive, Scope, Send
from starlette.types import Message as ASGIMessage
from starlette.websockets import WebSocket

from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.client import Refused, Unreachable, VoicectlClient
from voicectl.shared.edits import UndoEdit, edit_order
from voicectl.shared.errors import TtsError, VoicectlError
from voicectl.shared.keys import MAX_ROBOTS, RobotKeys, check_chunk
from voicectl.shared.messages import (
    Asked,
    Cancel,
    CancelAll,
    Done,
    GetHistory,
    GetState,
    Message,
    Order,
    ParseResult,
    Release,
    Reorder,
    Resume,
    StateReply,
    StateUpdate,
    SupervisorReply,
    Via,
)
from voicectl.shared.process import running
from voicectl.shared.tts import MAX_TEXT, Voice, load_voice, to_wav
from voicectl.shared.words import catalogue, from_header, known, languages, word

from .audio import AudioSocket
from .hub import END, Hub

_LOGGER = logging.getLogger(__name__)
STATIC = Path(__file__).parent / "static"
MAX_BODY = 64 * 1024
BUS_TIMEOUT = 5.0
KEEP_ALIVE = 15.0

S = TypeVar("S", bound=msgspec.Struct)


class SubmitBody(msgspec.Struct, forbid_unknown_fields=True):
    orders: list[Order]
    transcript: str = ""
    request_id: Annotated[str, msgspec.Meta(min_length=1, max_length=128)] = msgspec.field(
        default_factory=lambda: uuid.uuid4().hex
    )
    """One per batch a person means to send once: a retry with it queues nothing twice."""
    via: Via = Via.API
    """Who sends: the panel says `panel`; a script, nothing."""
    spoken: bool = False
    """The orders were said (into the panel's microphone), not typed."""


class AmendBody(msgspec.Struct, forbid_unknown_fields=True):
    order: Order
    change: Order


class TextBody(msgspec.Struct, forbid_unknown_fields=True):
    text: str
    language: Annotated[str, msgspec.Meta(pattern="^([a-z]{2,3})?$")] = ""
    """The language it is written in (the panel's); empty: the converter's default."""


class SpeechBody(msgspec.Struct, forbid_unknown_fields=True):
    text: Annotated[str, msgspec.Meta(min_length=1, max_length=MAX_TEXT)]
    """A short answer to say aloud ("stopped"), as the panel shows it."""
    language: Annotated[str, msgspec.Meta(pattern="^([a-z]{2,3})?$")] = ""
    """The language it is in (the panel's); empty: English."""


class CancelBody(msgspec.Struct, forbid_unknown_fields=True):
    order_id: str


class ReorderBody(msgspec.Struct, forbid_unknown_fields=True):
    order_id: str
    position: Annotated[int, msgspec.Meta(ge=0)]
    """0 is next; beyond the end means last (the answer says where it went)."""


class ApiError(VoicectlError):
    """A request refused with an HTTP status and a one-line reason."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class Access:
    """Who may drive the robots: the token, and the origins a browser may come from."""

    token: str
    origins: list[str] = field(default_factory=list)
    """Origins allowed besides the panel's own (scheme://host:port)."""

    def token_ok(self, given: str) -> bool:
        return hmac.compare_digest(given.encode(), self.token.encode())

    def check(self, request: Request) -> None:
        scheme, _, given = request.headers.get("authorization", "").partition(" ")
        if scheme.lower() != "bearer" or not self.token_ok(given):
            raise ApiError(401, "missing or wrong token (Authorization: Bearer <token>)")

    def origin_ok(self, websocket: WebSocket) -> bool:
        """A browser always sends Origin: it must be the panel's own, or listed. Clients
        that are not browsers send none and still need the token."""
        origin = websocket.headers.get("origin")
        if origin is None:
            return True
        scheme = "https" if websocket.url.scheme == "wss" else "http"
        own = f"{scheme}://{websocket.headers.get('host', '')}"
        return origin == own or origin in self.origins


def _who(request: Request, via: Via) -> str:
    """Who asked, as the history keeps it: the client's address."""
    client = request.client
    where = client.host if client is not None else "?"
    return f"panel at {where}" if via is Via.PANEL else where


def _one_line(exc: Exception) -> str:
    """An exception's text for a person: the first line, without a codec's byte dump."""
    if isinstance(exc, UnicodeDecodeError):
        return f"invalid UTF-8 at byte {exc.start} of a string"
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


@contextlib.contextmanager
def _as_api_errors() -> Iterator[None]:
    """A service's refusal or absence as the API's answer: the converter refuses a text
    (400), the supervisor a request (409); one that does not answer is unavailable (503)."""
    try:
        yield
    except Refused as exc:
        raise ApiError(400 if exc.service == "converter" else 409, exc.reason) from exc
    except Unreachable as exc:
        raise ApiError(503, f"{exc.service} unavailable: {exc}") from exc


class Panel:
    """The API's handlers; the bus and the hub arrive when the app starts. `voice` speaks
    the panel's answers (/api/speech); None turns that off."""

    def __init__(
        self, robot: str, access: Access, voice: Voice | None = None, max_robots: int = MAX_ROBOTS
    ) -> None:
        self.default_robot = robot
        self.max_robots = max_robots
        """Robots the hub follows at most besides `robot` (`--max-robots`)."""
        self.access = access
        self.voice = voice
        self._voices: dict[str, Voice] = {}
        """espeak-ng's own voice for each other language the panel speaks, made once."""
        self._bus: Bus | None = None
        self._client: VoicectlClient | None = None
        self.hub: Hub | None = None
        self._encoder = msgspec.json.Encoder()

    def attach(self, bus: Bus) -> Hub:
        """Serve from `bus`; the hub it gives is a service for the caller to run."""
        self._bus = bus
        self._client = VoicectlClient(bus, BUS_TIMEOUT)
        self.hub = Hub(bus, self.default_robot, self.max_robots)
        return self.hub

    def end_streams(self) -> None:
        """End the event streams: the server stops once its responses have ended."""
        if self.hub is not None:
            self.hub.end_streams()

    @property
    def bus(self) -> Bus:
        assert self._bus is not None, "the app has not started"
        return self._bus

    def routes(self) -> list[Route | WebSocketRoute]:
        def api(
            handler: Callable[[Request], Awaitable[object]],
        ) -> Callable[[Request], Awaitable[Response]]:
            async def endpoint(request: Request) -> Response:
                try:
                    self.access.check(request)
                    result = await handler(request)
                except ApiError as exc:
                    return JSONResponse({"error": str(exc)}, status_code=exc.status)
                if isinstance(result, Response):
                    return result
                return Response(self._encoder.encode(result), media_type="application/json")

            return endpoint

        audio = AudioSocket(lambda: self.bus, self.access.token_ok, self.access.origin_ok)
        return [
            Route("/", self._index),
            Route("/static/{name}", self._static),
            Route("/favicon.ico", self._favicon),
            Route("/words", self._words),
            Route("/api/health", self._health),
            Route("/api/robots", api(self._robots)),
            Route("/api/parse", api(self._parse), methods=["POST"]),
            Route("/api/submit", api(self._submit), methods=["POST"]),
            Route("/api/say", api(self._say), methods=["POST"]),
            Route("/api/cancel", api(self._cancel), methods=["POST"]),
            Route("/api/cancel_all", api(self._cancel_all), methods=["POST"]),
            Route("/api/stop", api(self._stop), methods=["POST"]),
            Route("/api/release", api(self._release), methods=["POST"]),
            Route("/api/resume", api(self._resume), methods=["POST"]),
            Route("/api/reorder", api(self._reorder), methods=["POST"]),
            Route("/api/undo", api(self._undo), methods=["POST"]),
            Route("/api/amend", api(self._amend), methods=["POST"]),
            Route("/api/speech", api(self._speech), methods=["POST"]),
            Route("/api/state", api(self._state)),
            Route("/api/history", api(self._history)),
            Route("/api/photo", api(self._photo)),
            Route("/api/events", api(self._events)),
            WebSocketRoute("/api/audio", audio.serve),
        ]

    # --- pages ---------------------------------------------------------------------------------

    async def _index(self, _request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    async def _favicon(self, _request: Request) -> Response:
        """The panel's icon, for browsers that ask before (or without) reading the page."""
        return FileResponse(STATIC / "icon.svg", media_type="image/svg+xml")

    async def _static(self, request: Request) -> Response:
        name = request.path_params["name"]
        missing = JSONResponse({"error": f"no static file {name[:80]!r}"}, status_code=404)
        if "/" in name or name.startswith(".") or len(name) > 64:
            return missing
        path = STATIC / name
        try:
            found = path.is_file()
        except OSError:
            found = False
        return FileResponse(path) if found else missing

    async def _words(self, request: Request) -> Response:
        """The panel's words in its language (shared/words.py): the one asked for
        (`?language=es`) when there is a catalogue for it, else the browser's
        (Accept-Language), else English; English fills whatever a catalogue lacks. Not
        secret: the login page needs them too."""
        asked = request.query_params.get("language", "")[:8]
        accept = request.headers.get("accept-language", "")
        language = known(asked) if asked else from_header(accept)
        return JSONResponse(
            {
                "language": language,
                "languages": [
                    {"code": code, "name": word(code, "language.name")} for code in languages()
                ],
                "words": catalogue(language),
            }
        )

    async def _health(self, _request: Request) -> Response:
        return JSONResponse({"ok": True, "robot": self.default_robot})

    # --- requests ------------------------------------------------------------------------------

    def _robot(self, request: Request) -> RobotKeys:
        name = request.query_params.get("robot", self.default_robot)
        try:
            return RobotKeys(check_chunk(name, "robot name"))
        except ValueError as exc:
            raise ApiError(400, str(exc)) from exc

    async def _body(self, request: Request, kind: type[S]) -> S:
        """The body decoded as `kind`, read no further than `MAX_BODY` bytes."""
        declared = request.headers.get("content-length", "")
        if declared.isdigit() and int(declared) > MAX_BODY:
            raise ApiError(413, f"request body over {MAX_BODY} bytes")
        raw = bytearray()
        try:
            async for chunk in request.stream():
                raw += chunk
                if len(raw) > MAX_BODY:
                    raise ApiError(413, f"request body over {MAX_BODY} bytes")
        except ClientDisconnect:
            raise ApiError(400, "the client left before sending its whole body") from None
        try:
            return msgspec.json.decode(bytes(raw), type=kind)
        except (msgspec.DecodeError, UnicodeDecodeError) as exc:
            # msgspec checks UTF-8 inside strings with Python's codec: UnicodeDecodeError.
            raise ApiError(400, f"bad request body: {_one_line(exc)}") from exc

    @property
    def client(self) -> VoicectlClient:
        assert self._client is not None, "the app has not started"
        return self._client

    async def _ask_converter(self, text: str, language: str = "") -> ParseResult:
        with _as_api_errors():
            return await self.client.parse(text, language)

    async def _ask_supervisor(self, keys: RobotKeys, request: Message) -> SupervisorReply:
        with _as_api_errors():
            return await self.client.ask(keys.robot, request)

    async def _robots(self, _request: Request) -> object:
        assert self.hub is not None
        return {"robots": self.hub.robots, "default": self.default_robot}

    async def _parse(self, request: Request) -> object:
        body = await self._body(request, TextBody)
        return await self._ask_converter(body.text, body.language)

    async def _submit(self, request: Request) -> object:
        """Orders queued, edits of the queue applied and questions answered, in order."""
        keys = self._robot(request)
        body = await self._body(request, SubmitBody)
        if not body.orders:
            raise ApiError(400, "nothing to submit: 'orders' is empty")
        asked = Asked(via=body.via, spoken=body.spoken, by=_who(request, body.via))
        with _as_api_errors():
            sent = await self.client.send(
                keys.robot, body.orders, body.transcript, asked, body.request_id
            )
        return {"order_ids": sent.order_ids, "answers": sent.answers}

    async def _undo(self, request: Request) -> object:
        """The last edit of the queue taken back, as "undo" said does."""
        keys = self._robot(request)
        undo = edit_order(UndoEdit(), "undo")
        asked = Asked(via=Via.PANEL, by=_who(request, Via.PANEL))
        with _as_api_errors():
            sent = await self.client.send(keys.robot, [undo], "undo", asked)
        (answered,) = sent.answers
        return {"answer": answered.answer, "changed": answered.changed}

    async def _amend(self, request: Request) -> object:
        """An order made again as a correction says ("no, three"): for an order a panel
        has staged and not sent."""
        body = await self._body(request, AmendBody)
        with _as_api_errors():
            return {"order": await self.client.amend(body.order, body.change)}

    async def _say(self, request: Request) -> object:
        """Parse and submit in one go, only when the whole text made orders."""
        keys = self._robot(request)
        body = await self._body(request, TextBody)
        asked = Asked(via=Via.API, by=_who(request, Via.API))
        with _as_api_errors():
            said = await self.client.say(keys.robot, body.text, asked=asked, language=body.language)
        result = said.result
        return {
            "orders": result.orders,
            "errors": result.errors,
            "order_ids": said.order_ids,
            "answers": said.answers,
        }

    async def _cancel(self, request: Request) -> object:
        keys = self._robot(request)
        body = await self._body(request, CancelBody)
        return await self._done(keys, Cancel(order_id=body.order_id))

    async def _cancel_all(self, request: Request) -> object:
        return await self._done(self._robot(request), CancelAll())

    async def _stop(self, request: Request) -> object:
        """Never a timeout: stopped through the supervisor, or from here when it does not
        answer; an error only when nothing at all could be stopped."""
        keys = self._robot(request)
        with _as_api_errors():
            stopped = await self.client.stop(keys.robot)
        return {"detail": stopped.detail, "confirmed": stopped.confirmed}

    async def _release(self, request: Request) -> object:
        return await self._done(self._robot(request), Release())

    async def _resume(self, request: Request) -> object:
        return await self._done(self._robot(request), Resume())

    async def _done(self, keys: RobotKeys, request: Message) -> object:
        reply = await self._ask_supervisor(keys, request)
        return {"detail": reply.detail if isinstance(reply, Done) else ""}

    async def _reorder(self, request: Request) -> object:
        keys = self._robot(request)
        body = await self._body(request, ReorderBody)
        return await self._done(keys, Reorder(order_id=body.order_id, position=body.position))

    async def _speech(self, request: Request) -> Response:
        """`text` spoken by the service's voice, as a WAV for the browser to play."""
        if self.voice is None:
            raise ApiError(404, "spoken answers are off (voicectl web --voice none)")
        body = await self._body(request, SpeechBody)
        try:
            # An engine is a child process per phrase: tens of milliseconds off the loop.
            voice = self._voice_for(body.language)
            speech = await asyncio.to_thread(voice.speak, body.text)
        except ValueError as exc:
            raise ApiError(400, str(exc)) from exc
        except TtsError as exc:
            raise ApiError(503, str(exc)) from exc
        return Response(to_wav(speech), media_type="audio/wav")

    def _voice_for(self, language: str) -> Voice:
        """The voice that says `language`: espeak-ng's voice for it (an English voice reads
        Spanish badly), the service's own for English or with another engine."""
        assert self.voice is not None
        if not language or language == "en" or self.voice.name != "espeak-ng":
            return self.voice
        if language not in self._voices:
            self._voices[language] = load_voice("espeak-ng", voice=language)
        return self._voices[language]

    async def _history(self, request: Request) -> object:
        keys = self._robot(request)
        try:
            offset = int(request.query_params.get("offset", "0"))
            limit = int(request.query_params.get("limit", "50"))
        except ValueError as exc:
            raise ApiError(400, "offset and limit must be integers") from exc
        if not (0 <= offset <= 10**9 and 1 <= limit <= 500):
            raise ApiError(400, "offset must be 0 or more, limit 1 to 500")
        return await self._ask_supervisor(keys, GetHistory(offset=offset, limit=limit))

    async def _photo(self, request: Request) -> Response:
        """The photo an order took, as the image file: a phone cannot open the robot's path."""
        keys = self._robot(request)
        order_id = request.query_params.get("order", "")
        if not order_id:
            raise ApiError(400, "which photo? give ?order=ORDER_ID")
        try:
            photo = await self.client.photo(keys.robot, order_id)
        except Refused as exc:
            raise ApiError(404, exc.reason) from exc
        except Unreachable as exc:
            raise ApiError(503, f"the robot's executor is unavailable: {exc}") from exc
        return Response(photo.data, media_type=photo.media_type)

    async def _state(self, request: Request) -> object:
        reply = await self._ask_supervisor(self._robot(request), GetState())
        assert isinstance(reply, StateReply)
        return reply.state

    async def _events(self, request: Request) -> Response:
        keys = self._robot(request)
        robot = keys.robot
        assert self.hub is not None
        hub = self.hub
        if not hub.knows_state(robot):
            with contextlib.suppress(ApiError):  # no supervisor yet: the state comes later
                reply = await self._ask_supervisor(keys, GetState())
                if isinstance(reply, StateReply):
                    hub.remember(robot, StateUpdate(state=reply.state))

        async def stream() -> AsyncIterator[bytes]:
            with hub.listen(robot) as queue:
                while True:
                    try:
                        async with asyncio.timeout(KEEP_ALIVE):
                            event = await queue.get()
                    except TimeoutError:
                        event = b": keep-alive\n\n"
                    if event == END:
                        return
                    yield event

        return StreamingResponse(stream(), media_type="text/event-stream")


SECURITY_HEADERS = [
    (
        b"content-security-policy",
        b"default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
        b"connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'none'; "
        b"frame-ancestors 'none'",
    ),
    (b"x-frame-options", b"DENY"),
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"no-referrer"),
]
"""On every HTTP response: the panel drives a robot, so no page of another site may frame
it (clickjacking a STOP or a Release), and it runs only its own scripts and styles. Its map
is a data: image; its audio worklet and requests come from its own origin."""


class SecurityHeaders:
    """ASGI middleware that adds `SECURITY_HEADERS` to every HTTP response, the event
    stream's too (a plain ASGI wrapper: it never buffers a streaming body)."""

    def __init__(self, app: ASGIApp) -> None:
        self._app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self._app(scope, receive, send)
            return

        async def with_headers(message: ASGIMessage) -> None:
            if message["type"] == "http.response.start":
                message = {**message, "headers": [*message.get("headers", []), *SECURITY_HEADERS]}
            await send(message)

        await self._app(scope, receive, with_headers)


def create_app(options: BusOptions, panel: Panel, bus: Bus | None = None) -> Starlette:
    """`panel` as an ASGI app. Its lifespan runs the hub as a service (`running`,
    shared/process.py) on the loop that serves it, whichever server that is (uvicorn in
    `voicectl web`, Starlette's TestClient in the tests), on `bus` when given (opened on
    that loop before the server starts: `voicectl web` does, so that a stop while it waits
    for the router ends it), else on a bus of its own that it opens and closes."""

    @contextlib.asynccontextmanager
    async def lifespan(_app: Starlette) -> AsyncIterator[None]:
        with contextlib.ExitStack() as owned:
            used = bus or owned.enter_context(Bus.open(options, asyncio.get_running_loop()))
            async with running(panel.attach(used)):
                yield

    return Starlette(
        routes=panel.routes(), lifespan=lifespan, middleware=[Middleware(SecurityHeaders)]
    )
