"""`voicectl executor`: run orders on one robot with the built-in and user executors."""

from __future__ import annotations

import argparse
import logging
import os
import sys

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import open_bus, run_service, serve
from voicectl.shared.robot import transports

from .build import build, choose_transport, load_bindings
from .config import ExecutorConfig, parse_args
from .framework import BindingError

_LOGGER = logging.getLogger(__name__)


async def main(args: argparse.Namespace) -> None:
    config = ExecutorConfig.of(args)
    try:
        bindings = load_bindings(config)
    except BindingError as exc:
        raise ServiceError(str(exc)) from exc
    chosen = config.reach.transport
    problem = transports()[chosen].unavailable() if chosen is not None else None
    if problem is not None:
        raise ServiceError(f"--transport {chosen}: {problem}")
    with open_bus(args) as bus:
        service = build(bus, config, bindings, await choose_transport(bus, config))
        await serve(service)
    if service.abandoned:
        # asyncio.run would wait for these forever: an executor that ignores cancellation
        # must not keep the process alive once the bus is closed.
        _LOGGER.warning(
            "exiting past %d executor task(s) that ignore cancel", len(service.abandoned)
        )
        logging.shutdown()
        os._exit(0)


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl executor", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
