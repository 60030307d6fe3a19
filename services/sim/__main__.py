"""voicectl sim: run one simulated robot until SIGINT or SIGTERM."""

from __future__ import annotations

import argparse
import sys

from voicectl.shared.process import open_bus, run_service, serve

from .build import build
from .config import config_of, parse_args


async def main(args: argparse.Namespace) -> None:
    with open_bus(args) as bus:
        await serve(build(bus, config_of(args)))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl sim", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
