"""Supervisor overhead: submit round trip, submit-to-dispatch latency and orders accepted
per second with durability on, beside a raw Zenoh request/reply measured in the same run,
and a raw Zenoh relay (a query that sends a query on: the two hops of a submit and its
dispatch, with nothing in between), from Zenoh's thread and from an event loop's. The
latencies are taken in turn, one of each after the same pause.

    .venv/bin/python -m bench.supervisor [--orders 10000] [--durability process|power] [--quick]

Everything runs on loopback: a router and the supervisor as their own processes, a raw
echo and relay queryable as its own process (the baselines), and this process as client
and as the robot's executor (it accepts every order and reports it done at once).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import subprocess
import sys
import tempfile
import time

import zenoh

from harness.measure import cpu_seconds, percentile
from harness.ports import free_port
from harness.processes import REPO
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.errors import BusError
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import (
    Accepted,
    ControlRequest,
    Done,
    Execute,
    ExecutorRequest,
    GetState,
    Message,
    Order,
    OrderFinished,
    OrderStatus,
    StateReply,
    Submit,
    Submitted,
    SupervisorReply,
)

ECHO = """
import sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", '["%s"]')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/timeout_ms", "-1")
with zenoh.open(conf) as session:
    def echo(query):
        query.reply(query.key_expr, query.payload.to_bytes() if query.payload is not None else b"")
    # Replies to the relayed query are not waited for, on Zenoh's own thread (a plain
    # function would start a Python thread for each query).
    ignore = zenoh.handlers.Callback(lambda reply: None, indirect=False)
    def relay(query):
        session.get("bench/relayed", ignore, payload=query.payload.to_bytes())
        query.reply(query.key_expr, b"")
    # The same, sent on from an event loop's thread, as a service whose state one loop
    # owns must: the floor for the supervisor's dispatch.
    import asyncio, threading
    loop = asyncio.new_event_loop()
    threading.Thread(target=loop.run_forever, daemon=True).start()
    def send_on(payload):
        session.get("bench/relayed", ignore, payload=payload)
    def loop_relay(query):
        loop.call_soon_threadsafe(send_on, query.payload.to_bytes())
        query.reply(query.key_expr, b"")
    queryable = session.declare_queryable("bench/echo", echo)
    relayer = session.declare_queryable("bench/relay", relay)
    loop_relayer = session.declare_queryable("bench/loop-relay", loop_relay)
    print("ready", flush=True)
    sys.stdin.read()
"""

PAUSE = 0.001
"""Between two timed requests: an order has finished by then."""


class CpuUse:
    """CPU time per request of the processes taking part in a burst."""

    def __init__(self, pids: dict[str, int]) -> None:
        self._pids = pids
        self._start = {name: cpu_seconds(pid) for name, pid in pids.items()}
        self._own = time.process_time()

    def per_request(self, count: int) -> str:
        used = {name: cpu_seconds(pid) - self._start[name] for name, pid in self._pids.items()}
        used["this client"] = time.process_time() - self._own
        return ", ".join(f"{name} {seconds / count * 1e6:.0f}" for name, seconds in used.items())


def describe(name: str, seconds: list[float]) -> tuple[float, float]:
    p50, p99 = percentile(seconds, 0.5) * 1e3, percentile(seconds, 0.99) * 1e3
    print(f"{name:<42} p50 {p50:7.3f} ms   p99 {p99:7.3f} ms   (n={len(seconds)})")
    return p50, p99


async def raw_round_trip(bus: Bus) -> float:
    start = time.perf_counter()
    await bus.request_bytes("bench/echo", b"x" * 200, 5.0)
    return time.perf_counter() - start


class Relay:
    """From a query to a relay (`through` one of its keys) to the relayed query's handler
    here, as an order's arrival at the executor is timed."""

    def __init__(self, bus: Bus) -> None:
        self._bus = bus
        self._arrivals: dict[bytes, float] = {}
        self._arrived = asyncio.Event()

    async def start(self) -> None:
        self._bus.serve_bytes("bench/relayed", self._on_relayed)
        for through in ("bench/relay", "bench/loop-relay"):
            for attempt in range(100):  # until the relay's query finds this queryable
                with contextlib.suppress(TimeoutError, BusError):
                    tag = f"warm-up-{through}-{attempt}".encode()
                    await asyncio.wait_for(self.time(through, tag), 0.1)
                    break

    async def _on_relayed(self, payload: bytes) -> bytes:
        self._arrivals[payload] = time.perf_counter()
        self._arrived.set()
        return b""

    async def time(self, through: str, tag: bytes) -> float:
        start = time.perf_counter()
        await self._bus.request_bytes(through, tag, 5.0)
        while tag not in self._arrivals:  # a relayed query lost ends the run, not hangs it
            self._arrived.clear()
            await asyncio.wait_for(self._arrived.wait(), 5.0)
        return self._arrivals[tag] - start


class FakeExecutor:
    """The robot's executor for the benchmark: takes every order, finishes it at once."""

    def __init__(self, bus: Bus, robot: str) -> None:
        self.bus = bus
        self.keys = RobotKeys(robot)
        self.arrivals: dict[str, float] = {}
        self.arrived = asyncio.Event()

    def start(self) -> None:
        self.bus.serve(self.keys.executor_execute, json_decoder(Execute), self.handle)
        self.bus.serve(self.keys.executor_control, json_decoder(ControlRequest), self.handle)
        self.bus.announce(self.keys.alive("executor"))

    async def handle(self, request: ExecutorRequest) -> Message:
        match request:
            case Execute(order_id=order_id):
                self.arrivals[order_id] = time.perf_counter()
                self.arrived.set()
                asyncio.get_running_loop().call_soon(self._finish, order_id)
                return Accepted(order_id=order_id)
        return Done()

    def _finish(self, order_id: str) -> None:
        self.bus.publish(
            self.keys.executor_events,
            OrderFinished(order_id=order_id, status=OrderStatus.SUCCEEDED, message="ok"),
        )


async def wait_for_executor(bus: Bus, keys: RobotKeys) -> None:
    decode = json_decoder(SupervisorReply)
    for _ in range(400):
        try:
            reply = await bus.request(keys.supervisor, GetState(), decode, 2.0)
            if isinstance(reply, StateReply) and reply.state.executor_online:
                return
        except BusError:
            pass
        await asyncio.sleep(0.05)
    raise SystemExit("the supervisor never saw the benchmark's executor")


async def measure(router: str, orders: int, round_trips: int, pids: dict[str, int]) -> None:
    options = BusOptions(connect=[router])
    order = Order(order="bench", label="bench", description="bench")
    decode = json_decoder(SupervisorReply)
    with Bus.open(options, asyncio.get_running_loop()) as bus:
        for _ in range(100):  # until the echo's queryable has reached the router
            try:
                await bus.request_bytes("bench/echo", b"warm-up", 5.0)
                break
            except BusError:
                await asyncio.sleep(0.1)
        relay = Relay(bus)
        await relay.start()
        executor = FakeExecutor(bus, "bench")
        executor.start()
        keys = RobotKeys("bench")
        await wait_for_executor(bus, keys)

        # One of each in turn, so that the load of the machine, which changes over a run,
        # weighs on the baselines and on the supervisor alike; each after the same pause,
        # so that none finds the processes busier or idler than the others do.
        raw: list[float] = []
        relayed: list[float] = []
        loop_relayed: list[float] = []
        submit_times: list[float] = []
        dispatch_times: list[float] = []
        for i in range(round_trips):
            await asyncio.sleep(PAUSE)
            raw.append(await raw_round_trip(bus))
            await asyncio.sleep(PAUSE)
            relayed.append(await relay.time("bench/relay", f"relay-{i}".encode()))
            await asyncio.sleep(PAUSE)
            loop_relayed.append(await relay.time("bench/loop-relay", f"loop-{i}".encode()))
            await asyncio.sleep(PAUSE)  # the order before has finished by now
            start = time.perf_counter()
            reply = await bus.request(
                keys.supervisor, Submit(request_id=f"rt{i}", orders=[order]), decode, 5.0
            )
            submit_times.append(time.perf_counter() - start)
            assert isinstance(reply, Submitted), reply
            (order_id,) = reply.order_ids
            while order_id not in executor.arrivals:
                executor.arrived.clear()
                await executor.arrived.wait()
            dispatch_times.append(executor.arrivals[order_id] - start)

        # Throughput: a robot without an executor, so every order stays queued (and stored);
        # beside it, the same number of raw requests to the echo, as many in flight.
        burst = RobotKeys("burst")
        in_flight = 64
        accepted = 0
        echoed = 0

        async def echo_worker(first: int) -> None:
            nonlocal echoed
            for _ in range(first, orders, in_flight):
                await bus.request_bytes("bench/echo", b"x" * 200, 10.0)
                echoed += 1

        cpu = CpuUse({"echo": pids["echo"], "router": pids["router"]})
        start = time.perf_counter()
        await asyncio.gather(*(echo_worker(k) for k in range(in_flight)))
        raw_rate = echoed / (time.perf_counter() - start)
        raw_cpu = cpu.per_request(echoed)

        async def worker(first: int) -> None:
            nonlocal accepted
            for i in range(first, orders, in_flight):
                reply = await bus.request(
                    burst.supervisor, Submit(request_id=f"b{i}", orders=[order]), decode, 10.0
                )
                assert isinstance(reply, Submitted), reply
                accepted += 1

        cpu = CpuUse({"supervisor": pids["supervisor"], "router": pids["router"]})
        start = time.perf_counter()
        await asyncio.gather(*(worker(k) for k in range(in_flight)))
        elapsed = time.perf_counter() - start
        order_cpu = cpu.per_request(accepted)

    print()
    raw50, _ = describe("raw Zenoh request/reply (baseline)", raw)
    rel50, _ = describe("raw Zenoh query relayed to here", relayed)
    loop50, _ = describe("the same, relayed from an event loop", loop_relayed)
    sub50, _ = describe("supervisor submit round trip", submit_times)
    dis50, _ = describe("submit to dispatch (order at the executor)", dispatch_times)
    print(f"{'raw Zenoh requests per second (64 in flight)':<42} {raw_rate:9.0f} /s  (baseline)")
    print(f"{'orders accepted per second (64 in flight)':<42} {accepted / elapsed:9.0f} /s")
    print(f"{'orders accepted / raw requests per second':<42} {accepted / elapsed / raw_rate:9.2f}")
    print(f"CPU per raw request, us: {raw_cpu}")
    print(f"CPU per order, us:       {order_cpu}")
    print(f"{'submit / raw round trip (p50)':<42} {sub50 / raw50:9.2f} x")
    print(f"{'submit-to-dispatch / raw round trip (p50)':<42} {dis50 / raw50:9.2f} x")
    print(f"{'raw relay / raw round trip (p50)':<42} {rel50 / raw50:9.2f} x")
    print(f"{'relay from a loop / raw round trip (p50)':<42} {loop50 / raw50:9.2f} x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--orders", type=int, default=10_000, help="orders in the burst")
    parser.add_argument("--round-trips", type=int, default=1000)
    parser.add_argument("--durability", choices=["process", "power"], default="process")
    parser.add_argument("--quick", action="store_true", help="2,000 orders, 200 round trips")
    args = parser.parse_args()
    if args.quick:
        args.orders, args.round_trips = 2000, 200
    router = f"tcp/127.0.0.1:{free_port()}"
    with tempfile.TemporaryDirectory() as tmp:
        python = sys.executable
        children = [
            subprocess.Popen(
                [python, "-m", "voicectl.services.router", "--listen", router], cwd=REPO
            ),
            subprocess.Popen(
                [
                    python,
                    "-m",
                    "voicectl.services.supervisor",
                    "--connect",
                    router,
                    "--db",
                    f"{tmp}/bench.sqlite3",
                    "--durability",
                    args.durability,
                    # Served from the start: "burst" never has an executor, and keeps
                    # the whole burst queued.
                    *("--robot", "bench", "--robot", "burst"),
                    *("--max-queue", str(max(args.orders, 1000))),
                ],
                cwd=REPO,
                stderr=subprocess.DEVNULL,
            ),
        ]
        echo = subprocess.Popen(
            [python, "-c", ECHO % router], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
        )
        try:
            assert echo.stdout is not None
            echo.stdout.readline()
            print(
                f"zenoh {zenoh.__version__ if hasattr(zenoh, '__version__') else ''}, "
                f"durability {args.durability}, {args.orders} orders in the burst"
            )
            pids = {"router": children[0].pid, "supervisor": children[1].pid, "echo": echo.pid}
            asyncio.run(measure(router, args.orders, args.round_trips, pids))
        finally:
            if echo.stdin is not None:
                echo.stdin.close()
            echo.wait(timeout=10)
            for child in reversed(children):
                child.terminate()
                child.wait(timeout=10)


if __name__ == "__main__":
    main()
