"""`voicectl supervisor`: queue, dispatch and durable history of orders, for every robot."""

from __future__ import annotations

import argparse
import contextlib
import logging
import sqlite3
import sys
from pathlib import Path

from voicectl.shared.config import data_dir
from voicectl.shared.errors import ServiceError, StoreError
from voicectl.shared.process import (
    add_bus_arguments,
    open_bus,
    positive_int,
    robot_name,
    run_service,
    serve,
)

from .queue import MAX_QUEUE
from .service import MAX_ROBOTS, SupervisorService
from .store import Durability, OrderStore

_LOGGER = logging.getLogger(__name__)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl supervisor", description=__doc__)
    parser.add_argument(
        "--robot",
        action="append",
        default=[],
        type=robot_name,
        help="a robot to serve from the start and announce (repeatable); any other robot "
        "is served once its executor announces itself, up to --max-robots of them",
    )
    parser.add_argument(
        "--max-queue",
        type=positive_int,
        default=MAX_QUEUE,
        metavar="N",
        help=f"most orders queued per robot (default: {MAX_QUEUE}); a submit past it is "
        "refused whole",
    )
    parser.add_argument(
        "--max-robots",
        type=positive_int,
        default=MAX_ROBOTS,
        metavar="N",
        help="most robots served besides those named with --robot or found in the store "
        f"(default: {MAX_ROBOTS}): names come from anyone on the bus; when full, a robot "
        "whose executor has gone and that holds no order makes room",
    )
    parser.add_argument(
        "--db",
        type=Path,
        default=None,
        help="SQLite file of queues and history (default: data dir/supervisor.sqlite3)",
    )
    parser.add_argument(
        "--durability",
        type=Durability,
        choices=list(Durability),
        default=Durability.PROCESS,
        help="'process': accepted orders survive the supervisor being killed (default); "
        "'power': also a power cut, at the cost of a disk flush per write",
    )
    parser.add_argument(
        "--continue-on-failure",
        action="store_true",
        help="keep running the rest of an utterance's orders when one fails",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(args: argparse.Namespace) -> None:
    db_path: Path = args.db or data_dir() / "supervisor.sqlite3"
    with contextlib.ExitStack() as closing:
        try:
            store = closing.enter_context(OrderStore(db_path, args.durability))
        except StoreError as exc:  # in use, damaged or emptied: said in one line
            raise ServiceError(str(exc)) from exc
        except (sqlite3.Error, OSError) as exc:
            raise ServiceError(f"cannot open {db_path}: {exc}") from exc
        bus = closing.enter_context(open_bus(args))
        service = SupervisorService(
            bus,
            store,
            args.robot,
            continue_on_failure=args.continue_on_failure,
            max_robots=args.max_robots,
            max_queue=args.max_queue,
        )
        await serve(service)


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl supervisor", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
