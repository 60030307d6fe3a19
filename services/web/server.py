"""The panel served by uvicorn, as a service (`PanelServer`), made from its config.

Like every service it is run by `serve()` (shared/process.py); the app's own lifespan
runs the hub on the bus, so that any ASGI server (Starlette's TestClient in the tests)
runs the panel the same way.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Iterator

import uvicorn

from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.config import load_or_create_token
from voicectl.shared.errors import ServiceError, TtsError
from voicectl.shared.process import Service
from voicectl.shared.tts import Voice, load_voice

from .app import Access, Panel, create_app
from .audio import MAX_MESSAGE
from .config import WebConfig

_LOGGER = logging.getLogger(__name__)


def panel_of(config: WebConfig) -> Panel:
    """The API's handlers with their token and voice: before the bus opens, so that a
    missing voice engine is told at once."""
    access = Access(load_or_create_token(config.token_path), origins=list(config.allow_origins))
    return Panel(config.robot, access, _voice(config.voice), config.max_robots)


def build(bus: Bus, config: WebConfig, options: BusOptions, panel: Panel) -> PanelServer:
    """The panel `config` describes, serving `panel` from `bus`; ServiceError when its
    port cannot be had."""
    server = uvicorn.Config(
        create_app(options, panel, bus),
        host=config.host,
        port=config.port,
        access_log=False,
        log_level="warning",
        ws_max_size=MAX_MESSAGE + 1024,
        ssl_certfile=str(config.certfile) if config.certfile else None,
        ssl_keyfile=str(config.keyfile) if config.keyfile else None,
    )
    try:
        listening = _bind(config.host, config.port)
    except OSError as exc:
        raise ServiceError(f"cannot serve on {config.host}:{config.port}: {exc.strerror}") from exc
    where = f"{config.scheme}://{config.host}:{config.port} (token in {config.token_path})"
    return PanelServer(server, listening, where, panel)


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
