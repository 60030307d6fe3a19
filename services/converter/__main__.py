"""`voicectl converter`: serve text-to-orders conversion on the bus."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path

from shared.bus import Bus, add_bus_arguments, bus_options, setup_logging, wait_for_stop
from shared.errors import OrdersFileError

from .orders import OrderSet
from .parser import Parser
from .service import ConverterService

_LOGGER = logging.getLogger(__name__)
DEFAULT_ORDERS = Path(__file__).resolve().parents[2] / "orders" / "demo.yaml"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl converter", description=__doc__)
    parser.add_argument(
        "--orders",
        type=Path,
        default=DEFAULT_ORDERS,
        help="orders YAML file or directory of them (default: the shipped demo orders)",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.debug)
    try:
        orders = OrderSet.load(args.orders)
    except OrdersFileError as exc:
        print(f"voicectl converter: {exc}", file=sys.stderr)
        return 2
    loop = asyncio.get_running_loop()
    with Bus.open(bus_options(args), loop) as bus:
        ConverterService(bus, Parser(orders)).start()
        _LOGGER.info("converter ready with %d orders from %s", len(orders.orders), args.orders)
        await wait_for_stop()
    return 0


def run(argv: list[str] | None = None) -> None:
    sys.exit(asyncio.run(main(argv)))


if __name__ == "__main__":
    run()
