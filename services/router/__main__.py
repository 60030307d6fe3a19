"""`voicectl router`: a Zenoh router that every voicectl service connects to."""

from __future__ import annotations

import argparse
import logging
import sys

import zenoh

from shared.errors import BusError, ServiceError
from shared.process import add_bus_arguments, bus_options, run_service, wait_for_stop

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl router", description=__doc__)
    add_bus_arguments(parser, router=True)
    return parser.parse_args(argv)


async def main(args: argparse.Namespace) -> None:
    options = bus_options(args, router=True)
    listen = ", ".join(options.listen) or f"the endpoints of {options.config_file}"
    try:
        session = zenoh.open(options.zenoh_config())
    except (zenoh.ZError, BusError) as exc:
        reason = str(exc).split(" at /", 1)[0]
        raise ServiceError(f"cannot listen on {listen}: {reason}") from exc
    try:
        _LOGGER.info("router listening on %s", listen)
        await wait_for_stop()
    finally:
        session.close()


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl router", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
