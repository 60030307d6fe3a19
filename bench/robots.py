"""Several simulated robots in one process, for bench/fleet.py --per-process.

    .venv/bin/python -m bench.robots --connect ENDPOINT NAME [NAME ...]

Per robot a simulator and an executor, built as `voicectl sim --namespace NAME` and
`voicectl executor --robot NAME --namespace NAME` build them, on one event loop and one
Zenoh session: the same keys and messages as the processes of their own that a real site
has (one per robot, on the robot), at a fraction of the cost on a machine with fewer cores
than robots. What it does not reproduce: a robot's own process and Zenoh session, so the
router serves fewer sessions than a real fleet would give it.
"""

from __future__ import annotations

import argparse
import asyncio

from services.executor.__main__ import executor_service, load_bindings
from services.executor.__main__ import parse_args as executor_args
from services.sim.__main__ import parse_args as sim_args
from services.sim.__main__ import sim_node
from shared.process import Service, open_bus, serve, setup_logging
from shared.robot import TransportKind


async def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True)
    parser.add_argument("names", nargs="+")
    args = parser.parse_args()
    setup_logging(False)
    connect = ["--connect", args.connect]
    with open_bus(sim_args(connect)) as bus:
        services: list[Service] = []
        for name in args.names:
            services.append(sim_node(bus, sim_args(["--namespace", name, *connect])))
            flags = executor_args(["--robot", name, "--namespace", name, *connect])
            bindings = load_bindings(flags)
            services.append(executor_service(bus, flags, bindings, TransportKind.BRIDGE))
        await serve(*services)


if __name__ == "__main__":
    asyncio.run(main())
