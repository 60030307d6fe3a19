"""The one place that owns a Zenoh session and bridges it to asyncio, in bytes.

Zenoh's Python API calls back on its own threads; a `Wire` turns those callbacks into calls
on one event loop, decodes payloads once at the edge with the decoder each subscription
brings (a payload that does not decode is dropped, and said in one line with its key at
most every 10 s per subscription: anyone on the bus can send thousands), and closes every
declaration with the session so that no callback thread keeps the process alive at exit.

It knows no message type: `bus.py` speaks voicectl's messages on top of it, and the robot
transports (shared/robot/) speak CDR through it.
"""

from __future__ import annotations

import asyncio
import contextlib
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
from typing import Any, Literal, Self, TypeVar

import zenoh
import zenoh.ext

from .errors import BusError
from .hints import voicectl_command
from .throttle import Throttled

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")
Decode = Callable[[bytes], T]
Answer = tuple[bytes, zenoh.Encoding]
"""A reply's payload and its encoding."""

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
CLIENT_TIMEOUT = 3.0
"""Seconds a command (voicectl state, stop...) waits for the router before it gives up."""
WAIT_WARNING = 10.0
"""Seconds between two warnings of a service still waiting for its router."""
OPEN_GRACE = 2.0
"""Seconds a stop signal waits for a session that is being opened, to close it."""
MATCHING_RECHECK = 1.0
"""Seconds between two reads of a watched matching status (`Wire._watch_matching`)."""
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


class Wire:
    """A Zenoh session whose callbacks land on one asyncio loop, for payloads of bytes."""

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
        self._running: set[asyncio.Task[Any]] = set()
        """Tasks in flight (the loop keeps only weak references to tasks)."""
        self._publishers: set[Publisher] = set()
        self._closers.callback(self._close_publishers)
        self._noise = Throttled(_LOGGER)
        """Warnings of what does not decode, at most every 10 s per declaration."""

    @classmethod
    @contextlib.contextmanager
    def open(cls, options: BusOptions, loop: asyncio.AbstractEventLoop) -> Iterator[Self]:
        """Open the session; raises BusError naming the endpoints when a command cannot
        reach the router, and SystemExit(0) on SIGINT/SIGTERM while a service waits."""
        session = _open_session(options)
        wire = cls(session, loop, secured=options.config_file is not None)
        try:
            yield wire
        finally:
            wire._closers.close()
            session.close()

    def at_close(self, func: Callable[[], object]) -> None:
        """Call `func()` when the bus closes, before its session does (what was opened on
        top of it: a robot transport's own node)."""
        self._closers.callback(func)

    def _close_publishers(self) -> None:
        for publisher in list(self._publishers):
            publisher.close()

    @property
    def session(self) -> zenoh.Session:
        return self._session

    def call_soon(self, func: Callable[..., object], *args: Any) -> None:
        """Run `func(*args)` on the bus's loop, from any thread; nothing once it closes."""
        with contextlib.suppress(RuntimeError):  # the loop is closing; nothing to deliver to
            self._loop.call_soon_threadsafe(func, *args)

    def _spawn(self, work: Awaitable[T], done: Callable[[asyncio.Task[T]], None]) -> None:
        """Run `work` as a task on the loop (called on the loop), held until it ends, then
        call `done(task)`."""
        task = self._loop.create_task(_awaitable(work))
        self._running.add(task)
        task.add_done_callback(self._running.discard)
        task.add_done_callback(done)

    # --- publish / subscribe -----------------------------------------------------------

    def publish_bytes(
        self,
        key: str,
        payload: bytes,
        encoding: zenoh.Encoding = CDR,
        urgent: bool = False,
        attachment: bytes | None = None,
        waits: bool = False,
    ) -> None:
        """Publish raw bytes (CDR for ROS topics), with an `attachment` if given (what
        rmw_zenoh's subscribers require). Under congestion it is dropped, as Zenoh does by
        default, unless it `waits` for room; an `urgent` one (zero velocity, a stop) waits,
        and goes first and at once."""
        qos = _URGENT if urgent else _WAITS if waits else {}
        self._session.put(key, payload, encoding=encoding, attachment=attachment, **qos)

    def publisher(self, key: str, encoding: zenoh.Encoding = CDR) -> Publisher:
        """A publisher declared once for many payloads on one key (an audio session);
        close it when done (the bus closes those still open)."""
        publisher = Publisher(self, key, encoding)
        self._publishers.add(publisher)
        return publisher

    def keeping(self, key: str, depth: int = 1, encoding: zenoh.Encoding = CDR) -> Kept:
        """A publisher of raw bytes on `key` that keeps its last `depth` samples for
        subscribers that come later, and asks them (ROS's transient local, as rmw_zenoh
        publishes it: an action's status; a voicectl status)."""
        kept = Kept(self, key, depth, encoding)
        self._closers.callback(kept.close)
        return kept

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

        With `history`, also for the last message of every `keeping` publisher on `key`,
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

        try:
            self._session.get(
                key,
                zenoh.handlers.Callback(on_reply, on_done, indirect=False),
                payload=payload,
                attachment=attachment,
                timeout=timeout,
                **(_URGENT if urgent else {}),
                **(_COMPLETE if complete else {}),
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
            **_URGENT,
            **(_COMPLETE if complete else {}),
        )

    def queryable(
        self, key: str, on_query: Callable[[zenoh.Query], None], complete: bool = False
    ) -> None:
        """Hand every query on `key` to `on_query` on Zenoh's own thread, until the bus
        closes; it must be quick, and reply (or not) and drop the query. A `complete`
        queryable answers for the whole key (rmw_zenoh's clients ask only those)."""
        queryable = self._session.declare_queryable(key, _direct(on_query), complete=complete)
        self._closers.callback(queryable.undeclare)

    def serve_bytes_now(
        self, key: str, handler: Callable[[bytes, Callable[[bytes | None], None]], None]
    ) -> None:
        """Answer CDR queries on `key` without the loop: `handler(payload, reply)` runs on
        Zenoh's own thread and must be quick; it (or whichever thread it hands the work
        to) calls `reply(answer)` once, from any thread, or `reply(None)` to leave the
        query unanswered. For what must not wait for a loop: a STOP's cancel."""

        def on_query(query: zenoh.Query) -> None:
            raw = query.payload.to_bytes() if query.payload is not None else b""
            lock = threading.Lock()

            def reply(answer: bytes | None) -> None:
                if not lock.acquire(blocking=False):
                    return  # answered already
                try:
                    if answer is not None:
                        query.reply(query.key_expr, answer, encoding=CDR)
                finally:
                    query.drop()

            try:
                handler(raw, reply)
            except Exception:
                _LOGGER.exception("query on %s failed", key)
                reply(None)

        self.queryable(key, on_query)

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

        async def respond(_query_key: str, raw: bytes) -> Answer | None:
            answer = await handler(raw)
            return None if answer is None else (answer, CDR)

        self._answer_queries(key, respond, complete, reply_attachment)

    def _answer_queries(
        self,
        key: str,
        respond: Callable[[str, bytes], Awaitable[Answer | None]],
        complete: bool = False,
        reply_attachment: Callable[[bytes | None], bytes | None] | None = None,
    ) -> None:
        """Declare a queryable on `key` whose answers `respond(query_key, payload)` makes,
        run as a task on the loop; the reply leaves from the loop when the task ends."""

        def reply(query: zenoh.Query, done: asyncio.Task[Answer | None]) -> None:
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
            self._spawn(respond(query_key, raw), lambda done: reply(query, done))

        def on_query(query: zenoh.Query) -> None:  # on Zenoh's thread: hand over at once
            raw = query.payload.to_bytes() if query.payload is not None else b""
            try:
                self._loop.call_soon_threadsafe(start, query, str(query.key_expr), raw)
            except RuntimeError:  # loop closed: the process is stopping
                query.drop()

        self.queryable(key, on_query, complete)

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
        return self._watch_matching(self._session.declare_publisher(key), handler)

    def watch_served(self, key: str, handler: Callable[[bool], None]) -> Callable[[], None]:
        """Call `handler(served)` on the loop as a service answering queries on `key`
        becomes reachable through the router, and as it goes, until the bus closes or the
        returned function ends the watch. A token says a process is up; this says its
        queries would arrive: after a link comes back the two are declared apart, and a
        query sent between them reaches nobody."""
        return self._watch_matching(self._session.declare_querier(key), handler)

    def _watch_matching(
        self, declared: zenoh.Publisher | zenoh.Querier, handler: Callable[[bool], None]
    ) -> Callable[[], None]:
        """Call `handler(matching)` on the loop now and whenever `declared` gains its first
        match or loses its last; the returned function undeclares it. The status is also
        read again every `MATCHING_RECHECK` seconds: Zenoh's matching listeners have
        missed changes (eclipse-zenoh/zenoh#2204), and a supervisor that never hears its
        executor's services come serves nobody."""
        said: list[bool] = []
        live = [True]

        def tell(matching: bool) -> None:
            if said != [matching]:
                said[:] = [matching]
                handler(matching)

        def on_status(status: zenoh.MatchingStatus) -> None:
            self.call_soon(tell, status.matching)

        def read_again() -> None:
            if not live[0]:
                return
            try:
                now: Any = declared.matching_status  # a MatchingStatus, whatever the stubs say
            except zenoh.ZError:
                return  # undeclared as the bus closed, on another thread
            tell(now.matching)
            self._loop.call_later(MATCHING_RECHECK, read_again)

        def end() -> None:
            live[0] = False

        stop_declared = self._undeclare_once(declared)
        listener = declared.declare_matching_listener(_direct(on_status))
        stop_listening = self._undeclare_once(listener)  # closed first: it lives in `declared`
        self._closers.callback(end)  # rechecks end first: closers run last-in, first-out
        self.call_soon(read_again)

        def stop() -> None:
            end()
            stop_listening()
            stop_declared()

        return stop


class Publisher:
    """Many payloads on one key through one declared publisher, in order and reliably.

    `matched()` waits until a subscriber is known: what is put before that can be lost, so
    a sender that starts a session waits for it first.
    """

    def __init__(self, wire: Wire, key: str, encoding: zenoh.Encoding) -> None:
        self._wire = wire
        self._publisher = wire.session.declare_publisher(
            key, encoding=encoding, congestion_control=zenoh.CongestionControl.BLOCK
        )
        self._closed = False
        self._lock = threading.Lock()
        """A put and the undeclare never overlap: a sender's thread and the bus closing
        may reach them at once, and Zenoh refuses that ("Already borrowed")."""

    def put(self, payload: bytes) -> None:
        with self._lock:
            if not self._closed:
                self._publisher.put(payload)

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
        self._wire._publishers.discard(self)


class Kept:
    """Payloads on one key whose last `depth` Zenoh's advanced publisher keeps for
    subscribers that come later (`Wire.keeping`).

    The publisher caches its last samples and announces itself, and a subscriber declared
    with `history` asks every such publisher for its cache, whether it starts before or
    after the publisher. These rare payloads (a status, a grammar of some 100 kB) block for
    room under congestion rather than being dropped.
    """

    def __init__(self, wire: Wire, key: str, depth: int, encoding: zenoh.Encoding) -> None:
        self._publisher = zenoh.ext.declare_advanced_publisher(
            wire.session,
            key,
            encoding=encoding,
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
            up, router = voicectl_command("up"), voicectl_command("router")
            why = f"waited {CLIENT_TIMEOUT:g} s; is {up} or {router} running"
            if options.config_file is not None:
                why += ", and do its TLS certificates and credentials match --config"
            why += "?"
        raise BusError(f"cannot reach the router at {options.where} ({why})") from failed[0]
    return opened[0]


_URGENT: dict[str, Any] = {
    "congestion_control": zenoh.CongestionControl.BLOCK,
    "priority": zenoh.Priority.REAL_TIME,
    "express": True,
}
"""How a stop goes out: it waits for room instead of being dropped, first and at once."""
_WAITS: dict[str, Any] = {"congestion_control": zenoh.CongestionControl.BLOCK}
"""How what matters goes out (an order's result): it waits for room instead of being dropped."""
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
