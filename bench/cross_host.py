"""Emergency stop across a slow, lossy link, beside a raw Zenoh round trip on the same link.

    sudo .venv/bin/python -m bench.cross_host [--stops 20] [--pings 200] [--delay-ms 100] [--loss 5]

Two network namespaces joined by a veth pair (harness/netns.py): on the host, a router and
the supervisor; on the robot, a router connected to the host's, the executor, the
simulator and a raw Zenoh echo. Every packet crossing the link, either way, is delayed by
--delay-ms and lost with --loss % probability. Measured in the same run:

- raw Zenoh: a put on the host, put back by the echo on the robot, received on the host
  (the link crossed twice);
- emergency stop: from sending EmergencyStop to the supervisor, on the host, to the
  simulator's odometry, read on the robot, showing zero velocity, while a `drive` order
  moves the robot. The simulator publishes odometry at 20 Hz: up to 50 ms of each figure
  is its tick.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import statistics
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import zenoh

from harness.cross_host import ROBOT, RobotWatch, observer, start_stack
from harness.netns import LEASE_MS, TwoHosts, impairment_unavailable, unavailable
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Done,
    EmergencyStop,
    GetHistory,
    GetState,
    HistoryPage,
    Message,
    Order,
    Release,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
)

PING, PONG = "bench/cross_host/ping", "bench/cross_host/pong"


class Operator:
    """The supervisor's client on the host."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.keys = RobotKeys(ROBOT)
        self._decode = json_decoder(SupervisorReply)

    async def ask(self, request: Message, timeout: float = 10.0) -> SupervisorReply:
        reply: SupervisorReply = await self.bus.request(
            self.keys.supervisor, request, self._decode, timeout
        )
        return reply

    async def ready(self, timeout: float = 60.0) -> None:
        """Until the supervisor answers and sees the executor, across the link."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                state = await self.ask(GetState(), timeout=2.0)
                if isinstance(state, StateReply) and state.state.executor_online:
                    return
            except BusError:
                pass  # not up yet
            if time.monotonic() > deadline:
                raise TimeoutError("the supervisor never saw the executor across the link")
            await asyncio.sleep(0.1)

    async def submit(self, *orders: Order) -> list[str]:
        reply = await self.ask(Submit(request_id=uuid.uuid4().hex, orders=list(orders)))
        assert isinstance(reply, Submitted), reply
        return reply.order_ids

    async def finished(self, order_id: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while True:
            page = await self.ask(GetHistory(limit=20))
            if isinstance(page, HistoryPage) and any(r.id == order_id for r in page.records):
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"order {order_id} never finished")
            await asyncio.sleep(0.05)


def drive(distance: float) -> Order:
    return Order(
        order="drive",
        label="drive",
        description=f"drive {distance:g} m",
        params={"distance": distance},
    )


async def round_trips(bus: Bus, count: int) -> list[float]:
    """Raw Zenoh: put on the host, the robot's echo puts it back; seconds per round."""
    arrived: dict[bytes, float] = {}
    got = threading.Event()

    def on_pong(sample: zenoh.Sample) -> None:
        arrived[sample.payload.to_bytes()] = time.monotonic()
        got.set()

    subscriber = bus.session.declare_subscriber(PONG, on_pong)
    try:
        for _ in range(100):  # until the echo answers at all (its routes are in place)
            got.clear()
            bus.session.put(PING, b"warm-up")
            if await asyncio.to_thread(got.wait, 0.5):
                break
        else:
            raise TimeoutError("the echo on the robot never answered")
        times = []
        for i in range(count):
            payload = f"{i:08d}".encode() + b"x" * 92
            got.clear()
            sent = time.monotonic()
            bus.session.put(PING, payload)
            while payload not in arrived:
                if not await asyncio.to_thread(got.wait, 10.0):
                    raise TimeoutError(f"ping {i} never came back")
                got.clear()
            times.append(arrived[payload] - sent)
        return times
    finally:
        subscriber.undeclare()


async def stop_latencies(operator: Operator, watch: RobotWatch, count: int) -> list[float]:
    """`count` emergency stops of a driving robot: seconds from each STOP sent on the host
    to zero velocity on the robot's odometry."""
    latencies = []
    for i in range(count):
        (order_id,) = await operator.submit(drive(3.0 if i % 2 == 0 else -3.0))
        await watch.moving()
        sent = time.monotonic()
        reply = await operator.ask(EmergencyStop())
        assert isinstance(reply, Done), reply
        latencies.append(await watch.stopped(sent, timeout=10.0))
        await operator.finished(order_id)
        assert isinstance(await operator.ask(Release()), Done)
    return latencies


def describe(name: str, seconds: list[float]) -> dict[str, float]:
    ms = sorted(s * 1000 for s in seconds)
    figures = {
        "min": ms[0],
        "p50": statistics.median(ms),
        "p90": ms[min(len(ms) - 1, int(0.9 * len(ms)))],
        "max": ms[-1],
    }
    shown = "   ".join(f"{key} {value:7.1f} ms" for key, value in figures.items())
    print(f"{name:<44} {shown}   (n={len(ms)})")
    return figures


def echo(connect: str) -> None:
    """The robot's raw echo: every ping put back as a pong, until SIGTERM."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
    options = BusOptions(connect=[connect], lease_ms=LEASE_MS)
    with zenoh.open(options.zenoh_config()) as session:
        subscriber = session.declare_subscriber(
            PING, lambda sample: session.put(PONG, sample.payload.to_bytes())
        )
        print("ready", flush=True)
        signal.sigwait({signal.SIGTERM, signal.SIGINT})
        subscriber.undeclare()


async def measure(rig: TwoHosts, args: argparse.Namespace) -> dict[str, object]:
    start_stack(rig, rig.logs / "supervisor.sqlite3")
    rig.start("robot", "bench.cross_host", "--echo", rig.local_router(), name="echo")
    loop = asyncio.get_running_loop()
    with (
        Bus.open(observer(rig, "host"), loop) as host,
        Bus.open(observer(rig, "robot"), loop) as robot,
    ):
        operator, watch = Operator(host), RobotWatch(robot)
        await operator.ready()
        await watch.ready()
        with rig.impaired(args.delay_ms, args.loss):
            print(f"link: {args.delay_ms:g} ms each way, {args.loss:g} % loss each way")
            raw = await round_trips(host, args.pings)
            stops = await stop_latencies(operator, watch, args.stops)
    return {
        "link": {"delay_ms": args.delay_ms, "loss_percent": args.loss},
        "raw_round_trip_ms": describe("raw Zenoh put round trip, host-robot-host", raw),
        "stop_ms": describe("emergency stop to zero velocity on odometry", stops),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stops", type=int, default=20)
    parser.add_argument("--pings", type=int, default=200)
    parser.add_argument("--delay-ms", type=float, default=100.0, help="each way (default 100)")
    parser.add_argument("--loss", type=float, default=5.0, metavar="PERCENT", help="each way")
    parser.add_argument("--json", action="store_true", help="also print the figures as JSON")
    parser.add_argument("--echo", metavar="ENDPOINT", help=argparse.SUPPRESS)  # the robot's echo
    parser.add_argument("--quick", action="store_true", help="5 stops, 50 pings")
    args = parser.parse_args()
    if args.quick:
        args.stops, args.pings = 5, 50
    if args.echo:
        echo(args.echo)
        return 0
    why = unavailable() or impairment_unavailable()
    if why:
        print(f"bench/cross_host.py: {why}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="cross-host-") as work:
        rig = TwoHosts(Path(work))
        try:
            figures = asyncio.run(measure(rig, args))
        except BaseException:
            print(rig.dump(), file=sys.stderr)
            raise
        finally:
            rig.close()
    if args.json:
        print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
