"""The supervisor's command line, and the `SupervisorConfig` it becomes."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from voicectl.shared.config import data_dir
from voicectl.shared.process import add_bus_arguments, positive_int, robot_name

from .queue import MAX_QUEUE
from .service import MAX_ROBOTS
from .store import Durability


@dataclass(frozen=True)
class SupervisorConfig:
    """Which robots from the start, how many more, how long a queue, and where history is."""

    db: Path
    robots: tuple[str, ...] = ()
    durability: Durability = Durability.PROCESS
    continue_on_failure: bool = False
    max_robots: int = MAX_ROBOTS
    max_queue: int = MAX_QUEUE

    @classmethod
    def of(cls, args: argparse.Namespace) -> SupervisorConfig:
        """The config the command line (`parse_args`) gives."""
        return cls(
            db=args.db or data_dir() / "supervisor.sqlite3",
            robots=tuple(args.robot),
            durability=args.durability,
            continue_on_failure=args.continue_on_failure,
            max_robots=args.max_robots,
            max_queue=args.max_queue,
        )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl supervisor",
        description="Queue, dispatch and durable history of orders, for every robot.",
    )
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
