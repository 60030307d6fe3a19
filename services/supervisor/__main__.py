"""`voicectl supervisor`: queue, dispatch and durable history of orders, for every robot."""

from __future__ import annotations

import argparse
import contextlib
import sqlite3
import sys

from voicectl.shared.errors import ServiceError, StoreError
from voicectl.shared.process import open_bus, run_service, serve

from .config import SupervisorConfig, parse_args
from .service import SupervisorService
from .store import OrderStore


async def main(args: argparse.Namespace) -> None:
    config = SupervisorConfig.of(args)
    with contextlib.ExitStack() as closing:
        try:
            store = closing.enter_context(OrderStore(config.db, config.durability))
        except StoreError as exc:  # in use, damaged or emptied: said in one line
            raise ServiceError(str(exc)) from exc
        except (sqlite3.Error, OSError) as exc:
            raise ServiceError(f"cannot open {config.db}: {exc}") from exc
        bus = closing.enter_context(open_bus(args))
        service = SupervisorService(
            bus,
            store,
            list(config.robots),
            continue_on_failure=config.continue_on_failure,
            max_robots=config.max_robots,
            max_queue=config.max_queue,
        )
        await serve(service)


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl supervisor", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
