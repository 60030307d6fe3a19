"""The supervisor under the faults and abuse of issue 32, each probe a real process on
loopback: a full disk, a flood of made-up robots, a forged owner, a skewed clock, a
damaged or emptied store."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from shared.keys import RobotKeys
from shared.messages import Done, Execute, Failed, OrderStatus, Resume, Submitted

from .conftest import SmallDisk
from .support import Client, Site, StandIn, client_wait_ready, order


def stored_status(db: Path, order_id: str) -> str | None:
    """The order's status as another process reads it from the store: what is committed."""
    with sqlite3.connect(db) as reader:
        row = reader.execute("SELECT status FROM orders WHERE id = ?", (order_id,)).fetchone()
    return None if row is None else str(row[0])


async def test_a_submit_refused_for_a_full_disk_runs_nothing_and_the_supervisor_recovers(
    site: Site, small_disk: SmallDisk
) -> None:
    """Issue 32, item 1: on a full disk the submit was refused and its first order ran
    all the same (dispatched before the commit, and never recorded). Now nothing is sent
    to the executor before its start is committed; the refusal says the disk is full;
    and once there is space the next submit runs, recorded as running before it is sent."""
    site.db = small_disk.path / "supervisor.sqlite3"
    site.start_supervisor()
    stand_in = StandIn(witness=lambda execute: stored_status(site.db, execute.order_id))
    keys = RobotKeys("r1")

    with site.joined() as bus:
        stand_in.serve(bus, keys)
        bus.announce(keys.alive("executor"))
        client = Client(bus, "r1")
        await client_wait_ready(client)
        small_disk.fill()

        for _ in range(3):  # the probe's retries drove the robot three times as far
            refused = await client.ask_submit(order("drive", distance=1.0), order("mul"))
            assert isinstance(refused, Failed), refused
            assert "could not store the orders, so none was queued or run: the disk" in (
                refused.reason
            )
            assert "is full" in refused.reason
            assert "savepoint" not in refused.reason
        state = await client.state()
        assert (state.current, state.queue_length) == (None, 0)

        small_disk.free()
        (accepted,) = await client.submit(order("mul", first=2, second=3))
        first: Execute = await stand_in.taken.get()
        assert first.order_id == accepted  # the first the executor ever got
        assert stand_in.witnessed[accepted] == OrderStatus.RUNNING.value
        assert stand_in.taken.empty()
        state = await client.wait_state(lambda s: s.current is not None, "the order to run")
        assert state.current is not None
        assert state.current.id == accepted


async def test_a_start_the_disk_refuses_is_not_sent_and_pauses_the_queue(
    site: Site, small_disk: SmallDisk
) -> None:
    """An order stored while there was space, whose start the disk then refuses (its
    executor came only after the disk filled): it is not sent, waits at the head of the
    queue, and the queue pauses saying why; resumed once there is space, it runs."""
    site.db = small_disk.path / "supervisor.sqlite3"
    site.start_supervisor()
    stand_in = StandIn(witness=lambda execute: stored_status(site.db, execute.order_id))
    keys = RobotKeys("r1")

    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        reply = await client.ask_submit(order("mul", first=1, second=1))
        assert isinstance(reply, Submitted)
        (waiting,) = reply.order_ids
        small_disk.fill()

        stand_in.serve(bus, keys)
        bus.announce(keys.alive("executor"))
        state = await client.wait_state(lambda s: bool(s.paused), "the queue to pause")
        assert f"order {waiting} could not start: the disk holding" in state.paused
        assert [r.id for r in state.queue] == [waiting]
        assert state.current is None
        assert stand_in.taken.empty()
        assert stored_status(site.db, waiting) == OrderStatus.QUEUED.value

        small_disk.free()
        assert isinstance(await client.ask(Resume()), Done)
        assert (await stand_in.taken.get()).order_id == waiting
        assert stand_in.witnessed[waiting] == OrderStatus.RUNNING.value
