"""The one place that owns a Zenoh session and bridges it to asyncio.

Zenoh's Python API calls back on its own threads; a `Bus` turns those callbacks into calls
on one event loop, decodes payloads once at the edge (a message that does not decode is
dropped, and said in one line with its key at most every 10 s per subscription: anyone on
the bus can send thousands), and closes every declaration with the
session so that no callback thread keeps the process alive at exit.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import functools
import json
import logging
import os
import re
import signal
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Literal, TypeVar

import msgspec
import zenoh
import zenoh.ext

from .errors import BusError
from .messages import Failed, Message
from .throttle import Throttled

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")
Decode = Callable[[bytes], T]

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
CLIENT_TIMEOUT = 3.0
"""Seconds a command (voicectl state, stop...) waits for the router before it gives up."""
WAIT_WARNING = 10.0
"""Seconds between two warnings of a service still waiting for its router."""
OPEN_GRACE = 2.0
"""Seconds a stop signal waits for a session that is being opened, to close it."""
JSON = zenoh.Encoding.APPLICATION_JSON
CDR = zenoh.Encoding.APPLICATION_CDR


Mode = Literal["client", "peer", "router"]
MODES: tuple[Mode, ...] = ("client", "peer", "router")


@dataclass(frozen=True)
class BusOptions:
    """How a process joins the Zenoh network: a Zenoh configuration file if any, then
    the options here on top of it, then the `settings`, as Zenoh's own tools do."""

    connect: list[str] = field(default_factory=lambda: [DEFAULT_ROUTER])
    listen: list[str] = field(default_factory=list)
    mode: Mode | None = "client"
    """None: as the configuration file says."""
    lease_ms: int | None = None
    """Shorter leases notice a lost peer sooner (tests on cut links use ~2000)."""
    wait: bool = True
    """Wait for the router however long it takes (services); a command someone typed
    gives up after `CLIENT_TIMEOUT` seconds instead."""
    config_file: Path | None = None
    """A Zenoh JSON5 configuration: TLS, credentials, anything Zenoh has a key for."""
    settings: tuple[str, ...] = ()
    """'KEY:VALUE' pairs, VALUE in JSON5, set last (zenohd's --cfg)."""

    def zenoh_config(self) -> zenoh.Config:
        """The configuration; BusError naming the file or setting that is wrong."""
        if self.config_file is not None:
            try:
                conf = zenoh.Config.from_file(str(self.config_file))
            except zenoh.ZError as exc:
                raise BusError(f"--config {self.config_file}: {_zenoh_reason(exc)}") from None
        else:
            conf = zenoh.Config()
            # Endpoints are always explicit: nothing joins by multicast.
            conf.insert_json5("scouting/multicast/enabled", "false")
            # No shared-memory transport: with it every process lazily makes a 16 MB pool
            # for messages over 3 KB, and each process on the host maps the pools of those
            # it talks to. A router serving 20 simulated robots' processes held 371 MB of
            # them (10 MB a session, docs/benchmarks.md) against 57 MB without, for the
            # same latency; a container's /dev/shm is 64 MB. `--cfg
            # transport/shared_memory/enabled:true` or a config file brings it back.
            conf.insert_json5("transport/shared_memory/enabled", "false")
        if self.mode is not None:
            conf.insert_json5("mode", json.dumps(self.mode))
        # Publishers that keep their last value for late subscribers need timestamps.
        conf.insert_json5("timestamping/enabled", "true")
        if self.connect:
            conf.insert_json5("connect/endpoints", json.dumps(self.connect))
        if self.listen:
            conf.insert_json5("listen/endpoints", json.dumps(self.listen))
        if self.lease_ms is not None:
            conf.insert_json5("transport/link/tx/lease", str(self.lease_ms))
        if json.loads(conf.get_json("mode")) == "client":
            # A service waits for the router instead of failing when it is not up yet.
            timeout = -1 if self.wait else int(CLIENT_TIMEOUT * 1000)
            conf.insert_json5("connect/timeout_ms", str(timeout))
        for setting in self.settings:
            key, colon, value = setting.partition(":")
            if not colon or not key or not value:
                raise BusError(f"--cfg {setting!r}: expected KEY:VALUE, VALUE in JSON5")
            try:
                conf.insert_json5(key, value)
            except zenoh.ZError as exc:  # the value is not repeated: it may be a password
                raise BusError(f"--cfg {key}: {_zenoh_reason(exc)}") from None
        return conf

    @property
    def where(self) -> str:
        """The endpoints this process connects to (as the flags or the file say), for
        messages."""
        endpoints = self.connect
        if not endpoints and self.config_file is not None:
            with contextlib.suppress(zenoh.ZError, BusError, ValueError):
                found = json.loads(self.zenoh_config().get_json("connect/endpoints"))
                # Zenoh also takes a list per mode: {router: [...], peer: [...]}.
                per_mode = found.values() if isinstance(found, dict) else [found]
                endpoints = [endpoint for listed in per_mode for endpoint in listed]
        return ", ".join(endpoints) or "no endpoint"


def _zenoh_reason(exc: zenoh.ZError) -> str:
    """Zenoh's error in one line, without its source location or the offending text (a
    setting's value may be a password), a JSON5 position made readable."""
    text = str(exc).split(" at /", 1)[0].replace("\\n", "\n")
    located = re.search(
        r'msg: "(.*?)", location: Some\(Location \{ line: (\d+), column: (\d+)', text, re.DOTALL
    )
    if located:
        # A JSON5 syntax error draws the offending line; keep only its last line, "= why".
        why = located[1].rsplit("= ", 1)[-1].strip()
        return f"{why} (line {located[2]}, column {located[3]})"
    drawn = re.match(r"\s*--> (\d+):(\d+)\n.*= ([^\n]+)", text, re.DOTALL)
    if drawn:
        return f"{drawn[3].strip()} (line {drawn[1]}, column {drawn[2]})"
    quoted = re.fullmatch(r'Str\("(.*)"\)', text)
    return quoted[1] if quoted else text.splitlines()[0]


class Bus:
    """A Zenoh session whose callbacks land on one asyncio loop."""

    def __init__(
        self, session: zenoh.Session, loop: asyncio.AbstractEventLoop, secured: bool = False
    ) -> None:
        self._session = session
        self._loop = loop
        self._unanswered = "no service answered"
        if secured:
            # The router drops what its access control refuses without a word.
            self._unanswered += " (none is up, or the router's access control refuses this user)"
        self._closers = contextlib.ExitStack()
        self._encoder = msgspec.json.Encoder()
        self._running: set[asyncio.Task[tuple[bytes, zenoh.Encoding] | None]] = set()
        """Handler tasks in flight (the loop keeps only weak references to tasks)."""
        self._answering: set[asyncio.Task[Message]] = set()
        """The same, for `serve_in_turn`."""
        self._streams: set[Stream] = set()
        self._closers.callback(self._close_streams)
        self._noise = Throttled(_LOGGER)
        """Warnings of what does not decode, at most every 10 s per declaration."""

    @classmethod
    @contextlib.contextmanager
    def open(cls, options: BusOptions, loop: asyncio.AbstractEventLoop) -> Iterator[Bus]:
        """Open the session; raises BusError naming the endpoints when a command cannot
        reach the router, and SystemExit(0) on SIGINT/SIGTERM while a service waits."""
        session = _open_session(options)
        bus = cls(session, loop, secured=options.config_file is not None)
        try:
            yield bus
        finally:
            bus._closers.close()
            session.close()

    def at_close(self, func: Callable[[], object]) -> None:
        """Call `func()` when the bus closes, before its session does (what was opened on
        top of it: a robot transport's own node)."""
        self._closers.callback(func)

    def _close_streams(self) -> None:
        for stream in list(self._streams):
            stream.close()

    @property
    def session(self) -> zenoh.Session:
        return self._session

    def encode(self, message: Message) -> bytes:
        return self._encoder.encode(message)

    def call_soon(self, func: Callable[..., object], *args: Any) -> None:
        """Run `func(*args)` on the bus's loop, from any thread; nothing once it closes."""
        with contextlib.suppress(RuntimeError):  # the loop is closing; nothing to deliver to
            self._loop.call_soon_threadsafe(func, *args)

    # --- publish / subscribe -----------------------------------------------------------

    def publish(self, key: str, message: Message, superseded: bool = False) -> None:
        """Publish a voicectl message. Most are few and matter (an order's result), so
        they wait for room under congestion instead of Zenoh's default of dropping; a
        `superseded` one (a partial transcript, which the next one replaces) is dropped
        instead, so that it never stalls the loop."""
        self._session.put(
            key,
            self._encoder.encode(message),
            encoding=JSON,
            congestion_control=zenoh.CongestionControl.DROP
            if superseded
            else zenoh.CongestionControl.BLOCK,
        )

    def stream(self, key: str) -> Stream:
        """A publisher declared once for many messages on one key (an audio session);
        close it when done (the bus closes those still open)."""
        stream = Stream(self, key)
        self._streams.add(stream)
        return stream

    def latest(self, key: str) -> Latest:
        """A publisher on `key` that sends its last message again to every new subscriber
        (a status, a grammar): what a late starter needs without asking."""
        latest = Latest(self, key)
        self._closers.callback(latest.close)
        return latest

    def publish_bytes(
        self,
        key: str,
        payload: bytes,
        encoding: zenoh.Encoding = CDR,
        urgent: bool = False,
        attachment: bytes | None = None,
    ) -> None:
        """Publish raw bytes (CDR for ROS topics), with an `attachment` if given (what
        rmw_zenoh's subscribers require). An `urgent` one (zero velocity, a stop) waits for
        room instead of being dropped, and goes first and at once."""
        if urgent:
            self._session.put(
                key,
                payload,
                encoding=encoding,
                attachment=attachment,
                congestion_control=zenoh.CongestionControl.BLOCK,
                priority=zenoh.Priority.REAL_TIME,
                express=True,
            )
        else:
            self._session.put(key, payload, encoding=encoding, attachment=attachment)

    def subscribe(
        self,
        key: str,
        decode: Decode[T],
        handler: Callable[[str, T], None],
        on_loop: bool = True,
        history: bool = False,
    ) -> Callable[[], None]:
        """Call `handler(key, message)` on the loop for every sample that decodes, until
        the bus closes or the returned function ends the subscription.

        With `history`, also for the last message of every `latest` publisher on `key`,
        whenever either side starts. With `on_loop` False the handler runs on Zenoh's own
        thread, for a stream so dense (audio, 50 messages a second) that waking the loop
        for each message would cost more than the work: it must be quick and thread-safe.
        """

        def on_sample(sample: zenoh.Sample) -> None:
            sample_key = str(sample.key_expr)
            try:
                message = decode(sample.payload.to_bytes())
            except Exception as exc:  # any decoder's failure is the sender's fault: drop it
                self._noise.warning(key, "dropped undecodable message on %s: %s", sample_key, exc)
                return
            if on_loop:
                self.call_soon(handler, sample_key, message)
            else:
                handler(sample_key, message)

        if history:
            subscriber: Any = zenoh.ext.declare_advanced_subscriber(
                self._session,
                key,
                _direct(on_sample),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
            )
        else:
            subscriber = self._session.declare_subscriber(key, _direct(on_sample))
        return self._undeclare_once(subscriber)

    def _undeclare_once(self, declared: Any) -> Callable[[], None]:
        """A function that undeclares `declared` once, now or when the bus closes."""
        live = True

        def undeclare() -> None:
            nonlocal live
            if live:
                live = False
                declared.undeclare()

        self._closers.callback(undeclare)
        return undeclare

    # --- request / reply ----------------------------------------------------------------

    async def request_bytes(
        self,
        key: str,
        payload: bytes,
        timeout: float,
        urgent: bool = False,
        attachment: bytes | None = None,
        complete: bool = False,
    ) -> bytes:
        """Send one query (with an `attachment` if given) and return the first good reply's
        payload. An `urgent` one (a stop, a cancel) waits for room instead of being
        dropped, and goes first. A `complete` one is asked only of queryables declared
        complete, one reply per key (rmw_zenoh's clients ask so)."""
        future: asyncio.Future[bytes] = self._loop.create_future()

        def settle(result: bytes | BaseException) -> None:
            if future.done():
                return
            if isinstance(result, BaseException):
                future.set_exception(result)
            else:
                future.set_result(result)

        answered = False  # touched on Zenoh's thread only

        def on_reply(reply: zenoh.Reply) -> None:
            nonlocal answered
            if answered:
                return
            answered = True
            if reply.ok is not None:
                self.call_soon(settle, reply.ok.payload.to_bytes())
            elif reply.err is not None:
                text = reply.err.payload.to_string()
                self.call_soon(settle, BusError(f"{key}: {text}"))

        def on_done() -> None:
            if not answered:  # one loop wake-up per request, not two
                self.call_soon(settle, BusError(f"{key}: {self._unanswered}"))

        qos: dict[str, Any] = {}
        if urgent:
            qos = {
                "congestion_control": zenoh.CongestionControl.BLOCK,
                "priority": zenoh.Priority.REAL_TIME,
                "express": True,
            }
        if complete:
            qos.update(_COMPLETE)
        try:
            self._session.get(
                key,
                zenoh.handlers.Callback(on_reply, on_done, indirect=False),
                payload=payload,
                attachment=attachment,
                timeout=timeout,
                **qos,
            )
        except zenoh.ZError as exc:  # the session is closing: no one can answer now
            future.cancel()  # on_done's late "no answer" is dropped, not left unretrieved
            raise BusError(f"{key}: {_zenoh_reason(exc)}") from None
        return await future

    def query_and_forget(
        self,
        key: str,
        payload: bytes,
        timeout: float,
        attachment: bytes | None = None,
        complete: bool = False,
    ) -> None:
        """Send an urgent query whose answer nobody waits for, from any thread: a cancel
        sent by a thread whose event loop cannot wait for it (the executor's watchdog)."""
        self._session.get(
            key,
            _direct(_ignore_reply),
            payload=payload,
            attachment=attachment,
            timeout=timeout,
            congestion_control=zenoh.CongestionControl.BLOCK,
            priority=zenoh.Priority.REAL_TIME,
            express=True,
            **(_COMPLETE if complete else {}),
        )

    def keeping(self, key: str, depth: int = 1) -> Kept:
        """A publisher of raw bytes (CDR) on `key` that keeps its last `depth` samples for
        subscribers that come later, and asks them (ROS's transient local, as rmw_zenoh
        publishes it: an action's status)."""
        kept = Kept(self, key, depth)
        self._closers.callback(kept.close)
        return kept

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

        async def respond(query_key: str, raw: bytes) -> tuple[bytes, zenoh.Encoding]:
            try:
                request = decode(raw)
            except Exception as exc:
                self._noise.warning(key, "rejected undecodable request on %s: %s", query_key, exc)
                answer: Message = Failed(reason=f"undecodable request: {exc}")
            else:
                try:
                    answer = await handler(query_key, request)
                except Exception as exc:
                    _LOGGER.exception("handler for %s failed", key)
                    answer = Failed(reason=f"internal error: {exc}")
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
                _LOGGER.exception("handler for %s failed", key)
                for pending in batch:
                    pending.answer(Failed(reason=f"internal error: {exc}"))

        async def in_turn(pending: Pending[T]) -> Message:
            nonlocal held
            held = False
            self._loop.call_soon(look)  # runs after the handler's first step, just below
            return await answer(pending)

        async def answer(pending: Pending[T]) -> Message:
            try:
                return await handler(pending.key, pending.request)
            except Exception as exc:
                _LOGGER.exception("handler for %s failed", key)
                return Failed(reason=f"internal error: {exc}")

        def start(pending: Pending[T], answering: Awaitable[Message]) -> None:
            task = self._loop.create_task(_awaitable(answering))
            self._answering.add(task)
            task.add_done_callback(functools.partial(self._answer_with, pending))

        def overtake(pending: Pending[T]) -> None:
            start(pending, answer(pending))

        def on_query(query: zenoh.Query) -> None:  # on Zenoh's thread
            nonlocal scheduled
            query_key = str(query.key_expr)
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                request = decode(raw)
            except Exception as exc:
                self._noise.warning(key, "rejected undecodable request on %s: %s", query_key, exc)
                refused: Pending[None] = Pending(query, query_key, None, self._encoder)
                refused.answer(Failed(reason=f"undecodable request: {exc}"))
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

        queryable = self._session.declare_queryable(key, _direct(on_query))
        self._closers.callback(queryable.undeclare)

    def _answer_with(self, pending: Pending[Any], done: asyncio.Task[Message]) -> None:
        self._answering.discard(done)
        if done.cancelled():
            pending.drop()
        else:
            pending.answer(done.result())

    def serve_now(self, key: str, decode: Decode[T], handler: Callable[[T], Message]) -> None:
        """Answer queries on `key` on Zenoh's own thread, never waiting for the loop: for
        the one request that must be answered however busy or blocked the loop is (an
        emergency stop). `handler` must be quick and thread-safe."""

        def on_query(query: zenoh.Query) -> None:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                answer: Message = handler(decode(raw))
            except (msgspec.DecodeError, ValueError) as exc:
                self._noise.warning(key, "rejected undecodable request on %s: %s", key, exc)
                answer = Failed(reason=f"undecodable request: {exc}")
            except Exception as exc:
                _LOGGER.exception("handler for %s failed", key)
                answer = Failed(reason=f"internal error: {exc}")
            try:
                query.reply(query.key_expr, self._encoder.encode(answer), encoding=JSON)
            finally:
                query.drop()

        queryable = self._session.declare_queryable(key, _direct(on_query))
        self._closers.callback(queryable.undeclare)

    def serve_bytes(
        self,
        key: str,
        handler: Callable[[bytes], Awaitable[bytes | None]],
        complete: bool = False,
        reply_attachment: Callable[[bytes | None], bytes | None] | None = None,
    ) -> None:
        """Answer queries whose payloads are raw bytes (CDR), for ROS-side services; a
        handler that raises is answered with a Zenoh error reply, one that returns None is
        not answered at all (the query ends with no reply, as when a route is lost).

        A `complete` queryable answers for the whole key (rmw_zenoh's clients ask only
        those); `reply_attachment` makes each reply's attachment from its query's."""

        async def respond(_query_key: str, raw: bytes) -> tuple[bytes, zenoh.Encoding] | None:
            answer = await handler(raw)
            return None if answer is None else (answer, CDR)

        self._answer_queries(key, respond, complete, reply_attachment)

    def _answer_queries(
        self,
        key: str,
        respond: Callable[[str, bytes], Awaitable[tuple[bytes, zenoh.Encoding] | None]],
        complete: bool = False,
        reply_attachment: Callable[[bytes | None], bytes | None] | None = None,
    ) -> None:
        """Declare a queryable on `key` whose answers `respond(query_key, payload)` makes,
        run as a task on the loop; the reply leaves from the loop when the task ends."""

        def reply(
            query: zenoh.Query, done: asyncio.Task[tuple[bytes, zenoh.Encoding] | None]
        ) -> None:
            self._running.discard(done)
            try:
                if done.cancelled():
                    return
                error = done.exception()
                if error is None:
                    answer = done.result()
                    if answer is not None:
                        attachment = None
                        if reply_attachment is not None:
                            asked = query.attachment
                            attachment = reply_attachment(
                                asked.to_bytes() if asked is not None else None
                            )
                        query.reply(
                            query.key_expr, answer[0], encoding=answer[1], attachment=attachment
                        )
                else:
                    _LOGGER.warning("query on %s failed: %s", key, error)
                    query.reply_err(str(error))
            finally:
                query.drop()

        def start(query: zenoh.Query, query_key: str, raw: bytes) -> None:
            task = self._loop.create_task(_awaitable(respond(query_key, raw)))
            self._running.add(task)
            task.add_done_callback(lambda done: reply(query, done))

        def on_query(query: zenoh.Query) -> None:  # on Zenoh's thread: hand over at once
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                self._loop.call_soon_threadsafe(start, query, str(query.key_expr), raw)
            except RuntimeError:  # loop closed: the process is stopping
                query.drop()

        queryable = self._session.declare_queryable(key, _direct(on_query), complete=complete)
        self._closers.callback(queryable.undeclare)

    # --- liveliness ------------------------------------------------------------------------

    def announce(self, key: str) -> Callable[[], None]:
        """Hold a liveliness token on `key` until the bus closes, or until the returned
        function withdraws it (a service going away says so before it stops serving)."""
        return self._undeclare_once(self._session.liveliness().declare_token(key))

    def watch(self, key: str, handler: Callable[[str, bool], None]) -> Callable[[], None]:
        """Call `handler(token_key, alive)` on the loop as tokens under `key` come and go,
        until the bus closes or the returned function ends the watch."""

        def on_sample(sample: zenoh.Sample) -> None:
            alive = sample.kind == zenoh.SampleKind.PUT
            self.call_soon(handler, str(sample.key_expr), alive)

        subscriber = self._session.liveliness().declare_subscriber(
            key, _direct(on_sample), history=True
        )
        return self._undeclare_once(subscriber)

    def watch_heard(self, key: str, handler: Callable[[bool], None]) -> Callable[[], None]:
        """Call `handler(heard)` on the loop as someone starts and stops subscribing to
        `key` (a relay that works only while it is listened to), and now; until the bus
        closes or the returned function ends the watch."""
        publisher = self._session.declare_publisher(key)

        def on_status(status: zenoh.MatchingStatus) -> None:
            self.call_soon(handler, status.matching)

        stop_publishing = self._undeclare_once(publisher)
        listener = publisher.declare_matching_listener(_direct(on_status))
        stop_listening = self._undeclare_once(listener)  # closed first: it lives in the publisher
        now: Any = publisher.matching_status
        self.call_soon(handler, now.matching)

        def stop() -> None:
            stop_listening()
            stop_publishing()

        return stop

    def watch_served(self, key: str, handler: Callable[[bool], None]) -> Callable[[], None]:
        """Call `handler(served)` on the loop as a service answering queries on `key`
        becomes reachable through the router, and as it goes, until the bus closes or the
        returned function ends the watch. A token says a process is up; this says its
        queries would arrive: after a link comes back the two are declared apart, and a
        query sent between them reaches nobody."""
        querier = self._session.declare_querier(key)

        def on_status(status: zenoh.MatchingStatus) -> None:
            self.call_soon(handler, status.matching)

        stop_querying = self._undeclare_once(querier)
        listener = querier.declare_matching_listener(_direct(on_status))
        stop_listening = self._undeclare_once(listener)  # closed first: it lives in the querier
        now: Any = querier.matching_status  # a MatchingStatus, whatever the stubs say
        self.call_soon(handler, now.matching)

        def stop() -> None:
            stop_listening()
            stop_querying()

        return stop


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

    def __init__(self, bus: Bus, key: str) -> None:
        self._bus = bus
        self._publisher = bus.session.declare_publisher(
            key, encoding=JSON, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._closed = False
        self._lock = threading.Lock()
        """A put and the undeclare never overlap: a sender's thread and the bus closing
        may reach them at once, and Zenoh refuses that ("Already borrowed")."""

    def send(self, message: Message) -> None:
        with self._lock:
            if not self._closed:
                self._publisher.put(self._bus.encode(message))

    async def matched(self, timeout: float) -> bool:
        """Whether a subscriber is there, waiting up to `timeout` seconds for one."""
        deadline = asyncio.get_running_loop().time() + timeout
        # The stubs say bool; zenoh 1.10 returns a MatchingStatus with `matching`.
        while not getattr(self._publisher.matching_status, "matching", False):
            if asyncio.get_running_loop().time() > deadline:
                return False
            await asyncio.sleep(0.02)
        return True

    def close(self) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._publisher.undeclare()
        self._bus._streams.discard(self)


class Kept:
    """Raw bytes published on one key, the last `depth` kept by Zenoh's advanced publisher
    for subscribers that come later (`Bus.keeping`)."""

    def __init__(self, bus: Bus, key: str, depth: int) -> None:
        self._publisher = zenoh.ext.declare_advanced_publisher(
            bus.session,
            key,
            encoding=CDR,
            congestion_control=zenoh.CongestionControl.BLOCK,
            cache=zenoh.ext.CacheConfig(max_samples=depth),
            publisher_detection=True,
        )
        self._closed = False

    def put(self, payload: bytes, attachment: bytes | None = None) -> None:
        if not self._closed:
            self._publisher.put(payload, attachment=attachment)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._publisher.undeclare()


class Latest:
    """Publishes on one key and keeps the last message for subscribers that come later.

    Zenoh's advanced publisher does it: it caches the last sample and announces itself, and
    a subscriber declared with `history` asks every such publisher for its cache, whether
    it starts before or after the publisher. These rare messages (a status, a grammar of
    some 100 kB) block for room under congestion rather than being dropped.
    """

    def __init__(self, bus: Bus, key: str) -> None:
        self._bus = bus
        self._publisher = zenoh.ext.declare_advanced_publisher(
            bus.session,
            key,
            encoding=JSON,
            congestion_control=zenoh.CongestionControl.BLOCK,
            cache=zenoh.ext.CacheConfig(max_samples=1),
            publisher_detection=True,
        )
        self._closed = False

    def publish(self, message: Message) -> None:
        if not self._closed:
            self._publisher.put(self._bus.encode(message))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._publisher.undeclare()


def _open_session(options: BusOptions) -> zenoh.Session:
    """zenoh.open on a thread of its own: waiting for a router blocks inside Zenoh, where
    no signal handler runs, so the main thread waits for it and stays interruptible."""
    opened: list[zenoh.Session] = []
    failed: list[BaseException] = []

    def open_it() -> None:
        try:
            opened.append(zenoh.open(options.zenoh_config()))
        except BaseException as exc:  # handed to the caller below
            failed.append(exc)

    def stop(signum: int, _frame: object) -> None:
        _LOGGER.info("stopped (%s) while waiting for the router", signal.Signals(signum).name)
        opener.join(OPEN_GRACE)  # it may be about to return: then close what it opened
        if opener.is_alive():
            # Still inside Zenoh: the interpreter's shutdown would end that thread by
            # unwinding it through Zenoh's Rust frames, which aborts the process. Nothing
            # of this process has started yet; end it here, its logs flushed.
            logging.shutdown()
            os._exit(0)
        for session in opened:
            session.close()
        raise SystemExit(0)

    opener = threading.Thread(target=open_it, name="zenoh-open", daemon=True)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        opener.start()
        started = time.monotonic()
        warn_at = started + WAIT_WARNING
        while opener.is_alive():
            opener.join(0.1)
            if opener.is_alive() and time.monotonic() >= warn_at:
                warn_at += WAIT_WARNING
                # A router that refuses us (TLS, credentials) looks exactly like one not up.
                _LOGGER.warning(
                    "still waiting for the router at %s after %.0f s: is it up, and do its "
                    "TLS certificates and credentials match this process's --config?",
                    options.where,
                    time.monotonic() - started,
                )
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if failed:
        if isinstance(failed[0], BusError):
            raise failed[0]
        why = str(failed[0]).split(" at /", 1)[0]  # Zenoh appends its source file
        if not options.wait:
            why = f"waited {CLIENT_TIMEOUT:g} s; is voicectl up or voicectl router running"
            if options.config_file is not None:
                why += ", and do its TLS certificates and credentials match --config"
            why += "?"
        raise BusError(f"cannot reach the router at {options.where} ({why})") from failed[0]
    return opened[0]


_COMPLETE: dict[str, Any] = {
    "target": zenoh.QueryTarget.ALL_COMPLETE,
    "consolidation": zenoh.ConsolidationMode.LATEST,
}
"""How rmw_zenoh's clients ask: only complete queryables, one reply per key."""


def _direct(callback: Callable[[T], None]) -> zenoh.handlers.Callback[T]:
    """Run `callback` on Zenoh's own thread: every callback here only decodes and hands
    over to the loop, so skipping the hop to a Python thread halves a round trip's cost."""
    return zenoh.handlers.Callback(callback, indirect=False)


def _ignore_reply(_reply: zenoh.Reply) -> None:
    pass


async def _awaitable(awaitable: Awaitable[T]) -> T:
    return await awaitable


def json_decoder(kind: Any) -> Decode[Any]:
    """A typed JSON decoder for `kind`, to be built once per subscription."""
    return msgspec.json.Decoder(kind).decode
