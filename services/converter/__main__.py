"""`voicectl converter`: serve text-to-orders conversion on the bus."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path

from voicectl.shared.errors import OrdersFileError, ServiceError
from voicectl.shared.process import add_bus_arguments, open_bus, run_service, serve

from .service import POLL_SECONDS, ConverterService, errors_of, load
from .shipped import shipped_orders
from .watch import signature

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl converter", description=__doc__)
    parser.add_argument(
        "--orders",
        type=Path,
        default=shipped_orders(),
        help="orders YAML file or directory of them (default: every shipped file in orders/); "
        "edits apply while running",
    )
    parser.add_argument(
        "--poll",
        type=float,
        default=POLL_SECONDS,
        metavar="SECONDS",
        help=f"how often to check the orders files for changes (default {POLL_SECONDS})",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(args: argparse.Namespace) -> None:
    try:
        before = await asyncio.to_thread(signature, args.orders)
        loaded = await asyncio.to_thread(load, args.orders, before)
    except OrdersFileError as exc:
        # Never start with half a configuration: a bad file at start is fatal. The log
        # has every problem with its line; the last line says the first one.
        for error in errors_of(exc):
            _LOGGER.error("%s", error)
        raise ServiceError(str(exc)) from exc
    with open_bus(args) as bus:
        await serve(ConverterService(bus, args.orders, loaded, args.poll))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl converter", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
