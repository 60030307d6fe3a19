"""STOP first, whatever the executor is doing: each fault of harness/stop_rig.py, once, with
real processes on loopback and the simulator. The tests wait for conditions: the robot
told to stop before any faulty part could have let it, standing, and moved no more. How
fast is bench/stop.py's figure (the same cases many times, percentiles, docs/benchmarks.md)."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path

import pytest

from harness.stop_rig import CASES, FAULT_SECONDS, ROBOT, StopRig, ended, order
from harness.wait import async_wait_until
from voicectl.shared.bus import json_decoder
from voicectl.shared.client import Unreachable, VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    EmergencyStop,
    ExecutorInfo,
    ExecutorReply,
    Failed,
    GetState,
    OrderStatus,
    Release,
    StateReply,
    Stopped,
)
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot.action import Cancelled
from voicectl.shared.robot.stop import (
    ExecutorLatch,
    LatchAnswer,
    RobotStop,
    StopOutcome,
    prepare,
    stop_codec,
)
from voicectl.shared.ros2 import CmdVelType, RosDistro

from .conftest import Processes
from .support import joined

BOUND = FAULT_SECONDS / 2
"""Seconds from STOP to the robot told to stop, at most: half as long as the faulty
executors block their loop, and well short of any timeout on the way (the supervisor's 5 s
for its executor), so a STOP that waited for any of them fails; generous on a busy
machine, where tens of milliseconds can become hundreds. Not a figure: bench/stop.py
measures that."""


@pytest.mark.parametrize(
    ("case", "transport"),
    [
        *((case, TransportKind.BRIDGE) for case in CASES),
        # On rmw_zenoh the robot hears only what carries its attachment, on its keys: the
        # stops of whoever is left alive, through the same seam.
        ("executor-killed", TransportKind.RMW_ZENOH),
        ("supervisor-and-executor-killed", TransportKind.RMW_ZENOH),
    ],
)
async def test_stop_stops_the_robot_at_once_and_for_good(
    case: str, transport: TransportKind, router: str, processes: Processes, tmp_path: Path
) -> None:
    rig = StopRig(router, processes, tmp_path / "supervisor.sqlite3", transport=transport)
    with rig.client() as client:
        outcome = await rig.run(case, client)
        print(case, outcome)
        assert outcome.zero_velocity < BOUND, outcome
        if outcome.cancelled is not None:
            assert outcome.cancelled < BOUND, outcome
        assert outcome.stood < math.inf, outcome  # it came to a stand, and stayed:
        assert outcome.moved_standing < 0.01, outcome
        assert outcome.fastest_standing == 0.0, outcome
        if case == "supervisor-and-executor-killed":
            assert outcome.stopped.detail.startswith("SUPERVISOR DID NOT STOP IT"), outcome
            assert "navigation cancelled every goal" in outcome.stopped.detail
            assert outcome.stopped.confirmed
            return
        if case == "executor-killed" and not outcome.stopped.confirmed:
            # Asked as the executor dies, before the supervisor has heard it go (under
            # load that can take longer than the stop): the latch finds no executor, and
            # the supervisor rightly says it could not confirm that part; the robot was
            # stopped all the same (above).
            assert "EXECUTOR: executor unreachable" in outcome.stopped.detail, outcome
            assert "navigation cancelled every goal" in outcome.stopped.detail, outcome
        else:
            assert outcome.stopped.confirmed, outcome
        reply = await client.ask(ROBOT, GetState())
        assert isinstance(reply, StateReply)
        assert reply.state.stopped
        assert reply.state.queue_length == 0
        if case == "commanding-from-blocked-loop":
            # Its commands went on, and the robot handle refused every one after the stop:
            # the executor's word on the order, which the stop ended at once.
            blocked = "the executor's word on the blocked order"
            record = await ended(
                client, lambda r: r.order.label == "blockdrive" and "drove; " in r.message, blocked
            )
            assert record.status == OrderStatus.CANCELLED, record
            refused = int(record.message.split("drove; ")[1].split()[0])
            assert refused >= 3, record
        if case == "50-queued":
            history = reply.state.history
            assert sum(r.message == "emergency stop" for r in history) >= 10, history


HUMBLE_WITHOUT_NAV2 = (
    "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported",
    ("--distro", "humble", "--navigate", "elsewhere"),
)
"""A Humble robot on rmw_zenoh with no navigation where its executor looks for it: nothing
answers the executor's distribution probe, and Jazzy's hash, the default, is not the one
its cmd_vel announces."""
HUMBLE_STAMPED = (
    "0/cmd_vel/geometry_msgs::msg::dds_::TwistStamped_/TypeHashNotSupported",
    ("--distro", "humble", "--cmd-vel-type", "stamped"),
)
"""A Humble robot on rmw_zenoh whose cmd_vel takes TwistStamped: neither the type nor the
hash is the default one."""


@pytest.mark.parametrize(
    ("case", "robot"),
    [
        ("executor-killed", HUMBLE_WITHOUT_NAV2),
        ("supervisor-started-after-executor-died", HUMBLE_STAMPED),
    ],
)
async def test_stop_on_rmw_zenoh_goes_to_the_key_the_robot_announced(
    case: str,
    robot: tuple[str, tuple[str, ...]],
    router: str,
    processes: Processes,
    tmp_path: Path,
) -> None:
    """On rmw_zenoh a robot's subscription hears only its own type and type hash, as its
    liveliness token announces them. Zero velocity from the supervisor and the client
    must go there, not to a key built from a guessed distribution or type: whether their
    executor learnt the key and died (`executor-killed`), or the supervisor never heard
    of an executor at all (it started after its executor died; it must not fall back to
    the bridge's keys)."""
    announced, sim_args = robot
    rig = StopRig(
        router,
        processes,
        tmp_path / "supervisor.sqlite3",
        transport=TransportKind.RMW_ZENOH,
        sim_args=sim_args,
    )
    with rig.client() as client:
        await rig.ready(client)
        assert rig.cmd_vel_keys == [announced]  # the stopwatch hears as the robot does
        stopped: Stopped
        if case == "executor-killed":
            await rig.submit(client, order("runaway"))
            await rig.driving()
            rig.kill(rig.executor)

            # Once the supervisor knows its executor is gone, the stop it confirms is its
            # own (a stop asked sooner tries to latch the dead executor, and rightly says
            # it could not): the key the zero velocity goes to is what this test is about.
            async def executor_lost() -> bool:
                reply = await client.ask(ROBOT, GetState())
                return isinstance(reply, StateReply) and not reply.state.executor_online

            await async_wait_until(executor_lost, 20.0, "the supervisor to lose its executor")
            asked = time.monotonic()
            stopped = await client.stop(ROBOT)
        else:
            rig.kill(rig.executor)
            rig.kill(rig.supervisor)
            rig.start_supervisor()

            async def supervisor_up() -> bool:
                try:
                    return isinstance(await client.ask(ROBOT, GetState()), StateReply)
                except BusError:
                    return False

            await async_wait_until(supervisor_up, 20.0, "the new supervisor")
            asked = time.monotonic()
            # The supervisor alone: this client's own stop is not asked.
            reply = await client.request(ROBOT, EmergencyStop())
            assert isinstance(reply, Stopped), reply
            stopped = reply
        # Heard there at all: a stop sent to another key never would be.
        await async_wait_until(
            lambda: rig.first_zero(asked) < math.inf, BOUND, "zero velocity on the robot's key"
        )
        print(case, rig.first_zero(asked), stopped)
        assert stopped.confirmed, stopped


async def test_a_stalled_event_loop_is_noticed_and_the_robot_halted(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """No STOP at all: an executor drives from a blocked loop, and the executor's own
    watchdog halts the robot once the loop has stalled for its limit (0.5 s)."""
    rig = StopRig(router, processes, tmp_path / "supervisor.sqlite3", stall_limit=0.5)

    with rig.client() as client:
        await rig.ready(client)
        block = 3 * BOUND  # long past the watchdog's limit, however busy the machine
        (order_id,) = await client.submit(ROBOT, [order("blockdrive", seconds=block)])
        await rig.driving()
        # Stopped by the watchdog, before the block ends.
        await async_wait_until(
            lambda: rig.odometry[-1][1].linear_x == 0.0, 2 * BOUND, "the watchdog to halt it"
        )
        halted = rig.odometry[-1][0]
        await asyncio.sleep(0.5)
        moved = [o for at, o in rig.odometry if at > halted]
        assert all(o.linear_x == 0.0 for o in moved), "it moved again"

        record = await ended(client, lambda r: r.id == order_id, "the stalled order to end")
        assert record.status == OrderStatus.FAILED, record
        assert "event loop stalled" in record.message, record


async def test_an_executor_back_at_once_leaves_no_order_running(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """An executor killed and started again within the supervisor's grace (as `voicectl
    up` restarts it) no longer runs the order: the order ends, the robot stands."""
    rig = StopRig(router, processes, tmp_path / "supervisor.sqlite3")

    with rig.client() as client:
        await rig.ready(client)
        (order_id,) = await client.submit(ROBOT, [order("runaway")])
        await rig.driving()
        rig.kill(rig.executor)
        rig.start_executor()

        record = await ended(client, lambda r: r.id == order_id, "the order to end")
        assert record.status in (OrderStatus.FAILED, OrderStatus.INTERRUPTED), record
        await async_wait_until(
            lambda: rig.odometry[-1][1].linear_x == 0.0, 5.0, "the robot to stand"
        )
        # The executor started again serves again (and is up before the test stops it).
        await rig.ready(client)


async def test_a_stop_for_a_robot_nobody_serves_creates_none(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """A made-up name is refused by the supervisor without becoming a robot; the client,
    knowing no keys for it either, says that nothing was stopped."""
    rig = StopRig(router, processes, tmp_path / "supervisor.sqlite3")

    with joined(router) as bus:
        rig.listen(bus)
        client = VoicectlClient(bus)
        await rig.ready(client)
        for name in ("nobody", "made-up-2"):
            reply = await client.request(name, EmergencyStop())
            assert isinstance(reply, Failed), reply
            assert f"no executor has served robot '{name}'" in reply.reason
            with pytest.raises(Unreachable, match="nothing stopped"):
                await client.stop(name)
        # Neither STOP made it a robot: the supervisor still knows only r1.
        known = await client.request("nobody", Release())
        assert isinstance(known, Failed), known
        assert "(known robots: r1)" in known.reason, known


async def test_the_stop_codec_is_built_when_an_executor_announces_itself_not_at_stop(
    router: str,
) -> None:
    """Building a distribution's types and encoders took the first STOP of a process
    about 0.1 s before zero velocity went out (bench/e2e.py); now whoever may stop a
    robot prepares it when the executor announces it, off the event loop."""
    stop_codec.cache_clear()
    info = ExecutorInfo(distro=RosDistro.HUMBLE, cmd_vel_type=CmdVelType.STAMPED)

    with joined(router) as bus:
        await prepare(info)
        built = stop_codec.cache_info().misses
        stop = RobotStop.of(info, bus)
        assert stop_codec.cache_info().misses == built  # nothing built at STOP time
        assert stop.codec is stop_codec(RosDistro.HUMBLE)
        stamped = stop.codec.velocity(stop.cmd_vel_type, 0.0, 0.0, 1.0)
        assert stop.codec.read_twist_stamped(stamped) == (0.0, 0.0)
    # A robot no executor announced is stopped with one codec, whatever its distribution.
    humble, jazzy = stop_codec(RosDistro.HUMBLE), stop_codec(RosDistro.JAZZY)
    for kind in CmdVelType:
        assert humble.velocity(kind, 0.0, 0.0, 1.0) == jazzy.velocity(kind, 0.0, 0.0, 1.0)
    assert humble.cancel_goal_request() == jazzy.cancel_goal_request()


async def test_the_executor_latch_says_what_no_answer_means(router: str) -> None:
    """The supervisor knows whether its executor is online: one that is not is not asked,
    and one that is but does not answer has failed (its order may still run). A client
    cannot know: no answer means no executor, and a dead executor commands nothing."""
    keys, decode = RobotKeys(ROBOT), json_decoder(ExecutorReply)
    with joined(router) as bus:
        offline = ExecutorLatch(bus, keys, decode, 1.0, online=lambda: False)
        assert await offline.latch() == LatchAnswer("no executor online", safe=True)
        assert await offline.release() == ""
        silent = await ExecutorLatch(bus, keys, decode, 1.0, online=lambda: True).latch()
        assert silent.detail.startswith("EXECUTOR: executor unreachable: "), silent
        assert (silent.safe, silent.failed) == (False, True), silent
        unknown = await ExecutorLatch(bus, keys, decode, 1.0).latch()
        dead = "no executor answered (a dead executor commands nothing)"
        assert unknown == LatchAnswer(dead, safe=True)


def test_a_stop_is_confirmed_once_navigation_and_the_executor_have_answered() -> None:
    sent = "sent zero velocity on 'cmd_vel'"
    cancelled = Cancelled(True, True, "navigation cancelled every goal")
    latched = LatchAnswer("executor: latched", safe=True)
    waiting = StopOutcome(sent, None, None)
    assert not waiting.settled
    assert not waiting.confirmed
    assert waiting.detail == (
        f"{sent}; navigation has not answered the cancel yet; the executor has not answered yet"
    )
    done = StopOutcome(sent, cancelled, latched)
    assert done.settled
    assert done.confirmed
    assert done.detail == f"{sent}; navigation cancelled every goal; executor: latched"
    # No navigation at all (a robot driven by cmd_vel alone): zero velocity is all.
    silent = Cancelled(False, False, "navigation did not answer the cancel of every goal")
    assert StopOutcome(sent, silent, latched).confirmed
    refused = Cancelled(True, False, "navigation refused to cancel every goal")
    assert not StopOutcome(sent, refused, latched).confirmed
    stuck = LatchAnswer("EXECUTOR: stuck", safe=False, failed=True)
    assert not StopOutcome(sent, cancelled, stuck).confirmed
    assert not StopOutcome(sent, None, latched).confirmed
