"""Several simulated robots in one process, for bench/fleet.py --per-process.

    .venv/bin/python -m bench.robots --connect ENDPOINT NAME [NAME ...]

Per robot a simulator and an executor, built from the configs `voicectl sim --namespace
NAME` and `voicectl executor --robot NAME --namespace NAME` build them from, on one event
loop and one Zenoh session: the same keys and messages as the processes of their own that
a real site has (one per robot, on the robot), at a fraction of the cost on a machine with
fewer cores than robots. What it does not reproduce: a robot's own process and Zenoh
session, so the router serves fewer sessions than a real fleet would give it.
"""

from __future__ import annotations

import argparse
import asyncio

from voicectl.services.executor.build import build as build_executor
from voicectl.services.executor.build import load_bindings
from voicectl.services.executor.config import ExecutorConfig
from voicectl.services.sim.build import build as build_sim
from voicectl.services.sim.node import SimConfig
from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.process import Service, serve, setup_logging
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.robot_options import RobotOptions


async def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True)
    parser.add_argument("names", nargs="+")
    args = parser.parse_args()
    setup_logging(False)
    options = BusOptions(connect=[args.connect])
    with Bus.open(options, asyncio.get_running_loop()) as bus:
        services: list[Service] = []
        for name in args.names:
            names = RobotNames(name)
            services.append(build_sim(bus, SimConfig(names=names)))
            config = ExecutorConfig(robot=name, reach=RobotOptions(names=names))
            services.append(
                build_executor(bus, config, load_bindings(config), TransportKind.BRIDGE)
            )
        await serve(*services)


if __name__ == "__main__":
    asyncio.run(main())
