"""The order store: one SQLite writer thread, and who is told when a write is committed."""

from __future__ import annotations

import asyncio
import queue
import sqlite3
import threading
from pathlib import Path

from services.supervisor.store import OrderStore
from shared.messages import OrderRecord, OrderStatus

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
