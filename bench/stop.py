"""STOP under every fault: time from STOP to the robot told to stop, and motion after it.

    .venv/bin/python -m bench.stop [--rounds N]

A simulated robot with its supervisor and executor, as processes on a router on
loopback; each case of harness/stop_rig.py (healthy navigation, an executor blocking its
loop, one commanding from a blocked loop, one swallowing its cancel, the executor killed,
supervisor and executor killed, 50 orders queued) is run `--rounds` times. STOP is sent
the way the panel and `voicectl stop` send it (VoicectlClient.stop on a warm session).
Measured at a separate session, as the robot's side of the bus: STOP to the first zero
velocity, and for navigation to the goal's end in the simulator's status; the robot's
motion from 0.3 s to 1.5 s after STOP. Beside them, in the same run: a raw Zenoh put
from one session to another through the same router (the floor).
"""

from __future__ import annotations

import argparse
import asyncio
import platform
import signal
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import zenoh

from harness.measure import percentile
from harness.ports import free_port
from harness.processes import Processes
from harness.stop_rig import CASES, Outcome, StopRig
from voicectl.shared.bus import BusOptions


def raw_put(router: str, rounds: int) -> list[float]:
    """A put from one session to a subscriber in another, through the router."""
    arrived = threading.Event()
    at: list[float] = []

    def on_sample(_sample: zenoh.Sample) -> None:
        at.append(time.monotonic())
        arrived.set()

    options = BusOptions(connect=[router]).zenoh_config()
    with zenoh.open(options) as sender, zenoh.open(options) as receiver:
        receiver.declare_subscriber("bench/floor", on_sample)
        time.sleep(0.5)
        took = []
        for _ in range(rounds):
            arrived.clear()
            sent = time.monotonic()
            sender.put("bench/floor", b"0")
            if arrived.wait(1.0):
                took.append(at[-1] - sent)
            time.sleep(0.01)
    return took


async def bench(rig: StopRig, router: str, rounds: int) -> dict[str, list[Outcome]]:
    outcomes: dict[str, list[Outcome]] = {case: [] for case in CASES}
    with rig.client() as client:
        for round_ in range(rounds):
            for case in CASES:
                outcome = await rig.run(case, client)
                outcomes[case].append(outcome)
                print(
                    f"  round {round_ + 1} {case}: {outcome.latency * 1000:.1f} ms, "
                    f"moved {outcome.moved * 100:.1f} cm",
                    file=sys.stderr,
                )
    return outcomes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--quick", action="store_true", help="3 rounds per case")
    args = parser.parse_args()
    if args.quick:
        args.rounds = 3
    # SIGTERM unwinds like Ctrl-C, so that the processes started are stopped too.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    print(
        f"{platform.machine()}, {len(__import__('os').sched_getaffinity(0))} cores, "
        f"Python {platform.python_version()}, {args.rounds} rounds per case, "
        f"{time.strftime('%Y-%m-%d')}"
    )
    router = f"tcp/127.0.0.1:{free_port()}"
    with (
        zenoh.open(BusOptions(mode="router", connect=[], listen=[router]).zenoh_config()),
        tempfile.TemporaryDirectory() as tmp,
    ):
        processes = Processes(Path(tmp))
        try:
            rig = StopRig(router, processes, Path(tmp) / "supervisor.sqlite3")
            floor = raw_put(router, 200)
            outcomes = asyncio.run(bench(rig, router, args.rounds))
        finally:
            processes.stop_all()
    print(
        "raw Zenoh put, session to session via the router: "
        f"p50 {statistics.median(floor) * 1000:.2f} ms, p99 {percentile(floor, 0.99) * 1000:.2f} ms"
    )
    print(
        f"{'case':32} {'zero vel p50':>12} {'p99':>7} {'goal end p50':>13} {'p99':>7} "
        f"{'worst':>7} {'moved after':>12} {'confirmed':>10}"
    )
    for case, results in outcomes.items():
        zero = [o.zero_velocity * 1000 for o in results]
        ends = [o.cancelled * 1000 for o in results if o.cancelled is not None]
        worst = max(o.latency for o in results) * 1000
        moved = max(o.moved for o in results) * 100
        confirmed = sum(o.stopped.confirmed for o in results)
        goal = (
            f"{statistics.median(ends):13.1f} {percentile(ends, 0.99):7.1f}"
            if ends
            else f"{'-':>13} {'-':>7}"
        )
        print(
            f"{case:32} {statistics.median(zero):12.1f} {percentile(zero, 0.99):7.1f} {goal} "
            f"{worst:7.1f} {moved:9.1f} cm {confirmed:>6}/{len(results)}"
        )
    print(
        "times in ms from STOP asked; 'moved after': the most any round moved from 0.3 s to 1.5 s"
    )


if __name__ == "__main__":
    main()
