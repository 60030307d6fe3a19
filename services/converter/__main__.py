"""`voicectl converter`: serve text-to-orders conversion on the bus."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from voicectl.shared.errors import OrdersFileError, ServiceError
from voicectl.shared.process import open_bus, run_service, serve

from .config import ConverterConfig, parse_args
from .service import ConverterService, errors_of, load
from .watch import signature

_LOGGER = logging.getLogger(__name__)


async def main(args: argparse.Namespace) -> None:
    config = ConverterConfig.of(args)
    try:
        before = await asyncio.to_thread(signature, config.orders)
        loaded = await asyncio.to_thread(load, config.orders, before)
    except OrdersFileError as exc:
        # Never start with half a configuration: a bad file at start is fatal. The log
        # has every problem with its line; the last line says the first one.
        for error in errors_of(exc):
            _LOGGER.error("%s", error)
        raise ServiceError(str(exc)) from exc
    with open_bus(args) as bus:
        await serve(ConverterService(bus, config.orders, loaded, config.poll))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl converter", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
