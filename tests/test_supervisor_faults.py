"""The supervisor under the faults and abuse of issue 32, each probe a real process on
loopback: a full disk, a flood of made-up robots, a forged owner, a skewed clock, a
damaged or emptied store."""

from __future__ import annotations

import asyncio
import re
import sqlite3
import subprocess
from pathlib import Path

from harness.client import STARTING, Client, client_wait_ready
from harness.processes import rss_mb
from harness.wait import async_wait_until
from voicectl.services.supervisor.service import CLAIM_WINDOW
from voicectl.shared.client import STOP_ANSWER, VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Done,
    EmergencyStop,
    Execute,
    ExecutorInfo,
    Failed,
    GetState,
    OrderStatus,
    Resume,
    StateReply,
    Stopped,
    Submitted,
    SupervisorReply,
)

from .conftest import SmallDisk
from .support import Site, StandIn, order


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
        freed = asyncio.get_running_loop().time()
        (accepted,) = await client.submit(order("mul", first=2, second=3))
        first: Execute = await stand_in.taken.get()
        back = asyncio.get_running_loop().time() - freed
        print(f"disk full: first order at the executor {back * 1000:.0f} ms after space returned")
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


async def served(client: Client) -> bool:
    """Whether the supervisor serves the client's robot (it answers its state)."""
    try:
        return isinstance(await client.ask(GetState()), StateReply)
    except BusError:  # no supervisor up (yet)
        return False


def served_robots(refusal: SupervisorReply) -> int:
    """How many robots a supervisor serves, from its refusal of a made-up one."""
    assert isinstance(refusal, Failed), refusal
    listed = re.search(r"known robots: (.*?)( and (\d+) more)?\)", refusal.reason)
    assert listed is not None, refusal.reason
    return len(listed[1].split(", ")) + int(listed[3] or 0)


FLOOD_ROBOTS, FLOOD_CAP = 2000, 64
"""The made-up names of the flood, and the supervisor's --max-robots under it."""
FLOOD_SENT = 120.0
"""Seconds for the flood to declare and send all of its names: a few alone; the margin is
for two suites on two cores, where the supervisor it floods shares them."""


async def test_made_up_robots_are_bounded_and_stop_stays_latched(site: Site) -> None:
    """Issue 32, item 2: 5,000 executor tokens, announcements and results for made-up
    names each made a robot (queue, owner token, queriers): the supervisor went deaf for
    minutes and grew by 210 MB, and a STOP during a flood fell back to the client's own,
    not latched. Now such robots are served up to --max-robots (256 by default), those
    beyond are ignored; a robot that holds a latched STOP is never let go; and a STOP
    during the flood is latched by the supervisor. How fast it answers is printed (run
    with -s; docs/benchmarks.md, "Faults and abuse"), not asserted: a busy machine may
    leave it to the client's own stop, which is as safe.

    The flood here is 2,000 names against a cap of 64 (the issue's was 5,000 against the
    default 256): as far past the cap, in less of the suite's time."""
    site.start_supervisor("--max-robots", str(FLOOD_CAP))
    assert site.supervisor is not None
    with site.joined() as bus:
        client, held = Client(bus, "r1"), Client(bus, "held")
        StandIn().serve(bus, RobotKeys("r1"))
        # How to reach the robot, as an executor says it: the client's STOP then waits
        # for nothing but the supervisor's answer.
        bus.latest(RobotKeys("r1").executor_info).publish(ExecutorInfo())
        bus.announce(RobotKeys("r1").alive("executor"))
        await client_wait_ready(client)
        # A robot taken on for its executor, stopped, and whose executor then goes.
        gone = bus.announce(RobotKeys("held").alive("executor"))
        await async_wait_until(lambda: served(held), STARTING, "held to be taken on")
        assert isinstance(await held.ask(EmergencyStop()), Stopped)
        gone()
        await held.wait_state(lambda s: not s.executor_online, "held's executor to go")
        before = rss_mb(site.supervisor.pid)

        flood = site.processes.start(
            "harness.flood", "--connect", site.router, "--robots", str(FLOOD_ROBOTS), "--owners"
        )
        supervisor, nobody = site.supervisor, Client(bus, "nobody")
        await async_wait_until(
            lambda: (
                f"{FLOOD_CAP} robots besides those configured are served already"
                in (site.processes.log(supervisor))
            ),
            STARTING,
            "the cap to be reached, and names past it turned away, in the middle of the flood",
        )
        loop = asyncio.get_running_loop()
        asked = loop.time()
        stopped = await VoicectlClient(bus).stop("r1")  # the panel's and voicectl's STOP
        took = loop.time() - asked
        # The supervisor latches it: its own answer, or, on a machine too busy for it to
        # answer within STOP_ANSWER, the request the client's own stop went on waiting for.
        await client.wait_state(lambda s: s.stopped, "the supervisor to latch the stop")

        await async_wait_until(
            lambda: f"flooding: {FLOOD_ROBOTS}" in site.processes.log(flood),
            FLOOD_SENT,
            "the whole flood",
        )
        grew = rss_mb(supervisor.pid) - before
        print(
            f"flood of {FLOOD_ROBOTS} robots: STOP answered in {took * 1000:.0f} ms "
            f"({'the supervisor' if took < STOP_ANSWER else 'the client'}: {stopped.detail}); "
            f"RSS +{grew:.1f} MB"
        )
        assert served_robots(await nobody.ask(GetState())) == 1 + FLOOD_CAP  # r1, the cap
        assert grew < 60, grew
        assert (await held.state()).stopped  # never let go to make room
        refused = await client.ask_submit(order("mul"))
        assert isinstance(refused, Failed)
        assert refused.reason.startswith("the emergency stop is on")


async def test_a_robot_whose_executor_went_makes_room_for_a_newcomer(site: Site) -> None:
    """Past --max-robots a newcomer is turned away while every robot served has its
    executor; once one has gone (and holds nothing), the next newcomer takes its place."""
    site.start_supervisor("--max-robots", "2")
    with site.joined() as bus:
        first, second, third = (Client(bus, name) for name in ("first", "second", "third"))
        gone = bus.announce(first.keys.alive("executor"))
        bus.announce(second.keys.alive("executor"))
        for client in (first, second):
            await async_wait_until(lambda c=client: served(c), STARTING, "a robot taken on")
        turned_away = bus.announce(third.keys.alive("executor"))
        await async_wait_until(
            lambda: "robot 'third' is not served: 2 robots besides" in site.log(),
            STARTING,
            "the third to be turned away",
        )
        assert not await served(third)

        gone()  # first's executor goes: first holds nothing, and may make room
        await first.wait_state(lambda s: not s.executor_online, "first's executor to go")
        turned_away()
        bus.announce(third.keys.alive("executor"))  # third's executor starts again
        await async_wait_until(lambda: served(third), STARTING, "the third to be served")
        assert "first: no longer served: its executor has gone" in site.log()
        assert not await served(first)
        assert await served(second)


async def test_a_forged_owner_token_displaces_no_supervisor_and_stops_none_starting(
    site: Site, tmp_path: Path
) -> None:
    """Issue 32, item 3: one owner token that sorts first (held by no supervisor) made
    the serving supervisor stand down, and kept the next from starting. A token counts
    only for a supervisor that answers for the robot, and never against one serving."""
    site.start_supervisor()
    assert site.supervisor is not None
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        # Heard within its claim's first seconds, a claim is checked (this one does not
        # answer); after that it is a newcomer's, which never displaces the one serving.
        withdraw = bus.announce(client.keys.supervisor_owner("0-forged"))
        await async_wait_until(
            lambda: "Zenoh id 0-forged" in site.log(),
            STARTING,
            "the serving supervisor to hear the forged claim",
        )
        withdraw()
        await asyncio.sleep(CLAIM_WINDOW)  # time passing, not a peer: the window closes
        bus.announce(client.keys.supervisor_owner("0-forged"))
        await async_wait_until(
            lambda: "another claim to supervise it (Zenoh id 0-forged)" in site.log(),
            STARTING,
            "the serving supervisor to hear the forged claim again",
        )
        assert site.supervisor.poll() is None
        assert not (await client.state()).stopped  # still answering

        site.kill_supervisor()
        site.db = tmp_path / "second.sqlite3"
        site.start_supervisor()  # the forged token is still up
        await client_wait_ready(client, executor=False)
        assert "Zenoh id 0-forged, which does not answer as its supervisor: ignored" in (site.log())


async def test_a_second_supervisor_whose_clock_is_a_day_behind_stands_down_itself(
    site: Site, tmp_path: Path
) -> None:
    """Issue 32, item 3: owners were ordered by their start on the wall clock, so a
    second supervisor whose clock was a day behind displaced the one serving (and took
    over with an empty database). No clock takes part now: the one serving keeps the
    robot, and the second stops, naming it."""
    site.start_supervisor()
    assert site.supervisor is not None
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        (kept,) = await client.submit(order("mul"))
        second = site.processes.start(
            "tests.clock_a_day_behind",
            "voicectl.services.supervisor",
            *("--connect", site.router, "--robot", "r1", "--db", str(tmp_path / "second.db")),
            name="skewed-supervisor",
        )
        await async_wait_until(lambda: second.poll() is not None, STARTING, "the second to stop")
        assert second.returncode == 2
        assert "robot 'r1' already has a supervisor (Zenoh id " in site.processes.log(second)
        assert site.supervisor.poll() is None
        assert [r.id for r in (await client.state()).queue] == [kept]


async def stopped_exit(site: Site) -> str:
    """Start the supervisor, which must refuse: its last line."""
    site.start_supervisor()
    supervisor = site.supervisor
    assert supervisor is not None
    await async_wait_until(lambda: supervisor.poll() is not None, STARTING, "it to refuse")
    assert supervisor.returncode == 2, site.log()
    return site.log().strip().splitlines()[-1]


async def test_an_emptied_store_is_refused_and_its_latched_stop_outlives_it(site: Site) -> None:
    """Issue 32, item 5: a database emptied to 0 bytes started empty without a word, its
    history gone and its latched STOP released. Now the supervisor refuses it in one line
    that says how to recover; done as it says, it starts with an empty history and the
    robot still stopped (the latch file beside the store kept the STOP)."""
    site.start_supervisor()
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        await client.submit(order("mul"), order("mul"))
        assert isinstance(await client.ask(EmergencyStop()), Stopped)
        assert (await client.history()).total == 2
        site.kill_supervisor()
        site.db.write_bytes(b"")  # emptied, with what its journal held
        for journal in ("-wal", "-shm"):
            site.db.with_name(site.db.name + journal).unlink(missing_ok=True)

        line = await stopped_exit(site)
        assert line == (
            f"voicectl supervisor: {site.db} is empty (0 bytes): it was emptied, and its "
            "queue, history and latched STOPs are lost; restore it from a backup, or move it "
            "away to start with an empty queue and history (robots stopped by a latched STOP "
            f"stay stopped): mv {site.db} {site.db}.damaged"
        )
        mv = ["mv", str(site.db), f"{site.db}.damaged"]  # as the line says
        moved = await asyncio.to_thread(subprocess.run, mv, check=False)
        assert moved.returncode == 0
        site.start_supervisor()
        await client_wait_ready(client, executor=False)
        state = await client.state()
        assert state.stopped  # never released by losing the data
        assert (await client.history()).total == 0
        assert "robots stopped by the last latched STOP stay stopped: r1" in site.log()


async def test_a_damaged_store_is_refused_in_one_line(site: Site) -> None:
    """Issue 32, item 5: garbage in an index page started silently, garbage in a table
    page ended in a traceback. The store checks itself at start and refuses either."""
    site.start_supervisor()
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        for _ in range(20):
            await client.submit(*(order("mul", note="n" * 500) for _ in range(10)))
    assert site.supervisor is not None
    assert site.processes.stop(site.supervisor) == 0  # its journal folded into the file
    pages = site.db.read_bytes()
    page = 4096
    for index in (2, len(pages) // page - 1):  # a page near the start, and the last
        pages = pages[: index * page] + bytes(range(256)) * 16 + pages[(index + 1) * page :]
    site.db.write_bytes(pages)

    line = await stopped_exit(site)
    assert line.startswith(f"voicectl supervisor: {site.db} is damaged (")
    assert line.endswith(f"mv {site.db} {site.db}.damaged")
    assert "Traceback" not in site.log()


async def test_an_unreadable_latch_file_holds_every_robot_stopped(site: Site) -> None:
    """A latch file that cannot be read (a write torn by a power cut) may have held any
    robot's STOP: the supervisor starts with every robot it serves stopped, and says so."""
    site.start_supervisor()
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        site.kill_supervisor()
        site.db.with_name(site.db.name + ".stop").write_bytes(b'{"stopped": ["r')
        site.start_supervisor()
        await client_wait_ready(client, executor=False)
        assert (await client.state()).stopped
        assert "the latch file cannot be read" in site.log()


async def test_a_submit_past_the_queue_cap_is_refused_whole(site: Site) -> None:
    """Issue 32, item 7: the queue had no cap (10,200 orders accepted). A submit that would
    take it past --max-queue is refused in words, none of its orders queued; a retry of
    one already taken is still answered."""
    site.start_supervisor("--max-queue", "5")
    with site.joined() as bus:
        client = Client(bus, "r1")
        await client_wait_ready(client, executor=False)
        first = await client.submit(*(order("mul") for _ in range(4)), request_id="first")
        refused = await client.ask_submit(order("mul"), order("mul"))
        assert isinstance(refused, Failed)
        assert refused.reason == (
            "robot 'r1' has 4 orders queued and takes at most 5 (--max-queue): none of these "
            "2 was queued; cancel some, or wait for them to run"
        )
        assert (await client.state()).queue_length == 4
        assert await client.submit(*(order("mul") for _ in range(4)), request_id="first") == first
        await client.submit(order("mul"))
        assert (await client.state()).queue_length == 5
