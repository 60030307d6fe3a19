"""The order store: one SQLite writer thread, and who is told when a write is committed."""

from __future__ import annotations

import asyncio
import queue
import sqlite3
import threading
import time
from pathlib import Path

import msgspec

from harness.wait import async_wait_until
from voicectl.services.supervisor.latch import LatchFile
from voicectl.services.supervisor.store import RETRY_EVERY, OrderStore, StoreFull
from voicectl.shared.messages import OrderRecord, OrderStatus

from .conftest import SmallDisk
from .support import order

Told = tuple[BaseException | None, int, str]


def record(order_id: str) -> OrderRecord:
    return OrderRecord(id=order_id, order=order("x"), status=OrderStatus.QUEUED)


def count_from_elsewhere(path: Path) -> int:
    """Orders another connection sees: only what is committed."""
    with sqlite3.connect(path) as other:
        (count,) = other.execute("SELECT count(*) FROM orders").fetchone()
    return int(count)


async def test_write_then_is_told_on_the_writer_thread_once_the_write_is_committed(
    tmp_path: Path,
) -> None:
    told: queue.SimpleQueue[Told] = queue.SimpleQueue()
    with OrderStore(tmp_path / "orders.sqlite3") as store:

        def committed(error: BaseException | None) -> None:
            seen = count_from_elsewhere(store.path)
            told.put((error, seen, threading.current_thread().name))

        records = [(record("a"), 0.0), (record("b"), 1.0)]
        store.write_then([store.save_orders("r1", records)], committed)
        assert await asyncio.to_thread(told.get, timeout=5) == (None, 2, "order-store")


async def test_write_then_is_told_why_a_write_failed_and_the_others_still_commit(
    tmp_path: Path,
) -> None:
    told: queue.SimpleQueue[Told] = queue.SimpleQueue()
    with OrderStore(tmp_path / "orders.sqlite3") as store:

        def fails(_db: sqlite3.Connection) -> None:
            raise sqlite3.IntegrityError("disk says no")

        def committed(error: BaseException | None) -> None:
            told.put((error, count_from_elsewhere(store.path), ""))

        store.write_then([store.save_orders("r1", [(record("a"), 0.0)]), fails], committed)
        store.write_then([store.save_orders("r1", [(record("b"), 1.0)])], committed)
        error, _, _ = await asyncio.to_thread(told.get, timeout=5)
        assert isinstance(error, sqlite3.IntegrityError)
        # The failed write is undone whole (its first operation too); the next one is kept.
        assert (await asyncio.to_thread(told.get, timeout=5))[:2] == (None, 1)


def big_record(order_id: str) -> OrderRecord:
    """A record of about 2 kB: a few thousand of them overflow SQLite's page cache inside
    one statement, where a full disk makes SQLite undo the whole transaction by itself."""
    return OrderRecord(id=order_id, order=order("x", note="n" * 2000), status=OrderStatus.QUEUED)


async def test_a_full_disk_is_said_in_plain_words_and_kept_writes_land_once_space_returns(
    small_disk: SmallDisk,
) -> None:
    """On a real filesystem filled to the last byte: an answered write fails saying the
    disk is full (SQLite's own words were "no such savepoint: op" when the disk filled in
    the middle of a statement); a kept write waits and lands, in order, once there is
    space; reads go on meanwhile."""
    told: queue.SimpleQueue[BaseException | None] = queue.SimpleQueue()
    with OrderStore(small_disk.path / "orders.sqlite3") as store:
        await store.write([store.save_orders("r1", [(record("first"), 0.0)])])
        small_disk.fill()

        # Small: refused at COMMIT. Large: refused inside a statement, transaction undone.
        store.write_then([store.save_orders("r1", [(record("small"), 1.0)])], told.put)
        many = [(big_record(f"big{i}"), 2.0 + i) for i in range(3000)]
        store.write_then([store.save_orders("r1", many)], told.put)
        for _ in range(2):
            error = await asyncio.to_thread(told.get, timeout=10)
            assert isinstance(error, StoreFull), repr(error)
            assert str(error).startswith(f"the disk holding {store.path} is full: free some")
            assert "savepoint" not in str(error)

        ended = msgspec.structs.replace(record("first"), status=OrderStatus.SUCCEEDED, ended_at=1.0)
        store.keep([store.save_orders("r1", [(ended, 0.0)])])
        history = store.history_page("r1", 0, 10)
        assert await store.call(history, reads=True) == ([], 0)  # read while full
        assert store.trouble is not None
        assert "is full" in store.trouble
        assert count_from_elsewhere(store.path) == 1

        small_disk.free()
        freed = time.monotonic()
        await async_wait_until(
            lambda: store.trouble is None, 5 * RETRY_EVERY, "the kept write to land"
        )
        print(f"disk full: kept write landed {time.monotonic() - freed:.2f} s after space returned")
        records, total = await store.call(history)
        assert (total, [r.id for r in records]) == (1, ["first"])
        assert count_from_elsewhere(store.path) == 1  # the refused ones never landed


async def test_a_stop_latched_on_a_full_disk_reaches_the_latch_file(small_disk: SmallDisk) -> None:
    """The latch file is rewritten in place (no new block needed): a STOP latched while
    the disk is full is on disk at once, though the database takes it only later."""
    path = small_disk.path / "orders.sqlite3"
    latch = LatchFile(path.with_name(path.name + ".stop"))
    with OrderStore(path) as store:
        await store.call(store.load(10))  # the latch file is made at start
        small_disk.fill()
        store.set_stopped("r1", True)
        await async_wait_until(
            lambda: latch.read().robots == {"r1"}, 5.0, "the latch file to say r1 is stopped"
        )
        await async_wait_until(
            lambda: store.trouble is not None, 5.0, "the database to refuse it for now"
        )
        small_disk.free()
        await async_wait_until(lambda: store.trouble is None, 5 * RETRY_EVERY, "the database")
        saved = await store.call(store.load(10))
        assert saved["r1"].stopped
