"""One site, many robots: one router, one converter and one supervisor serving N robots,
each with its own simulator and executor as processes, every robot given an order every
few seconds while one person presses STOP on one of them.

    .venv/bin/python -m bench.fleet [--robots 50] [--seconds 60] [--period 3] [--per-process K]
                                    [--quick]

Each robot's cycle: submit a turn (as the panel's Send does) and time it to the first
motion command at that robot's simulator (its navigation goal accepted, or a non-zero
cmd_vel); then cancel it, except on the first robot, which gets STOP instead, timed to
zero velocity on its cmd_vel, then a release. Reported: Send -> first motion over every
robot (p50/p99, and the worst robot's p99), STOP -> zero velocity, and the CPU share and
resident memory of the supervisor and the router over the measured window, beside the
raw Zenoh put -> subscriber time through the same router. --quick: 3 robots for 8 s.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

from harness.measure import MOTION_WAIT, Robot, cpu_seconds, line, percentile, raw_latency
from harness.ports import free_port
from harness.processes import REPO, rss_mb
from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.client import Unreachable, VoicectlClient
from voicectl.shared.errors import BusError
from voicectl.shared.messages import (
    CancelAll,
    GetState,
    Order,
    ParseResult,
    Release,
    StateReply,
    Submit,
    Submitted,
)
from voicectl.shared.robot.keys import RobotNames


class Fleet:
    """The site's processes: a router, a converter, a supervisor, and per robot a
    simulator and an executor; their data and their logs in directories of their own."""

    def __init__(self, robots: int, data: Path, logs: Path, per_process: int = 0) -> None:
        self.names = [f"bot{k}" for k in range(robots)]
        self.per_process = per_process
        """Robots per bench/robots.py process; 0: two processes per robot, as on a site."""
        self.router = f"tcp/127.0.0.1:{free_port()}"
        self.logs = logs
        self.data = data
        self.processes: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, name: str, *args: str, program: tuple[str, ...] = ("-m", "voicectl")) -> None:
        log = (self.logs / f"{name}.log").open("wb")
        self.processes[name] = subprocess.Popen(
            [sys.executable, *program, *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=REPO,
            env={
                **os.environ,
                "VOICECTL_DATA": str(self.data),
                "PYTHONUNBUFFERED": "1",
                # Each service ends when this process does, however it ends.
                "VOICECTL_PARENT": str(os.getpid()),
            },
        )

    def up(self) -> None:
        connect = ("--connect", self.router)
        self.start("router", "router", "--listen", self.router)
        time.sleep(1.0)
        self.start("converter", "converter", *connect)
        self.start("supervisor", "supervisor", *connect)
        if self.per_process:
            for first in range(0, len(self.names), self.per_process):
                group = self.names[first : first + self.per_process]
                robots = ("-m", "bench.robots")
                self.start(f"robots-{first}", *connect, *group, program=robots)
            return
        for name in self.names:
            self.start(f"sim-{name}", "sim", "--namespace", name, *connect)
        for name in self.names:
            self.start(
                f"executor-{name}", "executor", "--robot", name, "--namespace", name, *connect
            )

    def stop(self) -> None:
        for process in self.processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + 60
        for process in self.processes.values():
            try:
                process.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@dataclass
class Results:
    to_motion: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))
    """Send -> first motion, by robot."""
    to_zero: list[float] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


async def measure(
    fleet: Fleet, seconds: float, period: float
) -> tuple[Results, list[float], dict[str, float]]:
    loop = asyncio.get_running_loop()
    options = BusOptions(connect=[fleet.router])
    # The robots are watched from a session of their own, as a simulator is: the STOP's
    # zero velocity, sent from the client's session, is timed across the router.
    with Bus.open(options, loop) as bus, Bus.open(options, loop) as watching:
        client = VoicectlClient(bus)
        watched = {name: Robot() for name in fleet.names}
        for name, robot in watched.items():
            robot.listen(watching, RobotNames(name))
        await ready(client, fleet.names)
        (turn,) = (await parsed(client, "turn left")).orders
        raw = await raw_latency(bus)
        results = Results()
        pids = {n: fleet.processes[n].pid for n in ("supervisor", "router")}
        cpu = {n: cpu_seconds(p) for n, p in pids.items()}
        robot_side = [
            p.pid
            for n, p in fleet.processes.items()
            if n.startswith(("sim-", "executor-", "robots-"))
        ]
        robots_cpu = sum(cpu_seconds(p) for p in robot_side)
        began = time.monotonic()
        end = began + seconds
        await asyncio.gather(
            *(
                cycle(client, watched[name], name, turn, (end, period), index == 0, results)
                for index, name in enumerate(fleet.names)
            )
        )
        elapsed = time.monotonic() - began
        usage = {f"{n} CPU %": 100 * (cpu_seconds(p) - cpu[n]) / elapsed for n, p in pids.items()}
        usage["simulators and executors CPU %"] = (
            100 * (sum(cpu_seconds(p) for p in robot_side) - robots_cpu) / elapsed
        )
        usage |= {f"{n} RSS MB": rss_mb(p) for n, p in pids.items()}
        usage |= {f"{n} peak RSS MB": rss_mb(p, "VmHWM") for n, p in pids.items()}
    return results, raw, usage


async def ready(client: VoicectlClient, names: list[str], timeout: float = 600.0) -> None:
    """Until the supervisor sees every robot's executor."""
    deadline = time.monotonic() + timeout
    waiting = set(names)
    while waiting:
        for name in sorted(waiting):
            try:
                reply = await client.request(name, GetState())
            except BusError:
                continue
            if isinstance(reply, StateReply) and reply.state.executor_online:
                waiting.discard(name)
        if time.monotonic() > deadline:
            sys.exit(f"executors not online after {timeout:g} s: {sorted(waiting)[:10]}")
        await asyncio.sleep(0.5)


async def parsed(client: VoicectlClient, text: str, timeout: float = 120.0) -> ParseResult:
    """`text` parsed, once the converter answers (it loads every language's orders first)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            return await client.parse(text)
        except Unreachable:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.5)


async def cycle(
    client: VoicectlClient,
    robot: Robot,
    name: str,
    turn: Order,
    timing: tuple[float, float],
    stopping: bool,
    results: Results,
) -> None:
    """One robot's orders until the end of `timing` (end, period): submit, first motion,
    then cancel (or STOP)."""
    end, period = timing
    problems = results.problems
    await asyncio.sleep(random.uniform(0, period))
    while time.monotonic() < end:
        started = time.monotonic()
        sent = time.monotonic()
        reply = await client.request(name, Submit(request_id=uuid.uuid4().hex, orders=[turn]))
        if not isinstance(reply, Submitted):
            problems.append(f"{name}: submit answered {reply}")
        else:
            moved = await robot.first(robot.moved, sent)
            if moved is None:
                problems.append(f"{name}: no motion within {MOTION_WAIT:g} s")
            else:
                results.to_motion[name].append(moved - sent)
        if stopping:
            asked = time.monotonic()
            await client.stop(name)
            zero = await robot.first(robot.zero, asked)
            if zero is None:
                problems.append(f"{name}: no zero velocity after STOP")
            else:
                results.to_zero.append(zero - asked)
            await client.request(name, Release())
        else:
            await client.request(name, CancelAll())
        await asyncio.sleep(max(0.0, started + period - time.monotonic()))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--period", type=float, default=3.0, help="seconds between orders")
    parser.add_argument(
        "--per-process",
        type=int,
        default=0,
        metavar="K",
        help="K simulated robots per process (bench/robots.py) instead of two processes each",
    )
    parser.add_argument("--quick", action="store_true", help="3 robots for 8 s")
    args = parser.parse_args()
    if args.quick:
        args.robots, args.seconds = 3, 8.0
    # The logs are kept when something went wrong, to be read; the data never is.
    logs = Path(tempfile.mkdtemp(prefix="voicectl-fleet-logs-"))
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="voicectl-fleet-", ignore_cleanup_errors=True) as data:
        fleet = Fleet(args.robots, Path(data), logs, args.per_process)
        try:
            fleet.up()
            results, raw, usage = asyncio.run(measure(fleet, args.seconds, args.period))
        except BaseException:
            print(f"logs in {logs}", file=sys.stderr)
            raise
        finally:
            fleet.stop()
    every = [t for times in results.to_motion.values() for t in times]
    worst = max(
        (percentile(t, 0.99) for t in results.to_motion.values() if t), default=float("nan")
    )
    print(
        f"fleet: {time.strftime('%Y-%m-%d')}, {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores; {args.robots} robots (a simulator and an executor each, "
        + (f"{args.per_process} robots per process" if args.per_process else "as processes")
        + f"), one router, converter and supervisor; an order per robot every "
        f"{args.period:g} s for {args.seconds:g} s (whole run {time.monotonic() - started:.0f} s)"
    )
    print(line("Send -> first motion, every robot", every, "p99 100 ms"))
    print(f"{'':<46}worst robot's p99 {1e3 * worst:.1f} ms")
    print(line("STOP -> zero velocity (one robot)", results.to_zero, "p99 50 ms"))
    print(
        f"{'baseline: raw Zenoh put -> subscriber':<44} p50 {1e6 * percentile(raw, 0.5):7.0f}  "
        f"p99 {1e6 * percentile(raw, 0.99):7.0f} µs"
    )
    for name, value in usage.items():
        print(f"  {name:<32} {value:8.1f}")
    for problem in results.problems[:20]:
        print(f"  ! {problem}")
    if results.problems:
        print(f"  ({len(results.problems)} problems; logs in {logs})")
        sys.exit(1)
    shutil.rmtree(logs, ignore_errors=True)
    print("  (0 problems; logs removed)")


if __name__ == "__main__":
    main()
