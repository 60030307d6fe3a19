"""`voicectl relay`, whose event loop a test can block: on SIGUSR1 the loop sleeps
`--block` seconds (`time.sleep` on the loop, as blocking code would), saying when it
starts and ends on stdout, one JSON line each, stamped with CLOCK_MONOTONIC (the same
clock in every process of the machine): ``{"event": "blocked", "at": ...}``,
``{"event": "unblocked", ...}``. Otherwise the relay of services/relay, as it runs:

    python -m harness.blocking_relay [--block SECONDS] [voicectl relay's flags]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import sys
import time

from voicectl.services.relay.config import parse_args
from voicectl.services.relay.relay import StopRelay
from voicectl.shared.errors import ServiceError
from voicectl.shared.process import open_bus, run_service, serve
from voicectl.shared.robot.dds import Ros2Transport
from voicectl.shared.robot_options import robot_options


def say(event: str) -> None:
    print(json.dumps({"event": event, "at": time.monotonic()}), flush=True)


async def main(args: argparse.Namespace, block: float) -> None:
    problem = Ros2Transport.unavailable()
    if problem is not None:
        raise ServiceError(problem)

    def blocked() -> None:
        say("blocked")
        time.sleep(block)  # on the loop: the fault under test
        say("unblocked")

    asyncio.get_running_loop().add_signal_handler(signal.SIGUSR1, blocked)
    reach = robot_options(args)
    with open_bus(args) as bus:
        await serve(StopRelay(bus, reach.names, reach.domain_id))


def run(argv: list[str]) -> int:
    own = argparse.ArgumentParser(add_help=False)
    own.add_argument("--block", type=float, default=10.0)
    known, rest = own.parse_known_args(argv)
    return run_service("blocking relay", parse_args(rest), lambda args: main(args, known.block))


if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
