"""`voicectl stt`: speech to text for one robot, listening only for the orders' commands."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys

from shared.errors import ServiceError
from shared.process import add_bus_arguments, open_bus, robot_name, run_service, serve

from .engine import ENGINES, EngineError, EngineOptions, load_engine
from .service import SessionLimits, SttService

_LOGGER = logging.getLogger(__name__)


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    """The engine flags of every command that loads an engine, each engine's own among them."""
    parser.add_argument(
        "--engine",
        choices=list(ENGINES),
        default=EngineOptions.name,
        help="speech engine (default %(default)s)",
    )
    for kind in ENGINES.values():
        for flag in kind.flags:
            parser.add_argument(
                f"--{flag.name}",
                type=flag.type,
                metavar=flag.metavar,
                help=f"{flag.help}, with --engine {kind.name}",
            )
    parser.add_argument(
        "--min-confidence",
        type=float,
        default=0.5,
        metavar="C",
        help="reject utterances recognised with less confidence, 0 to 1 (default %(default)s)",
    )
    parser.add_argument(
        "--workers",
        type=_count,
        default=0,
        metavar="N",
        help="decode in N worker processes, one engine each, for several people speaking "
        "at once on several cores (default 0: in this process)",
    )


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of 0 or more")
    return value


def engine_options(args: argparse.Namespace) -> EngineOptions:
    return EngineOptions(
        name=args.engine,
        min_confidence=args.min_confidence,
        workers=args.workers,
        settings={flag.dest: getattr(args, flag.dest) for flag in ENGINES[args.engine].flags},
    )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl stt", description=__doc__)
    parser.add_argument("--robot", type=robot_name, default="robot")
    add_engine_arguments(parser)
    limits = SessionLimits()
    for flag, kind, default, metavar, text in (
        ("--max-utterance", float, limits.max_utterance, "SECONDS", "cut longer utterances"),
        ("--max-sessions", int, limits.max_sessions, "N", "audio sessions open at once"),
        ("--idle", float, limits.idle_seconds, "SECONDS", "end a session silent this long"),
    ):
        help_text = f"{text} (default %(default)s)"
        parser.add_argument(flag, type=kind, default=default, metavar=metavar, help=help_text)
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(args: argparse.Namespace) -> None:
    try:
        engine = await asyncio.to_thread(load_engine, engine_options(args))
    except EngineError as exc:
        raise ServiceError(str(exc)) from exc
    limits = SessionLimits(
        max_utterance=args.max_utterance,
        max_sessions=args.max_sessions,
        idle_seconds=args.idle,
    )
    try:
        with open_bus(args) as bus:
            await serve(SttService(bus, args.robot, engine, limits))
    finally:
        engine.close()


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl stt", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
