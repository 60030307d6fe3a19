"""The converter's command line, and the `ConverterConfig` it becomes."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from voicectl.shared.process import add_bus_arguments

from .service import POLL_SECONDS
from .shipped import shipped_orders


@dataclass(frozen=True)
class ConverterConfig:
    """Which orders files, and how often to look for edits."""

    orders: Path
    poll: float = POLL_SECONDS

    @classmethod
    def of(cls, args: argparse.Namespace) -> ConverterConfig:
        """The config the command line (`parse_args`) gives."""
        return cls(orders=args.orders, poll=args.poll)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl converter", description="Serve text-to-orders conversion on the bus."
    )
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
