"""STOP on every robot transport, in one run: time from STOP to zero velocity and to the
goal's cancel at the robot, for a robot navigating, with its executor's loop running and
with it blocked.

    .venv/bin/python -m bench.stop_transports [--rounds N] [--blocked-rounds N]

- bridge and rmw-zenoh: the simulator and its executor (harness/stop_rig.py), timed at a
  separate Zenoh session as the robot's side of the bus;
- ros2 on Jazzy and on Kilted (needs root and scripts/ros2-env): a robot of real rclpy in
  a network namespace with only loopback up, the executor on `--transport ros2` and the
  STOP relay beside it (harness/ros2_rig.py), timed by the robot itself as the messages
  arrive (CLOCK_MONOTONIC, shared by every process).

STOP is sent the way the panel and `voicectl stop` send it (VoicectlClient.stop, on a warm
session). The blocked loop is harness/executors.py's BlockingNavigator (4 s), with
the executor's stall watchdog held off, so that STOP alone is timed.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import platform
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

import zenoh

from harness import ros2_env
from harness.client import Client
from harness.measure import percentile
from harness.ports import free_port
from harness.processes import Processes
from harness.ros2_rig import ROBOT, DdsRobot, dds_robot
from harness.stop_rig import StopRig, order
from harness.wait import async_wait_until
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.client import VoicectlClient
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import Order, Release, RobotPose, TargetPose
from voicectl.shared.robot import TransportKind

CASES = {"navigating": "healthy", "blocked-loop": "blocked-loop"}
"""This bench's cases, by the name harness/stop_rig.py gives them."""
Timings = dict[str, list[tuple[float, float]]]
"""Case -> (seconds to zero velocity, seconds to the cancel) per round."""


async def on_zenoh(kind: TransportKind, rounds: dict[str, int], tmp: Path) -> Timings:
    router = f"tcp/127.0.0.1:{free_port()}"
    timings: Timings = {case: [] for case in CASES}
    with zenoh.open(BusOptions(mode="router", connect=[], listen=[router]).zenoh_config()):
        (tmp / kind.value).mkdir()
        processes = Processes(tmp / kind.value)
        try:
            rig = StopRig(router, processes, tmp / f"{kind.value}.sqlite3", transport=kind)
            with rig.client() as client:
                for case, rig_case in CASES.items():
                    for _ in range(rounds[case]):
                        outcome = await rig.run(rig_case, client)
                        timings[case].append((outcome.zero_velocity, outcome.cancelled or 0.0))
        finally:
            processes.stop_all()
    return timings


async def on_dds(distro: str, rounds: dict[str, int], tmp: Path) -> Timings:
    env = ros2_env.find(distro)
    if env is None:
        raise SystemExit(f"ROS 2 {distro} is not made: run scripts/ros2-env")
    args = ("--executor", "harness.executors:BlockingNavigator", "--stall-limit", "30")
    timings: Timings = {case: [] for case in CASES}
    (tmp / distro).mkdir()
    processes = Processes(tmp / distro)
    try:
        with dds_robot(env, processes, tmp / distro, args) as robot:
            loop = asyncio.get_running_loop()
            with Bus.open(BusOptions(connect=[robot.router]), loop) as bus:
                client = Client(bus, ROBOT)
                stopper = VoicectlClient(bus)  # warm from here on, as the panel's is
                await robot.ready(client)
                poses: list[RobotPose] = []
                bus.subscribe(
                    RobotKeys(ROBOT).pose, json_decoder(RobotPose), lambda _k, p: poses.append(p)
                )
                await async_wait_until(lambda: poses, 30.0, "the robot's pose")
                for case in CASES:
                    for _ in range(rounds[case]):
                        timings[case].append(await dds_round(robot, client, stopper, case, poses))
    finally:
        processes.stop_all()
    return timings


async def dds_round(
    robot: DdsRobot, client: Client, stopper: VoicectlClient, case: str, poses: list[RobotPose]
) -> tuple[float, float]:
    start = poses[-1].x
    x = 0.0 if start > 4.0 else 8.0
    if case == "blocked-loop":
        await client.submit(order("blocknav", seconds=4, x=x))
    else:
        target = TargetPose(frame="map", x=x)
        await client.submit(
            Order(order="goal", label="mbgoal", description="far", target_pose=target)
        )
    await async_wait_until(lambda: abs(poses[-1].x - start) > 0.3, 30.0, "the robot under way")
    if case == "blocked-loop":
        await asyncio.sleep(0.5)  # the executor's loop is blocked by now
    asked = time.monotonic()
    await stopper.stop(ROBOT)
    await async_wait_until(
        lambda: robot.events("zero", asked) and robot.events("cancel", asked), 5.0, "the stop"
    )
    zero = robot.events("zero", asked)[0] - asked
    cancel = robot.events("cancel", asked)[0] - asked
    # Every way the stop went (the client's and the supervisor's through the relay, the
    # executor's own) cancels every goal: a goal sent before the last of them lands would
    # be cancelled too. A person releases seconds later; this bench waits for the goal's
    # end and half a second more.
    await async_wait_until(lambda: robot.events("canceled", asked), 5.0, "the goal's end")
    await asyncio.sleep(0.5)

    async def idle() -> bool:
        await client.ask(Release())
        state = await client.state()
        return state.executor_online and state.current is None and not state.stopped

    await async_wait_until(idle, 30.0, "the robot idle again")
    return zero, cancel


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=30, help="rounds navigating")
    parser.add_argument("--blocked-rounds", type=int, default=10, help="rounds blocked")
    args = parser.parse_args()
    rounds = {"navigating": args.rounds, "blocked-loop": args.blocked_rounds}
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(1))
    print(
        f"{platform.machine()}, {len(os.sched_getaffinity(0))} cores, "
        f"Python {platform.python_version()}, {args.rounds} rounds navigating and "
        f"{args.blocked_rounds} with the executor's loop blocked, {time.strftime('%Y-%m-%d')}"
    )
    results: dict[str, Timings] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in (TransportKind.BRIDGE, TransportKind.RMW_ZENOH):
            results[kind.value] = asyncio.run(on_zenoh(kind, rounds, Path(tmp)))
        for distro in ros2_env.DISTROS:
            results[f"ros2 ({distro})"] = asyncio.run(on_dds(distro, rounds, Path(tmp)))
    print(
        f"{'transport':18} {'case':13} {'zero vel p50':>12} {'p99':>7} {'cancel p50':>11} "
        f"{'p99':>7} {'worst':>7}"
    )
    for transport, timings in results.items():
        for case, rows in timings.items():
            zero = [z * 1000 for z, _ in rows]
            cancel = [c * 1000 for _, c in rows]
            worst = max(max(zero), max(cancel))
            print(
                f"{transport:18} {case:13} {statistics.median(zero):12.1f} "
                f"{percentile(zero, 0.99):7.1f} {statistics.median(cancel):11.1f} "
                f"{percentile(cancel, 0.99):7.1f} {worst:7.1f}"
            )
    print("times in ms from STOP asked to its arrival at the robot")


if __name__ == "__main__":
    main()
