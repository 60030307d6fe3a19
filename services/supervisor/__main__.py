"""`voicectl supervisor`: queue, dispatch and history of orders, for one or more robots."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from shared.bus import Bus, add_bus_arguments, bus_options, setup_logging, wait_for_stop
from shared.keys import check_chunk

from .queue import RobotQueue
from .service import RobotSupervisor, run_supervisors

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl supervisor", description=__doc__)
    parser.add_argument(
        "--robot",
        action="append",
        type=lambda name: check_chunk(name, "robot name"),
        help="robot to supervise (repeatable; default: robot)",
    )
    parser.add_argument(
        "--continue-on-failure",
        action="store_true",
        help="keep running the rest of an utterance's orders when one fails",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.debug)
    robots: list[str] = args.robot or ["robot"]
    loop = asyncio.get_running_loop()
    with Bus.open(bus_options(args), loop) as bus:
        supervisors = [
            RobotSupervisor(bus, RobotQueue(robot, continue_on_failure=args.continue_on_failure))
            for robot in robots
        ]
        _LOGGER.info("supervisor ready for %s", ", ".join(robots))
        await wait_for_stop(run_supervisors(supervisors))
    return 0


def run(argv: list[str] | None = None) -> None:
    sys.exit(asyncio.run(main(argv)))


if __name__ == "__main__":
    run()
