"""`voicectl router`: a Zenoh router that every voicectl service connects to."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

import zenoh

from shared.bus import DEFAULT_ROUTER, BusOptions, setup_logging, wait_for_stop

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl router", description=__doc__)
    parser.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable; default {DEFAULT_ROUTER})",
    )
    parser.add_argument("--debug", action="store_true", help="log at DEBUG level")
    return parser.parse_args(argv)


async def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.debug)
    listen: list[str] = args.listen or [DEFAULT_ROUTER]
    options = BusOptions(mode="router", connect=[], listen=listen)
    try:
        session = zenoh.open(options.zenoh_config())
    except zenoh.ZError as exc:
        print(f"voicectl router: cannot listen on {', '.join(listen)}: {exc}", file=sys.stderr)
        return 2
    try:
        _LOGGER.info("router listening on %s", ", ".join(listen))
        await wait_for_stop()
    finally:
        session.close()
    return 0


def run(argv: list[str] | None = None) -> None:
    sys.exit(asyncio.run(main(argv)))


if __name__ == "__main__":
    run()
