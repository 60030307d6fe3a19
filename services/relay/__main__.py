"""`voicectl relay`: the STOP relay of a robot on DDS, beside its executor (relay.py)."""

from __future__ import annotations

import argparse
import sys

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import open_bus, run_service, serve
from voicectl.shared.robot.dds import Ros2Transport
from voicectl.shared.robot_options import robot_options

from .config import parse_args
from .relay import StopRelay


async def main(args: argparse.Namespace) -> None:
    problem = Ros2Transport.unavailable()
    if problem is not None:
        raise ServiceError(problem)
    reach = robot_options(args)
    with open_bus(args) as bus:
        await serve(StopRelay(bus, reach.names, reach.domain_id))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl relay", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
