"""`voicectl web`: the browser panel and HTTP API for the robots on the bus.

Like every service it is served by `serve()` (shared/process.py); the service here is
uvicorn (`PanelServer`), and the app's own lifespan opens the bus and runs the hub, so
that any ASGI server (Starlette's TestClient in the tests) runs the panel the same way.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import uvicorn

from shared.bus import Bus
from shared.config import default_token_file, load_or_create_token
from shared.errors import ServiceError, TtsError
from shared.process import (
    Service,
    add_bus_arguments,
    bus_options,
    open_bus,
    robot_name,
    run_service,
    serve,
)
from shared.tts import VOICES, Voice, load_voice

from .app import Access, Panel, create_app
from .audio import MAX_MESSAGE
from .tls import add_tls_arguments, tls_problem

_LOGGER = logging.getLogger(__name__)


class _QuietServer(uvicorn.Server):
    """uvicorn without its own signal handling: this process stops it on SIGINT/SIGTERM."""

    @contextlib.contextmanager
    def capture_signals(self) -> Iterator[None]:
        yield


def _bind(host: str, port: int) -> socket.socket:
    """The panel's listening socket, bound before anything says the panel is up: a port
    in use is one clear line, not a traceback after 'panel on ...'."""
    family, kind, proto, _, address = socket.getaddrinfo(
        host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    )[0]
    listening = socket.socket(family, kind, proto)
    try:
        listening.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listening.bind(address)
        listening.listen(128)
    except OSError:
        listening.close()
        raise
    listening.set_inheritable(True)
    return listening


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl web", description=__doc__)
    parser.add_argument("--robot", default="robot", type=robot_name, help="robot shown first")
    parser.add_argument("--host", default="127.0.0.1", help="address to serve on")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--token-file",
        type=Path,
        default=None,
        help="file holding the API token, created if missing (default: data dir/token; "
        "$VOICECTL_TOKEN overrides)",
    )
    add_tls_arguments(parser)
    parser.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="another origin (scheme://host:port) whose pages may open the microphone socket",
    )
    parser.add_argument(
        "--voice",
        default=None,
        choices=[*VOICES, "none"],
        help="speech engine that says the panel's answers when a page asks (default: "
        "espeak-ng when installed, else none); none turns spoken answers off",
    )
    add_bus_arguments(parser)
    return parser.parse_args(argv)


class PanelServer(Service):
    """uvicorn serving the panel on a socket already bound, as a service: `start()` sets it
    serving, `run()` returns if it ends by itself (its app failed to start), `stop()` has it
    close its connections and return. The app's lifespan runs the hub on the bus `main`
    opened before it."""

    def __init__(
        self, config: uvicorn.Config, listening: socket.socket, where: str, panel: Panel
    ) -> None:
        self._server = _QuietServer(config)
        self._panel = panel
        self._listening = listening
        self._where = where
        self._serving: asyncio.Task[None] | None = None

    async def start(self) -> None:
        self._serving = asyncio.create_task(self._server.serve(sockets=[self._listening]))
        _LOGGER.info("panel on %s", self._where)

    async def run(self) -> None:
        assert self._serving is not None
        # asyncio.wait, not await: cancelling run() at a stop must not cancel uvicorn,
        # which stop() ends gracefully.
        await asyncio.wait({self._serving})

    async def stop(self) -> None:
        try:
            if self._serving is not None:
                self._panel.end_streams()  # else uvicorn would wait for them forever
                self._server.should_exit = True  # uvicorn closes connections and returns
                await self._serving
        finally:
            self._listening.close()
        if not self._server.started:
            raise ServiceError("the panel's server did not start (its log says why)")


async def main(args: argparse.Namespace) -> None:
    problem = tls_problem(args)
    if problem:
        raise ServiceError(problem)
    token_file = args.token_file or default_token_file()
    access = Access(load_or_create_token(token_file), origins=args.allow_origin)
    panel = Panel(args.robot, access, _voice(args.voice))
    # The bus first, as every service opens it: a stop while it waits for the router ends
    # the process then; inside uvicorn's lifespan that wait would hold the loop that a
    # stop must reach.
    with open_bus(args) as bus:
        await _serve(args, panel, bus, token_file)


def _voice(engine: str | None) -> Voice | None:
    """The engine asked for, or a one-line reason the panel does not start. Unasked, a
    missing espeak-ng turns spoken answers off: the panel works without them."""
    if engine == "none":
        return None
    try:
        return load_voice(engine or "espeak-ng")
    except TtsError as exc:
        if engine is None:
            _LOGGER.warning("spoken answers are off: %s", exc)
            return None
        raise ServiceError(f"{exc}; or --voice none") from exc


async def _serve(args: argparse.Namespace, panel: Panel, bus: Bus, token_file: Path) -> None:
    config = uvicorn.Config(
        create_app(bus_options(args), panel, bus),
        host=args.host,
        port=args.port,
        access_log=False,
        log_level="warning",
        ws_max_size=MAX_MESSAGE + 1024,
        ssl_certfile=str(args.certfile) if args.certfile else None,
        ssl_keyfile=str(args.keyfile) if args.keyfile else None,
    )
    try:
        listening = _bind(args.host, args.port)
    except OSError as exc:
        raise ServiceError(f"cannot serve on {args.host}:{args.port}: {exc.strerror}") from exc
    scheme = "https" if args.certfile else "http"
    where = f"{scheme}://{args.host}:{args.port} (token in {token_file})"
    await serve(PanelServer(config, listening, where, panel))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl web", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
