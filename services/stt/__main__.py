"""`voicectl stt`: speech to text for one robot, listening only for the orders' commands."""

from __future__ import annotations

import argparse
import asyncio
import sys

from voicectl.shared.errors import ServiceError
from voicectl.shared.process import open_bus, run_service, serve

from .config import SttConfig, parse_args
from .engine import EngineError
from .load import load_engine
from .service import SttService


async def main(args: argparse.Namespace) -> None:
    config = SttConfig.of(args)
    try:
        engine = await asyncio.to_thread(load_engine, config.engine)
    except EngineError as exc:
        raise ServiceError(str(exc)) from exc
    if config.language not in engine.languages:
        engine.close()
        raise ServiceError(
            f"--language {config.language}: the {engine.name} engine hears "
            + ("it not" if len(engine.languages) > 3 else ", ".join(sorted(engine.languages)))
            + (" (--engine whisper hears 99 languages)" if engine.name != "whisper" else "")
        )
    try:
        with open_bus(args) as bus:
            await serve(SttService(bus, config.robot, engine, config.limits, config.language))
    finally:
        engine.close()


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl stt", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
