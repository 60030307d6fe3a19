"""voicectl's messages on the bus: typed publish/subscribe and request/reply.

A `Bus` is a `Wire` (wire.py: the Zenoh session bridged to asyncio, in bytes) that also
speaks voicectl's msgspec messages: it encodes each once with one encoder, decodes replies
with the decoder a caller built once (`json_decoder`), and answers a request that does not
decode, or whose handler fails, with `Failed` instead of leaving its asker to time out.
`BusOptions`, its defaults and `Decode` are wire.py's, importable from here as ever.
"""

from __future__ import annotations

import asyncio
import collections
import functools
import logging
from collections.abc import Awaitable, Callable
from typing import Any, Generic, TypeVar

import msgspec
import zenoh

from .errors import BusError
from .messages import Failed, Message
from .throttle import Throttled
from .wire import DEFAULT_ROUTER as DEFAULT_ROUTER
from .wire import JSON, Answer, Kept, Publisher, Wire
from .wire import MODES as MODES
from .wire import BusOptions as BusOptions
from .wire import Decode as Decode

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")


class Bus(Wire):
    """A Zenoh session whose callbacks land on one asyncio loop, speaking voicectl's
    messages."""

    def __init__(
        self, session: zenoh.Session, loop: asyncio.AbstractEventLoop, secured: bool = False
    ) -> None:
        super().__init__(session, loop, secured)
        self._encoder = msgspec.json.Encoder()
        self._refused = Throttled(_LOGGER)
        """Warnings of requests that do not decode, at most every 10 s per queryable."""

    def encode(self, message: Message) -> bytes:
        return self._encoder.encode(message)

    # --- publish / subscribe -----------------------------------------------------------

    def publish(self, key: str, message: Message, superseded: bool = False) -> None:
        """Publish a voicectl message. Most are few and matter (an order's result), so
        they wait for room under congestion instead of Zenoh's default of dropping; a
        `superseded` one (a partial transcript, which the next one replaces) is dropped
        instead, so that it never stalls the loop."""
        self.publish_bytes(key, self._encoder.encode(message), JSON, waits=not superseded)

    def stream(self, key: str) -> Stream:
        """A publisher declared once for many messages on one key (an audio session);
        close it when done (the bus closes those still open)."""
        return Stream(self.publisher(key, JSON), self._encoder)

    def latest(self, key: str) -> Latest:
        """A publisher on `key` that sends its last message again to every new subscriber
        (a status, a grammar): what a late starter needs without asking."""
        return Latest(self.keeping(key, 1, JSON), self._encoder)

    # --- request / reply ----------------------------------------------------------------

    async def request(
        self,
        key: str,
        message: Message,
        decode: Decode[T],
        timeout: float = 5.0,
        urgent: bool = False,
    ) -> T:
        """Send `message` as a query on `key` and decode the reply."""
        payload = await self.request_bytes(key, self._encoder.encode(message), timeout, urgent)
        try:
            return decode(payload)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise BusError(f"{key}: reply does not decode: {exc}") from exc

    def serve(
        self,
        key: str,
        decode: Decode[T],
        handler: Callable[[T], Awaitable[Message]],
    ) -> None:
        """Answer queries on `key` with `handler(request)`, run on the loop."""

        async def keyless(_key: str, request: T) -> Message:
            return await handler(request)

        self.serve_keyed(key, decode, keyless)

    def serve_keyed(
        self,
        key: str,
        decode: Decode[T],
        handler: Callable[[str, T], Awaitable[Message]],
    ) -> None:
        """Like `serve`, for a key expression with wildcards: the handler also gets the
        query's key (``voice/r1/...`` for a queryable on ``voice/*/...``). A request that
        does not decode, or a handler that raises, is answered with `Failed`."""

        async def respond(query_key: str, raw: bytes) -> Answer:
            try:
                request = decode(raw)
            except Exception as exc:
                answer: Message = self._refuse(key, query_key, exc)
            else:
                try:
                    answer = await handler(query_key, request)
                except Exception as exc:
                    answer = _failed(key, exc)
            return self._encoder.encode(answer), JSON

        self._answer_queries(key, respond)

    def serve_in_turn(
        self,
        key: str,
        decode: Decode[T],
        handler: Callable[[str, T], Awaitable[Message]],
        batched: Callable[[T], bool],
        take: Callable[[list[Pending[T]]], None],
        overtakes: Callable[[T], bool],
    ) -> None:
        """Like `serve_keyed`, for a burst of small requests: one wake-up of the loop for
        every query that arrived since it last looked, not one each.

        Requests are decoded on Zenoh's thread and handled in arrival order: a run of those
        `batched` goes to `take(batch)` in one call, which must answer each `Pending`,
        then or later, from any thread; any other goes to `handler` as `serve_keyed` would,
        and the requests after it wait until it has started. One that `overtakes` (an
        emergency stop) waits for none: it goes to `handler` at once. A request that does
        not decode is answered with `Failed` on Zenoh's thread.
        """
        arrived: collections.deque[Pending[T]] = collections.deque()
        scheduled = False
        """A `look` is due on the loop and has not started: what arrives now, it takes."""
        held = False
        """A request's handler was started and has not run its first step yet."""

        def look() -> None:  # on the loop
            nonlocal scheduled, held
            scheduled = False
            if held:
                return  # `in_turn` looks again once the held request has started
            batch: list[Pending[T]] = []
            while arrived:
                pending = arrived.popleft()
                if batched(pending.request):
                    batch.append(pending)
                    continue
                if batch:
                    give(batch)
                held = True
                start(pending, in_turn(pending))
                return
            if batch:
                give(batch)

        def give(batch: list[Pending[T]]) -> None:
            try:
                take(batch)
            except Exception as exc:
                failed = _failed(key, exc)
                for pending in batch:
                    pending.answer(failed)

        async def in_turn(pending: Pending[T]) -> Message:
            nonlocal held
            held = False
            self._loop.call_soon(look)  # runs after the handler's first step, just below
            return await answer(pending)

        async def answer(pending: Pending[T]) -> Message:
            try:
                return await handler(pending.key, pending.request)
            except Exception as exc:
                return _failed(key, exc)

        def start(pending: Pending[T], answering: Awaitable[Message]) -> None:
            self._spawn(answering, functools.partial(_answer_with, pending))

        def overtake(pending: Pending[T]) -> None:
            start(pending, answer(pending))

        def on_query(query: zenoh.Query) -> None:  # on Zenoh's thread
            nonlocal scheduled
            query_key = str(query.key_expr)
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                request = decode(raw)
            except Exception as exc:
                refused: Pending[None] = Pending(query, query_key, None, self._encoder)
                refused.answer(self._refuse(key, query_key, exc))
                return
            pending = Pending(query, query_key, request, self._encoder)
            try:
                if overtakes(request):
                    self._loop.call_soon_threadsafe(overtake, pending)
                    return
                arrived.append(pending)
                # A `look` that is due takes this one too; only the first of a burst wakes
                # the loop. Under the GIL the worst race is a second `look`, finding nothing.
                if not scheduled:
                    scheduled = True
                    self._loop.call_soon_threadsafe(look)
            except RuntimeError:  # loop closed: the process is stopping
                pending.drop()

        self.queryable(key, on_query)

    def serve_now(self, key: str, decode: Decode[T], handler: Callable[[T], Message]) -> None:
        """Answer queries on `key` on Zenoh's own thread, never waiting for the loop: for
        the one request that must be answered however busy or blocked the loop is (an
        emergency stop). `handler` must be quick and thread-safe."""

        def on_query(query: zenoh.Query) -> None:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                answer: Message = handler(decode(raw))
            except (msgspec.DecodeError, ValueError) as exc:
                answer = self._refuse(key, key, exc)
            except Exception as exc:
                answer = _failed(key, exc)
            try:
                query.reply(query.key_expr, self._encoder.encode(answer), encoding=JSON)
            finally:
                query.drop()

        self.queryable(key, on_query)

    def _refuse(self, key: str, query_key: str, exc: Exception) -> Failed:
        """The answer to a request on `query_key` (asked of the queryable on `key`) that
        does not decode."""
        self._refused.warning(key, "rejected undecodable request on %s: %s", query_key, exc)
        return Failed(reason=f"undecodable request: {exc}")


def _failed(key: str, exc: Exception) -> Failed:
    """The answer of a handler for `key` that raised `exc` (logged with its traceback)."""
    _LOGGER.exception("handler for %s failed", key)
    return Failed(reason=f"internal error: {exc}")


def _answer_with(pending: Pending[Any], done: asyncio.Task[Message]) -> None:
    if done.cancelled():
        pending.drop()
    else:
        pending.answer(done.result())


class Pending(Generic[T]):
    """A request taken on Zenoh's thread, answered once, then or later, from any thread."""

    __slots__ = ("_encoder", "_query", "key", "request")

    def __init__(
        self, query: zenoh.Query, key: str, request: T, encoder: msgspec.json.Encoder
    ) -> None:
        self.key = key
        """The query's key (``voice/r1/supervisor`` for a queryable on ``voice/*/...``)."""
        self.request = request
        self._query: zenoh.Query | None = query
        self._encoder = encoder

    def answer(self, message: Message) -> None:
        """Reply with `message`, and end the query; any later answer is ignored."""
        query, self._query = self._query, None
        if query is None:
            return
        try:
            query.reply(query.key_expr, self._encoder.encode(message), encoding=JSON)
        except zenoh.ZError as exc:  # the session is closing: nobody can hear it
            _LOGGER.debug("could not answer on %s: %s", self.key, exc)
        finally:
            query.drop()

    def drop(self) -> None:
        """End the query without a reply (the asker hears that no one answered)."""
        query, self._query = self._query, None
        if query is not None:
            query.drop()


class Stream:
    """Many messages on one key through one declared publisher, in order and reliably.

    `matched()` waits until a subscriber is known: what is published before that can be
    lost, so a sender that starts a session waits for it first.
    """

    def __init__(self, publisher: Publisher, encoder: msgspec.json.Encoder) -> None:
        self._publisher = publisher
        self._encoder = encoder

    def send(self, message: Message) -> None:
        """Send `message`, from any thread; nothing once the stream is closed."""
        self._publisher.put(self._encoder.encode(message))

    async def matched(self, timeout: float) -> bool:
        """Whether a subscriber is there, waiting up to `timeout` seconds for one."""
        return await self._publisher.matched(timeout)

    def close(self) -> None:
        self._publisher.close()


class Latest:
    """Publishes messages on one key and keeps the last for subscribers that come later,
    whether they start before or after it (`Kept`, of depth 1)."""

    def __init__(self, kept: Kept, encoder: msgspec.json.Encoder) -> None:
        self._kept = kept
        self._encoder = encoder

    def publish(self, message: Message) -> None:
        self._kept.put(self._encoder.encode(message))

    def close(self) -> None:
        self._kept.close()


def json_decoder(kind: Any) -> Decode[Any]:
    """A typed JSON decoder for `kind`, to be built once per subscription."""
    return msgspec.json.Decoder(kind).decode
