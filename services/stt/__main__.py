"""`voicectl stt`: speech to text for one robot, listening only for the orders' commands."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from pathlib import Path

from shared.bus import Bus
from shared.process import add_bus_arguments, bus_options, robot_name, setup_logging, wait_for_stop

from .engine import ENGINES, EngineError, EngineOptions, load_engine
from .service import SessionLimits, SttService

_LOGGER = logging.getLogger(__name__)


def add_engine_arguments(parser: argparse.ArgumentParser) -> None:
    """The engine flags `voicectl stt` and `voicectl transcribe` share."""
    parser.add_argument(
        "--engine",
        choices=ENGINES,
        default="pocketsphinx",
        help="speech engine (default %(default)s)",
    )
    parser.add_argument(
        "--vosk-model",
        type=Path,
        metavar="DIR",
        help="an unpacked Vosk model (https://alphacephei.com/vosk/models), with --engine vosk",
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
        vosk_model=args.vosk_model,
        min_confidence=args.min_confidence,
        workers=args.workers,
    )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl stt", description=__doc__)
    parser.add_argument("--robot", type=robot_name, default="robot")
    add_engine_arguments(parser)
    limits = SessionLimits()
    parser.add_argument(
        "--max-utterance",
        type=float,
        default=limits.max_utterance,
        metavar="SECONDS",
        help="cut an utterance that goes on longer (default %(default)s)",
    )
    parser.add_argument(
        "--max-sessions",
        type=int,
        default=limits.max_sessions,
        help="audio sessions open at once (default %(default)s)",
    )
    parser.add_argument(
        "--idle",
        type=float,
        default=limits.idle_seconds,
        metavar="SECONDS",
        help="end a session that sends no audio for this long (default %(default)s)",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.debug)
    try:
        engine = await asyncio.to_thread(load_engine, engine_options(args))
    except EngineError as exc:
        print(f"voicectl stt: {exc}", file=sys.stderr)
        return 2
    limits = SessionLimits(
        max_utterance=args.max_utterance,
        max_sessions=args.max_sessions,
        idle_seconds=args.idle,
    )
    loop = asyncio.get_running_loop()
    try:
        with (
            Bus.open(bus_options(args), loop) as bus,
            SttService(bus, args.robot, engine, limits) as service,
        ):
            _LOGGER.info("stt ready for robot %s with %s", args.robot, engine.name)
            await wait_for_stop(service.run())
    finally:
        engine.close()
    return 0


def run(argv: list[str] | None = None) -> None:
    sys.exit(asyncio.run(main(argv)))


if __name__ == "__main__":
    run()
