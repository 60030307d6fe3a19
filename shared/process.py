"""A voicectl process: the flags every service shares (the Zenoh ones named as zenohd
names them, with their environment variables), one logging setup, waiting for SIGINT or
SIGTERM, and one lifecycle for every service.

A service (`Service`) has three steps: `start()` declares what it serves and announces
it on the bus; `run()` does its ongoing work (a poll, a tick, a watch) and returns or
raises only when the service must end by itself; `stop()` withdraws, stops what runs and
lets go of what it holds. It is an async context manager of those. `serve()` runs
services until a stop signal, `running()` for the length of a block; `run_service()` is
every entry point's process: its exit code, and a `ServiceError` as one line on stderr.
"""

from __future__ import annotations

import abc
import argparse
import asyncio
import contextlib
import ctypes
import logging
import os
import signal
import sys
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from pathlib import Path
from types import FrameType
from typing import Self, TypeVar

import zenoh

from .bus import DEFAULT_ROUTER, MODES, Bus, BusOptions
from .errors import BusError, ServiceError
from .keys import check_chunk

_LOGGER = logging.getLogger(__name__)
T = TypeVar("T")


def argument_type(check: Callable[[str], T]) -> Callable[[str], T]:
    """An argparse type from a check that raises ValueError: the check's own message in the
    error instead of argparse's 'invalid value'."""

    def convert(text: str) -> T:
        try:
            return check(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc

    return convert


robot_name = argument_type(lambda text: check_chunk(text, "robot name"))
"""argparse type for a robot name."""


def positive_int(text: str) -> int:
    """argparse type for a count of 1 or more."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of 1 or more")
    return value


def positive_float(text: str) -> float:
    """argparse type for a number above 0 (a speed, a limit)."""
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 0.0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number above 0")
    return value


ZENOH_ENVIRONMENT = {
    "mode": "ZENOH_MODE",
    "connect": "ZENOH_CONNECT",
    "listen": "ZENOH_LISTEN",
    "config": "ZENOH_CONFIG",
    "cfg": "ZENOH_CFG",
}
"""Environment variables that stand in for the flags (containers): endpoints separated
by ',', settings by ';'. A flag on the command line wins over its variable."""


def add_bus_arguments(parser: argparse.ArgumentParser, router: bool = False) -> None:
    """The Zenoh flags every voicectl process shares, named as zenohd names them."""
    group = parser.add_argument_group(
        "Zenoh", "as zenohd's flags; each has an environment variable: ZENOH_MODE, ..."
    )
    if not router:
        group.add_argument(
            "--mode", choices=MODES, help="client (default), peer, or what --config says"
        )
    default_endpoint = "" if router else f"; default {DEFAULT_ROUTER}"
    group.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to connect to (repeatable{default_endpoint})",
    )
    group.add_argument(
        "--listen",
        action="append",
        metavar="ENDPOINT",
        help=f"endpoint to listen on (repeatable{'; default ' + DEFAULT_ROUTER if router else ''})",
    )
    group.add_argument(
        "--config",
        type=Path,
        metavar="FILE",
        help="a Zenoh JSON5 configuration (TLS, credentials...); the other flags override it",
    )
    group.add_argument(
        "--cfg",
        action="append",
        metavar="KEY:VALUE",
        help="set one configuration key to a JSON5 value, last (repeatable), e.g. "
        "transport/link/tx/lease:2000",
    )
    parser.add_argument("--debug", action="store_true", help="log at DEBUG level")
    parser.set_defaults(bus_prog=parser.prog)


def bus_options(
    args: argparse.Namespace,
    wait: bool = True,
    router: bool = False,
    environ: Mapping[str, str] = os.environ,
) -> BusOptions:
    """The options the flags (or their environment variables) give; a mistake in them
    ends the process now, in one line, rather than when the session opens."""

    def given(name: str, separator: str) -> list[str]:
        flag: list[str] | None = getattr(args, name, None)
        if flag:
            return flag
        text = environ.get(ZENOH_ENVIRONMENT[name], "")
        return [part.strip() for part in text.split(separator) if part.strip()]

    config_file: Path | None = args.config or (
        Path(environ["ZENOH_CONFIG"]) if environ.get("ZENOH_CONFIG") else None
    )
    mode: str | None = "router" if router else (args.mode or environ.get("ZENOH_MODE"))
    connect, listen = given("connect", ","), given("listen", ",")
    if config_file is None:
        mode = mode or "client"
        if router:
            listen = listen or [DEFAULT_ROUTER]
        elif not connect:
            connect = [DEFAULT_ROUTER]
    prog = getattr(args, "bus_prog", "voicectl")
    if mode is not None and mode not in MODES:
        _exit(prog, f"ZENOH_MODE {mode!r}: expected one of {', '.join(MODES)}")
    options = BusOptions(
        connect=connect,
        listen=listen,
        mode=mode,  # type: ignore[arg-type]  # checked just above
        wait=wait,
        config_file=config_file,
        settings=tuple(given("cfg", ";")),
    )
    try:
        options.zenoh_config()
    except BusError as exc:
        _exit(prog, str(exc))
    return options


def _exit(prog: str, message: str) -> None:
    print(f"{prog}: {message}", file=sys.stderr)
    raise SystemExit(2)


def setup_logging(debug: bool) -> None:
    """Logging for a service; the first thing each does, so also where a service started
    by `voicectl up` ties its life to it (`_die_with_parent`)."""
    logging.basicConfig(
        level=logging.DEBUG if debug else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    zenoh.init_log_from_env_or("error")
    # Until the service waits for its stop (wait_for_stop), SIGTERM unwinds like Ctrl-C:
    # a service stopped while it starts still closes its session and files.
    signal.signal(signal.SIGTERM, _stop_while_starting)
    _die_with_parent()


def _stop_while_starting(signum: int, _frame: object) -> None:
    raise SystemExit(0)


PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """When `voicectl up` started this process (VOICECTL_PARENT holds its pid): SIGTERM
    when it dies, even by SIGKILL, so that no service is left holding ports, the database
    or the robot (Linux). Done here, in the service itself, rather than between fork and
    exec, where a threaded parent may run nothing."""
    parent = os.environ.pop("VOICECTL_PARENT", "")
    if not parent.isdigit():
        return
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)  # this process's own C library
        libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    if os.getppid() != int(parent):  # it died before the line above took effect
        os.kill(os.getpid(), signal.SIGTERM)


HEARTBEAT_EVERY = 2.0
"""Seconds between touches of the heartbeat file."""


async def _heartbeat(path: Path) -> None:
    """Touch `path` while this process's event loop runs. A container's health check
    (compose.yaml) reads the file's age, which costs nothing, where a check that opens a
    Zenoh session costs 0.4 CPU-seconds; a blocked loop goes unhealthy too."""

    def touch() -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.touch()

    try:
        while True:
            await asyncio.to_thread(touch)
            await asyncio.sleep(HEARTBEAT_EVERY)
    except OSError as exc:
        _LOGGER.warning("no heartbeat (%s): the container will not report healthy", exc)
    finally:
        with contextlib.suppress(OSError):
            path.unlink()  # noqa: ASYNC240 - once, at the stop, in no hurry


async def wait_for_stop(*tasks: Awaitable[object]) -> None:
    """Return on SIGINT or SIGTERM; with `tasks`, also when one of them ends (re-raising
    its error), cancelling the others. Meanwhile, with VOICECTL_HEARTBEAT naming a file,
    the service is up and running: it touches the file (`_heartbeat`)."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()

    # Not loop.add_signal_handler: asyncio reads the signal's number from the pipe that
    # also wakes the loop for every Zenoh callback, and under a storm of them (a flood of
    # liveliness tokens going at once) the pipe is full and the SIGTERM is lost (the
    # service then ran until SIGKILL). A Python handler runs whatever the pipe holds.
    def on_signal(_sig: int, _frame: FrameType | None) -> None:
        loop.call_soon_threadsafe(stop.set)

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    beat = os.environ.get("VOICECTL_HEARTBEAT", "")
    running = [asyncio.ensure_future(t) for t in tasks]
    stopper = asyncio.ensure_future(stop.wait())
    beating = [asyncio.ensure_future(_heartbeat(Path(beat)))] if beat else []
    try:
        done, _ = await asyncio.wait([stopper, *running], return_when=asyncio.FIRST_COMPLETED)
        for task in done:
            if task is not stopper:
                task.result()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for task in [stopper, *running, *beating]:
            task.cancel()
        await asyncio.gather(stopper, *running, *beating, return_exceptions=True)


class Service(abc.ABC):
    """What every voicectl service is (the module's docstring says when each part runs);
    used as an async context manager, entering starts it and leaving stops it."""

    async def __aenter__(self) -> Self:
        await self.start()
        return self

    async def __aexit__(self, *_exc: object) -> None:
        await self.stop()

    @abc.abstractmethod
    async def start(self) -> None:
        """Declare and announce what it serves."""

    async def run(self) -> None:
        """Its ongoing work; by default none: it answers the bus until it is stopped."""
        await forever()

    @abc.abstractmethod
    async def stop(self) -> None:
        """Withdraw, stop what runs and let go of what it holds."""


def open_bus(args: argparse.Namespace) -> contextlib.AbstractContextManager[Bus]:
    """The Zenoh session the flags describe, on the running event loop."""
    return Bus.open(bus_options(args), asyncio.get_running_loop())


async def serve(*services: Service) -> None:
    """Enter `services` in order, run them until a stop signal or until one's `run()`
    ends (its error raised again), then leave them in the reverse order."""
    async with running(*services) as runs:
        await wait_for_stop(*runs)


@contextlib.asynccontextmanager
async def running(*services: Service) -> AsyncIterator[list[asyncio.Task[None]]]:
    """Enter `services` in order and run each one's `run()` as a task while the block
    lasts (the tasks are what it gives); then cancel the tasks and leave the services in
    the reverse order. `serve()` waits on it for a stop signal; a service inside another
    server's lifecycle (the panel's hub, in its ASGI lifespan) lives in its block."""
    async with contextlib.AsyncExitStack() as entered:
        for service in services:
            await entered.enter_async_context(service)
        runs = [asyncio.create_task(service.run()) for service in services]
        try:
            yield runs
        finally:
            for task in runs:
                task.cancel()
            await asyncio.gather(*runs, return_exceptions=True)


async def forever() -> None:
    """A `run()` for a service whose work is all in answering the bus."""
    await asyncio.get_running_loop().create_future()


def run_service(
    prog: str, args: argparse.Namespace, main: Callable[[argparse.Namespace], Awaitable[None]]
) -> int:
    """A service's process: logging as `args` say, then `main(args)`; the exit code, 0
    when it returns and 2 when it raises ServiceError, said on one line after `prog`."""
    setup_logging(args.debug)

    async def guarded() -> int:
        try:
            await main(args)
        except ServiceError as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 2
        return 0

    return asyncio.run(guarded())
