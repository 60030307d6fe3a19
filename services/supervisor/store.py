"""Queue and history of every robot in SQLite, written in order from one thread.

The supervisor's state lives in memory and every change is also written here; a submit is
acknowledged only once its orders are committed, so an accepted order survives a SIGKILL
at any moment. Writes that pile up while a transaction commits go into the next one
together: a burst of submits costs one commit per batch, not one per order.

A write is either answered (a submit: told once whether it committed, never retried) or
kept (a change of state, such as an order's end: retried in order until it commits). When
the disk is full, answered writes fail at once in plain words, and kept ones wait and are
written, in their order, once there is space again.

The store checks itself when it opens (`PRAGMA quick_check`) and refuses a database that
is damaged, or was emptied after use, in one line that says how to recover; the latched
STOPs are also kept in a latch file beside it (latch.py), which an emptied database
cannot lose. A new database is made under another name and renamed into place once it
holds its tables, so that an empty file where the store should be is never one of ours.
"""

from __future__ import annotations

import asyncio
import contextlib
import fcntl
import functools
import logging
import os
import queue
import sqlite3
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import IO, Any, TypeVar

import msgspec

from voicectl.shared.errors import StoreError
from voicectl.shared.messages import OrderRecord

from .latch import Latched, LatchFile, sync_directory

_LOGGER = logging.getLogger(__name__)
T = TypeVar("T")

SCHEMA = """
CREATE TABLE IF NOT EXISTS orders (
    id TEXT PRIMARY KEY,
    robot TEXT NOT NULL,
    status TEXT NOT NULL,
    position REAL NOT NULL,
    ended_at REAL,
    record BLOB NOT NULL
);
CREATE INDEX IF NOT EXISTS orders_open ON orders (robot, position) WHERE ended_at IS NULL;
CREATE INDEX IF NOT EXISTS orders_ended ON orders (robot, ended_at) WHERE ended_at IS NOT NULL;
CREATE TABLE IF NOT EXISTS robots (
    robot TEXT PRIMARY KEY,
    stopped INTEGER NOT NULL DEFAULT 0
);
CREATE TABLE IF NOT EXISTS requests (
    robot TEXT NOT NULL,
    request_id TEXT NOT NULL,
    order_ids BLOB NOT NULL,
    PRIMARY KEY (robot, request_id)
);
CREATE TABLE IF NOT EXISTS edits (
    robot TEXT NOT NULL,
    id TEXT NOT NULL,
    undo BLOB NOT NULL,
    PRIMARY KEY (robot, id)
);
"""
BATCH_LIMIT = 2000
"""Most operations in one transaction."""
RETRY_EVERY = 1.0
"""Seconds between two tries to write what a full (or failing) disk refused."""


class Durability(StrEnum):
    PROCESS = "process"
    """Survives the supervisor being killed (WAL, synchronous=NORMAL): the default."""
    POWER = "power"
    """Also survives power loss (synchronous=FULL): every commit waits for the disk."""


KEPT_REQUESTS = 10_000
"""Request ids kept on disk (the newest), to answer a retry after a restart."""
KEPT_UNDOS = 10
"""Edits per robot that can be undone after a restart (the newest)."""


@dataclass
class SavedRobot:
    """What the store holds for one robot, as read at start-up."""

    open_orders: list[tuple[OrderRecord, float]] = field(default_factory=list)
    """Queued and running orders with their queue positions, in queue order."""
    history: list[OrderRecord] = field(default_factory=list)
    """The most recent finished orders, most recent first."""
    requests: dict[str, list[str]] = field(default_factory=dict)
    stopped: bool = False
    """The emergency stop was latched when the supervisor stopped."""
    undos: list[bytes] = field(default_factory=list)
    """How to undo its last edits, oldest first, as the supervisor encoded them."""


Operation = Callable[[sqlite3.Connection], Any]
Committed = Callable[[BaseException | None], None]
"""Told on the writer thread, once its write is committed (None) or has failed (why)."""


@dataclass(frozen=True, slots=True)
class Call:
    """An operation, and what to do on the writer thread with its outcome (ok, result or
    error) once its transaction has ended."""

    operation: Operation
    done: Callable[[bool, Any], None]
    kept: bool = False
    """Retried in order with every other kept call until it commits, instead of failing."""
    reads: bool = False
    """Only reads: when the disk refuses a transaction it is run again alone, since a
    read needs no space (history stays readable while the disk is full)."""
    latched: frozenset[str] | None = None
    """The robots latched from this call on, for the latch file (None: unchanged)."""


class StoreFull(StoreError):
    """The disk under the store is full (or failing): nothing can be written now."""


class NotStored(StoreError):
    """An order that should be in the store is not: its submit never committed."""


class StoreDamaged(StoreError):
    """The database cannot be trusted: damaged, emptied, or not a database at all."""


class OrderStore:
    """One SQLite database, one writer thread; every call runs there, in call order."""

    def __init__(self, path: Path, durability: Durability = Durability.PROCESS) -> None:
        self.path = path
        self._durability = durability
        self._inbox: queue.SimpleQueue[Call | None] = queue.SimpleQueue()
        """Calls in order; None stops the writer thread."""
        self._backlog: list[Call] = []
        """Kept calls the disk refused, in order: they go first into every transaction
        until they commit (writer thread only)."""
        self.trouble: str | None = None
        """Why the store cannot write now, in words; None while it writes."""
        self._outbox: list[Call] = []
        """Calls made during this turn of the event loop, handed over at its end."""
        self._thread: threading.Thread | None = None
        self._encoder = msgspec.json.Encoder()
        self._decoder = msgspec.json.Decoder(OrderRecord)
        self._ready = threading.Event()
        self._open_error: BaseException | None = None
        self._lock: IO[str] | None = None
        self._latch = LatchFile(path.with_name(path.name + ".stop"))
        self.latched = Latched()
        """What the latch file said at start."""
        self._latched_now: frozenset[str] = frozenset()
        """The robots latched now, as the loop knows them."""
        self._latch_unwritten: frozenset[str] | None = None
        """What the latch file should say and the disk refused (writer thread)."""

    def __enter__(self) -> OrderStore:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = _exclusive(self.path.with_name(self.path.name + ".lock"))
        self._thread = threading.Thread(target=self._run, name="order-store", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._open_error is not None:
            raise self._open_error
        return self

    def __exit__(self, *_exc: object) -> None:
        self._flush()
        self._inbox.put(None)
        if self._thread is not None:
            self._thread.join(timeout=10)
        if self._lock is not None:
            self._lock.close()  # closing the file releases the lock

    # --- calls from the event loop -------------------------------------------------------

    async def call(self, operation: Callable[[sqlite3.Connection], T], reads: bool = False) -> T:
        """Run `operation` on the writer thread after everything queued before it; one
        that only `reads` is answered even while the disk refuses writes."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()
        self._send(Call(operation, functools.partial(_settle_soon, loop, future), reads=reads))
        return await future

    def keep(self, operations: list[Operation]) -> asyncio.Future[None]:
        """Queue `operations` as one, to be committed whatever it takes: when the disk
        refuses them they are tried again, in order with every other kept write, until
        they commit. For changes of state (an order's end, the stop); the future resolves
        once they are committed, for whoever answers only then (a reorder)."""
        return self._kept(_all(operations))

    def _kept(
        self, operation: Operation, latched: frozenset[str] | None = None
    ) -> asyncio.Future[None]:
        loop = asyncio.get_running_loop()
        future: asyncio.Future[None] = loop.create_future()
        future.add_done_callback(_said)
        settle = functools.partial(_settle_soon, loop, future)
        self._send(Call(operation, settle, kept=True, latched=latched))
        return future

    def write(self, operations: list[Operation]) -> asyncio.Future[None]:
        """Queue `operations` as one, tried once; the future resolves when they are
        committed, or fails saying why (StoreFull in plain words when the disk is full).
        Nobody has to await it: a failure is logged either way."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[None] = loop.create_future()

        def log_failure(done: asyncio.Future[None]) -> None:
            error = None if done.cancelled() else done.exception()
            if error is not None and not isinstance(error, StoreError):  # said once already
                _LOGGER.error("order store: write failed: %s", error)

        future.add_done_callback(log_failure)
        self._send(Call(_all(operations), functools.partial(_settle_soon, loop, future)))
        return future

    def write_then(self, operations: list[Operation], committed: Committed) -> None:
        """Queue `operations` as one, and call `committed` on the writer thread when they
        are committed or have failed: what answers a batch of submits straight from the
        writer, without a round through the event loop. It must be quick and thread-safe;
        a failure is logged here either way."""

        def done(ok: bool, value: Any) -> None:
            if not ok and not isinstance(value, StoreError):  # a full disk is said once
                _LOGGER.error("order store: write failed: %s", value)
            committed(None if ok else value)

        self._send(Call(_all(operations), done))

    def _send(self, call: Call) -> None:
        """Hand `call` to the writer thread once the callbacks already due on the loop have
        run, in order with every other call. Woken at once, the writer would take the GIL
        from the loop just as it dispatches the order that was just submitted (measured:
        180 us of the 250 us between a submit's arrival and its dispatch)."""
        self._outbox.append(call)
        if len(self._outbox) == 1:
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        calls, self._outbox = self._outbox, []
        for call in calls:
            self._inbox.put(call)

    # --- operations ------------------------------------------------------------------------

    def save_orders(self, robot: str, records: list[tuple[OrderRecord, float]]) -> Operation:
        rows = [
            (r.id, robot, r.status.value, position, r.ended_at, self._encoder.encode(r))
            for r, position in records
        ]

        def save(db: sqlite3.Connection) -> None:
            db.executemany(
                "INSERT INTO orders (id, robot, status, position, ended_at, record)"
                " VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT (id) DO UPDATE SET"
                " status = excluded.status, position = excluded.position,"
                " ended_at = excluded.ended_at, record = excluded.record",
                rows,
            )

        return save

    def require_stored(self, order_id: str) -> Operation:
        """Fails (NotStored) unless order `order_id` is in the store: written before an
        order's start, in the same transaction, so that no order runs whose submit did not
        commit (its rows are gone, its submitter told so)."""

        def require(db: sqlite3.Connection) -> None:
            if db.execute("SELECT 1 FROM orders WHERE id = ?", (order_id,)).fetchone() is None:
                raise NotStored(f"order {order_id} was never stored: its submit failed")

        return require

    def set_stopped(self, robot: str, stopped: bool) -> asyncio.Future[None]:
        """Keep `robot`'s emergency stop latched (or released), in the database and in the
        latch file, whatever it takes (a kept write); the future resolves once it is
        committed, for a STOP that answers only then."""
        if stopped:
            self._latched_now |= {robot}
        else:
            self._latched_now -= {robot}

        def save(db: sqlite3.Connection) -> None:
            db.execute(
                "INSERT INTO robots (robot, stopped) VALUES (?, ?)"
                " ON CONFLICT (robot) DO UPDATE SET stopped = excluded.stopped",
                (robot, int(stopped)),
            )

        return self._kept(save, latched=self._latched_now)

    def save_requests(self, robot: str, requests: list[tuple[str, list[str]]]) -> Operation:
        """Request ids with the ids of the orders they queued, to answer retries."""
        rows = [(robot, request_id, self._encoder.encode(ids)) for request_id, ids in requests]

        def save(db: sqlite3.Connection) -> None:
            db.executemany(
                "INSERT OR IGNORE INTO requests (robot, request_id, order_ids) VALUES (?, ?, ?)",
                rows,
            )

        return save

    def save_undo(self, robot: str, edit_id: str, undo: bytes) -> Operation:
        """How to undo edit `edit_id` (kept until it is undone, or too old)."""

        def save(db: sqlite3.Connection) -> None:
            db.execute(
                "INSERT OR REPLACE INTO edits (robot, id, undo) VALUES (?, ?, ?)",
                (robot, edit_id, undo),
            )

        return save

    def drop_undo(self, robot: str, edit_id: str) -> Operation:
        def drop(db: sqlite3.Connection) -> None:
            db.execute("DELETE FROM edits WHERE robot = ? AND id = ?", (robot, edit_id))

        return drop

    def history_page(
        self, robot: str, offset: int, limit: int
    ) -> Callable[[sqlite3.Connection], tuple[list[OrderRecord], int]]:
        def page(db: sqlite3.Connection) -> tuple[list[OrderRecord], int]:
            rows = db.execute(
                "SELECT record FROM orders WHERE robot = ? AND ended_at IS NOT NULL"
                " ORDER BY ended_at DESC, rowid DESC LIMIT ? OFFSET ?",
                (robot, limit, offset),
            ).fetchall()
            (total,) = db.execute(
                "SELECT count(*) FROM orders WHERE robot = ? AND ended_at IS NOT NULL", (robot,)
            ).fetchone()
            return [self._decoder.decode(row[0]) for row in rows], int(total)

        return page

    def load(self, history: int) -> Callable[[sqlite3.Connection], dict[str, SavedRobot]]:
        def load(db: sqlite3.Connection) -> dict[str, SavedRobot]:
            robots: dict[str, SavedRobot] = {}
            for robot, position, raw in db.execute(
                "SELECT robot, position, record FROM orders WHERE ended_at IS NULL"
                " ORDER BY robot, position"
            ):
                saved = robots.setdefault(robot, SavedRobot())
                saved.open_orders.append((self._decoder.decode(raw), position))
            for (robot,) in db.execute("SELECT DISTINCT robot FROM orders"):
                saved = robots.setdefault(robot, SavedRobot())
                saved.history = self.history_page(robot, 0, history)(db)[0]
            ids_decoder = msgspec.json.Decoder(list[str])
            # Only recent request ids answer retries: older ones are dropped from disk too,
            # oldest first, so the table does not grow with every submit ever taken.
            db.execute(
                "DELETE FROM requests WHERE rowid <= (SELECT MAX(rowid) FROM requests) - ?",
                (KEPT_REQUESTS,),
            )
            for robot, request_id, ids in db.execute(
                "SELECT robot, request_id, order_ids FROM requests ORDER BY rowid"
            ):
                saved = robots.setdefault(robot, SavedRobot())
                saved.requests[request_id] = ids_decoder.decode(ids)
            for (robot,) in db.execute("SELECT DISTINCT robot FROM edits").fetchall():
                db.execute(
                    "DELETE FROM edits WHERE robot = ? AND rowid NOT IN (SELECT rowid FROM edits"
                    " WHERE robot = ? ORDER BY rowid DESC LIMIT ?)",
                    (robot, robot, KEPT_UNDOS),
                )
            for robot, undo in db.execute("SELECT robot, undo FROM edits ORDER BY rowid"):
                robots.setdefault(robot, SavedRobot()).undos.append(undo)
            for robot, stopped in db.execute("SELECT robot, stopped FROM robots"):
                robots.setdefault(robot, SavedRobot()).stopped = bool(stopped)
            # Stopped in either the database or the latch file: stopped.
            for robot in self.latched.robots:
                robots.setdefault(robot, SavedRobot()).stopped = True
            self._latched_now = frozenset(r for r, saved in robots.items() if saved.stopped)
            self._write_latch(self._latched_now)
            return robots

        return load

    # --- the writer thread -------------------------------------------------------------------

    def _connect(self) -> sqlite3.Connection:
        self.latched = self._latch.read()
        if self.latched.unreadable:
            _LOGGER.error(
                "the latch file cannot be read (%s): every robot served from the start is "
                "held stopped; release each once it is safe",
                self.latched.unreadable,
            )
        if self.path.exists():
            self._check()
        else:
            self._create()
        db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=True)
        db.execute("PRAGMA journal_mode = WAL")
        sync = "FULL" if self._durability is Durability.POWER else "NORMAL"
        db.execute(f"PRAGMA synchronous = {sync}")
        db.executescript(SCHEMA)
        return db

    def _check(self) -> None:
        """Refuse a database that is empty, damaged or stripped of its tables: starting
        on it would forget the queue, the history and a latched STOP without a word."""
        recover = (
            "restore it from a backup, or move it away to start with an empty queue and "
            f"history (robots stopped by a latched STOP stay stopped): mv {self.path} "
            f"{self.path}.damaged"
        )
        if self.path.stat().st_size == 0:
            raise StoreDamaged(
                f"{self.path} is empty (0 bytes): it was emptied, and its queue, history and "
                f"latched STOPs are lost; {recover}"
            )
        try:
            with contextlib.closing(sqlite3.connect(self.path)) as db:
                found = db.execute("PRAGMA quick_check").fetchall()
                tables = {row[0] for row in db.execute("SELECT name FROM sqlite_master")}
        except sqlite3.DatabaseError as exc:
            raise StoreDamaged(f"{self.path} is damaged ({exc}); {recover}") from exc
        if found != [("ok",)]:
            raise StoreDamaged(f"{self.path} is damaged ({found[0][0]}); {recover}")
        if "orders" not in tables and self.latched.found:
            raise StoreDamaged(
                f"{self.path} holds none of the supervisor's tables, though it has been used "
                f"(see {self._latch.path}): it was emptied; {recover}"
            )

    def _create(self) -> None:
        """A new database: made under another name, then renamed into place. It holds what
        people said: readable by its owner only, like the token file (SQLite gives its
        -wal and -shm files the database's permissions)."""
        if self.latched.found:
            _LOGGER.warning(
                "no order store at %s: a new, empty one is made; robots stopped by the last "
                "latched STOP stay stopped: %s",
                self.path,
                ", ".join(sorted(self.latched.robots)) or "none",
            )
        fresh = self.path.with_name(self.path.name + ".new")
        for leftover in (self.path.name + suffix for suffix in ("-wal", "-shm")):
            # Without their database these belong to none; moved aside, never applied to
            # the new one.
            with contextlib.suppress(FileNotFoundError):
                os.replace(self.path.with_name(leftover), self.path.with_name(leftover + ".orphan"))
        for stale in (fresh.name, fresh.name + "-wal", fresh.name + "-shm"):
            with contextlib.suppress(FileNotFoundError):
                self.path.with_name(stale).unlink()
        os.close(os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        with contextlib.closing(sqlite3.connect(fresh, isolation_level=None)) as db:
            db.execute("PRAGMA journal_mode = WAL")
            db.executescript(SCHEMA)
            db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        os.replace(fresh, self.path)
        sync_directory(self.path.parent)

    def _write_latch(self, robots: frozenset[str]) -> None:
        """The latch file says `robots` from now on, or will as soon as the disk lets it
        (writer thread)."""
        try:
            self._latch.write(robots)
        except OSError as exc:
            if self._latch_unwritten is None:
                _LOGGER.error("cannot write the latch file %s: %s", self._latch.path, exc)
            self._latch_unwritten = robots
            return
        if self._latch_unwritten is not None:
            _LOGGER.warning("the latch file %s is written again", self._latch.path)
        self._latch_unwritten = None

    def _run(self) -> None:
        try:
            db = self._connect()
        except (sqlite3.Error, OSError, StoreError) as exc:
            self._open_error = exc
            self._ready.set()
            return
        self._ready.set()
        try:
            while True:
                behind = self._backlog or self._latch_unwritten is not None
                try:
                    first = self._inbox.get(timeout=RETRY_EVERY if behind else None)
                except queue.Empty:  # nothing new: try the backlog alone
                    self._run_batch(db, [])
                    continue
                if first is None:
                    return
                batch = [first]
                stop = False
                while len(batch) < BATCH_LIMIT:
                    try:
                        item = self._inbox.get_nowait()
                    except queue.Empty:
                        break
                    if item is None:
                        stop = True
                        break
                    batch.append(item)
                self._run_batch(db, batch)
                if stop:
                    return
        finally:
            if self._backlog:
                _LOGGER.error(
                    "order store: %d change(s) never reached the disk (%s)",
                    len(self._backlog),
                    self.trouble,
                )
            db.close()

    def _run_batch(self, db: sqlite3.Connection, new: list[Call]) -> None:
        """One transaction: the backlog of kept calls first, then `new`, in order. A call
        that fails on its own (a bad operation) is undone alone; when the disk fails, the
        whole transaction is undone, kept calls wait in the backlog for the next try and
        the others are told, in plain words."""
        latched = [call.latched for call in new if call.latched is not None]
        if latched or self._latch_unwritten is not None:
            self._write_latch(latched[-1] if latched else self._latch_unwritten or frozenset())
        batch, self._backlog = [*self._backlog, *new], []
        if not batch:
            return
        results: list[tuple[bool, Any]] = []
        try:
            db.execute("BEGIN IMMEDIATE")
            for call in batch:
                # A savepoint per operation: one that fails is undone alone.
                db.execute("SAVEPOINT op")
                try:
                    results.append((True, call.operation(db)))
                    db.execute("RELEASE op")
                except Exception as exc:
                    # A full disk can make SQLite undo the whole transaction by itself:
                    # then there is no savepoint left, and the disk is what to report.
                    if _disk_trouble(exc) or not db.in_transaction:
                        raise
                    db.execute("ROLLBACK TO op")
                    db.execute("RELEASE op")
                    results.append((False, exc))
            db.execute("COMMIT")
        except Exception as exc:
            if db.in_transaction:
                db.rollback()
            self._refused(db, batch, self._plain(exc))
            return
        if self.trouble is not None:
            _LOGGER.warning("order store: writing again, after: %s", self.trouble)
            self.trouble = None
        for call, (ok, value) in zip(batch, results, strict=True):
            _report(call, ok, value)

    def _refused(self, db: sqlite3.Connection, batch: list[Call], error: StoreError) -> None:
        """The disk refused `batch`: kept calls wait for the next try, reads run alone,
        the others fail."""
        if self.trouble != str(error):  # once, not once a second while it lasts
            _LOGGER.error("order store: cannot write: %s", error)
            self.trouble = str(error)
        self._backlog = [call for call in batch if call.kept]
        for call in batch:
            if call.reads:
                try:
                    _report(call, True, call.operation(db))
                except Exception as exc:
                    _report(call, False, exc)
            elif not call.kept:
                _report(call, False, error)

    def _plain(self, exc: BaseException) -> StoreError:
        """What went wrong, in words a person acts on (SQLite's own can read "no such
        savepoint" when the disk filled up in the middle of a transaction)."""
        code = getattr(exc, "sqlite_errorcode", 0) & 0xFF
        if code == sqlite3.SQLITE_FULL:
            return StoreFull(
                f"the disk holding {self.path} is full: free some space there "
                "(nothing is recorded, and no new order starts, until then)"
            )
        if code == sqlite3.SQLITE_IOERR:
            return StoreFull(f"the disk holding {self.path} fails to write: {exc}")
        return StoreError(f"the order store {self.path} refused a write: {exc}")


class StoreInUse(StoreError, OSError):
    """Another supervisor holds the database: two would hand the same orders out twice."""


def _exclusive(path: Path) -> IO[str]:
    """An exclusive lock on `path`, held while the returned file stays open."""
    handle = path.open("a+", encoding="utf-8")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "another process"
        handle.close()
        raise StoreInUse(f"{path.parent} is in use by another supervisor ({holder})") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"pid {os.getpid()}\n")
    handle.flush()
    return handle


def _disk_trouble(exc: BaseException) -> bool:
    """Whether `exc` is the disk's failure (full, or failing to write), not an operation's."""
    code = getattr(exc, "sqlite_errorcode", 0) & 0xFF
    return code in (sqlite3.SQLITE_FULL, sqlite3.SQLITE_IOERR)


def _report(call: Call, ok: bool, value: Any) -> None:
    try:
        call.done(ok, value)
    except Exception:  # one caller's failure must not keep the others waiting
        _LOGGER.exception("order store: reporting a write's outcome failed")


def _said(done: asyncio.Future[None]) -> None:
    """A kept write that failed alone (a bad operation) is logged, whether or not anyone
    awaits it."""
    error = None if done.cancelled() else done.exception()
    if error is not None:
        _LOGGER.error("order store: write failed: %s", error)


def _all(operations: list[Operation]) -> Operation:
    def run_all(db: sqlite3.Connection) -> None:
        for operation in operations:
            operation(db)

    return run_all


def _settle_soon(
    loop: asyncio.AbstractEventLoop, future: asyncio.Future[Any], ok: bool, value: Any
) -> None:
    with contextlib.suppress(RuntimeError):  # the loop closed: nobody is waiting
        loop.call_soon_threadsafe(_settle, future, ok, value)


def _settle(future: asyncio.Future[Any], ok: bool, value: Any) -> None:
    if future.done():
        return
    if ok:
        future.set_result(value)
    else:
        future.set_exception(value)
