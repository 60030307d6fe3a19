"""`voicectl web`: the browser panel and HTTP API for one robot."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path

import uvicorn

from shared.bus import Bus, add_bus_arguments, bus_options, robot_name, setup_logging, wait_for_stop
from shared.config import default_token_file, load_or_create_token

from .app import Panel

_LOGGER = logging.getLogger(__name__)


class _QuietServer(uvicorn.Server):
    """uvicorn without its own signal handling: this process stops it on SIGINT/SIGTERM."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl web", description=__doc__)
    parser.add_argument("--robot", default="robot", type=robot_name)
    parser.add_argument("--host", default="127.0.0.1", help="address to serve on")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--token-file",
        type=Path,
        default=None,
        help="file holding the API token, created if missing (default: data dir/token; "
        "$VOICECTL_TOKEN overrides)",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


async def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    setup_logging(args.debug)
    token_file = args.token_file or default_token_file()
    token = load_or_create_token(token_file)
    loop = asyncio.get_running_loop()
    with Bus.open(bus_options(args), loop) as bus:
        panel = Panel(bus, args.robot, token)
        panel.start()
        config = uvicorn.Config(
            panel.app(), host=args.host, port=args.port, access_log=False, log_level="warning"
        )
        server = _QuietServer(config)
        serving = asyncio.create_task(server.serve())
        stopping = asyncio.create_task(wait_for_stop())
        _LOGGER.info("panel on http://%s:%d (token in %s)", args.host, args.port, token_file)
        await asyncio.wait({serving, stopping}, return_when=asyncio.FIRST_COMPLETED)
        server.should_exit = True  # uvicorn closes connections and returns
        stopping.cancel()
        await serving
        await asyncio.gather(stopping, return_exceptions=True)
    return 0 if server.started else 1


def run(argv: list[str] | None = None) -> None:
    sys.exit(asyncio.run(main(argv)))


if __name__ == "__main__":
    run()
