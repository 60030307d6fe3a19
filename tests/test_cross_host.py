"""voicectl across two hosts: Linux network namespaces joined by a veth pair (harness/netns.py).

On the host: a router listening on the link, and the supervisor. On the robot: a router
connected to the host's across the link, the executor and the simulator. Every process
has a 2 s Zenoh lease. The test joins each side's router through a Unix socket, as a
process on that host would: it submits orders and reads state on the host, and reads the
simulator's odometry on the robot, so that the robot's motion is seen where it happens,
even while the link is down.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

from harness.client import Client, client_wait_ready
from harness.cross_host import RobotWatch, observer, start_stack
from harness.netns import LEASE_MS, TwoHosts, impairment_unavailable, unavailable
from voicectl.shared.messages import EmergencyStop, Order, OrderStatus, Stopped, TargetPose

from .conftest import cannot_run
from .support import joined, order

WHY_NOT = unavailable()

LEASE = LEASE_MS / 1000
FAR = Order(
    order="goal",
    label="mbgoal",
    description="reach far",
    target_pose=TargetPose(frame="map", x=8.0, y=0.0),
)
STOP_BOUND = 2.0
"""Seconds from STOP to zero velocity across a 100 ms, 5 % loss link: one crossing plus a
simulator tick is about 0.15 s; lost packets cost TCP retransmissions of 0.2 s and more."""


@pytest.fixture
def rig(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[TwoHosts]:
    if WHY_NOT is not None:
        cannot_run(f"two hosts: {WHY_NOT}")
    hosts = TwoHosts(tmp_path / "logs")
    try:
        start_stack(hosts, tmp_path / "supervisor.sqlite3")
        yield hosts
    finally:
        unclean = hosts.close()
        report = getattr(request.node, "rep_call", None)
        if report is None or report.failed:
            print(hosts.dump())
    assert not unclean, f"processes did not stop cleanly: {unclean}\n{hosts.dump()}"


@contextlib.asynccontextmanager
async def session(rig: TwoHosts) -> AsyncIterator[tuple[Client, RobotWatch]]:
    """The supervisor's client on the host and the robot's odometry read on the robot,
    once the supervisor sees the executor across the link."""
    with joined(observer(rig, "host")) as host, joined(observer(rig, "robot")) as robot:
        client, watch = Client(host, "r1"), RobotWatch(robot)
        await client_wait_ready(client)
        await watch.ready()
        yield client, watch


async def test_orders_run_across_the_link(rig: TwoHosts) -> None:
    async with session(rig) as (client, watch):
        (product,) = await client.submit(order("mul", first=6, second=7))
        assert (await client.finished(product)).message == "6 x 7 = 42"
        start = watch.last.pose.x
        (driven,) = await client.submit(order("drive", distance=0.5))
        record = await client.finished(driven)
        assert (record.status, record.message) == (OrderStatus.SUCCEEDED, "drove 0.5 m")
        assert watch.last.pose.x - start == pytest.approx(0.5, abs=0.05)


async def test_a_link_down_past_the_lease_stops_the_robot_and_loses_no_order(rig: TwoHosts) -> None:
    async with session(rig) as (client, watch):
        moving, sibling = await client.submit(FAR, order("mul", first=2, second=2))
        (after,) = await client.submit(order("mul", first=3, second=3))
        await watch.moving()
        with rig.link_down():
            cut = time.monotonic()
            # The robot's side: the executor loses the supervisor after the lease, and
            # stops the robot itself (the supervisor's own stop cannot cross the link).
            took = await watch.stopped(cut, timeout=LEASE + 10.0)
            print(f"link cut to zero velocity on odom: {took:.2f} s (lease {LEASE:g} s)")
            assert took < LEASE + 3.0
            stood = watch.last.pose
            assert stood.x < 6.0
            # The host's side: the order failed, the rest of its command was dropped, and
            # the queue is held until the executor is back.
            record = await client.finished(moving)
            assert (record.status, record.message) == (
                OrderStatus.FAILED,
                "executor lost; halting the robot",
            )
            assert (await client.finished(sibling)).status == OrderStatus.CANCELLED
            state = await client.state()
            assert not state.executor_online
            assert state.current is None
            assert [r.id for r in state.queue] == [after]
            assert abs(watch.last.pose.x - stood.x) < 0.01, "it moved with the link down"

        # The robot's router reconnects; the queue runs on (nothing was paused).
        await client.wait_state(lambda s: s.executor_online, "the executor to be back")
        assert (await client.finished(after)).message == "3 x 3 = 9"
        ids = [r.id for r in (await client.history()).records]
        assert sorted(ids) == sorted([moving, sibling, after])  # none lost, none twice
        assert abs(watch.last.pose.x - stood.x) < 0.01, "it moved again"
        log = rig.log("executor")
        assert log.count(f"supervisor lost while order {moving}") == 1
        assert "supervisor back" in log


@pytest.fixture
def impairable() -> None:
    """The link can be made slow and lossy here (asked before the hosts are made)."""
    if (why := impairment_unavailable()) is not None:
        cannot_run(why)


async def test_a_slow_lossy_link_still_runs_orders_and_stops_the_robot(
    impairable: None, rig: TwoHosts
) -> None:
    async with session(rig) as (client, watch):
        with rig.impaired(delay_ms=100, loss_percent=5):
            ids = await client.submit(
                order("mul", first=1, second=2),
                order("drive", distance=0.3),
                order("mul", first=3, second=4),
                order("rotate", angle=0.5),
            )
            for order_id in ids:
                assert (await client.finished(order_id)).status == OrderStatus.SUCCEEDED
            assert [r.id for r in (await client.history()).records] == ids[::-1]

            (moving,) = await client.submit(FAR)
            await watch.moving()
            sent = time.monotonic()
            assert isinstance(await client.ask(EmergencyStop()), Stopped)
            took = await watch.stopped(sent, timeout=10.0)
            print(f"emergency stop across 100 ms / 5 % loss: {took * 1000:.0f} ms to zero on odom")
            assert took < STOP_BOUND
            stood = watch.last.pose
            record = await client.finished(moving)
            assert (record.status, record.message) == (OrderStatus.CANCELLED, "emergency stop")
            assert (await client.state()).stopped
            await asyncio.sleep(1.0)  # a window to watch it stand
            assert abs(watch.last.pose.x - stood.x) < 0.01, "it moved again"
