"""`voicectl web`: the browser panel and HTTP API for the robots on the bus."""

from __future__ import annotations

import argparse
import sys

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import bus_options, open_bus, run_service, serve

from .config import WebConfig, parse_args
from .server import build, panel_of
from .tls import tls_problem


async def main(args: argparse.Namespace) -> None:
    problem = tls_problem(args)
    if problem:
        raise ServiceError(problem)
    config = WebConfig.of(args)
    panel = panel_of(config)
    # The bus first, as every service opens it: a stop while it waits for the router ends
    # the process then; inside uvicorn's lifespan that wait would hold the loop that a
    # stop must reach.
    with open_bus(args) as bus:
        await serve(build(bus, config, bus_options(args), panel))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl web", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
