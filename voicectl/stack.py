"""`voicectl up`: the whole local stack as child processes, stopped together."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import FrameType
from typing import IO

import zenoh

from voicectl.shared.bus import BusOptions
from voicectl.shared.hints import voicectl_command

STOP_TIMEOUT = 10.0
START_TIMEOUT = 60.0
RESTARTS = 5
"""A service that crashes is started again, at most this many times within..."""
RESTART_WINDOW = 60.0
"""...this many seconds; past that, the stack stops."""


@dataclass(frozen=True)
class PanelAddress:
    """Where the panel listens, its address, and the address that logs a browser in."""

    host: str
    port: int
    address: str
    login: str
    """`address` with the token in its fragment: shown to a person only, never logged."""


@dataclass
class Child:
    """One service process of the stack, its output prefixed with its name."""

    name: str
    argv: list[str]
    process: subprocess.Popen[bytes] | None = None
    _pump: threading.Thread | None = field(default=None, repr=False)
    restarts: list[float] = field(default_factory=list)
    """When it was restarted after a crash (monotonic seconds)."""

    def start(self) -> None:
        self._close_output()
        # Own session: a Ctrl-C in the terminal reaches `voicectl up` alone, which then
        # stops the children (the services together, the router last). VOICECTL_PARENT
        # makes each service end with `voicectl up` even when it is killed
        # (shared.process): set by the child itself, since a fork of this threaded process
        # may run nothing before exec.
        self.process = subprocess.Popen(
            [sys.executable, "-m", *self.argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env={**os.environ, "VOICECTL_PARENT": str(os.getpid())},
        )
        self._pump = threading.Thread(
            target=_prefix_lines, args=(self.name, self.process.stdout), daemon=True
        )
        self._pump.start()

    def terminate(self) -> None:
        """Ask it to stop (SIGTERM), without waiting."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)

    def finish(self, deadline: float) -> None:
        """Wait for it to have stopped until `deadline` (monotonic), then kill it."""
        process = self.process
        if process is None:
            return
        try:
            process.wait(timeout=max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            print(f"voicectl up: {self.name} did not stop in {STOP_TIMEOUT:g} s; killing")
            process.kill()
            process.wait()
        self._close_output()

    def _close_output(self) -> None:
        if self._pump is not None:
            self._pump.join(timeout=2.0)
            self._pump = None
        if self.process is not None and self.process.stdout is not None:
            self.process.stdout.close()


STOP_STAGES = (
    frozenset({"supervisor", "stt", "converter", "listen"}),
    frozenset({"sim"}),
    frozenset({"router"}),
)
"""Who stops after whom on Ctrl-C; any other service (the panel, the executor) stops
first. The supervisor outlives the executor to record how the running order ended, the
robot outlives the executor that cancels its goal, the router outlives everyone."""


def stop_all(children: list[Child]) -> None:
    """Stop the services stage by stage (`STOP_STAGES`), those of a stage together, each
    given `STOP_TIMEOUT` before it is killed: one at a time, slow ones made Ctrl-C wait for
    the sum of their delays."""

    def stage(child: Child) -> int:
        return next((k + 1 for k, names in enumerate(STOP_STAGES) if child.name in names), 0)

    for current in range(len(STOP_STAGES) + 1):
        together = [child for child in reversed(children) if stage(child) == current]
        for child in together:
            child.terminate()
        deadline = time.monotonic() + STOP_TIMEOUT
        for child in together:
            child.finish(deadline)


def port_in_use(host: str, port: int) -> bool:
    """Whether something already listens on `host:port`. With SO_REUSEADDR, as every
    server sets it: connections of a stack just stopped, left in TIME_WAIT, do not count,
    while a port another process listens on still does."""
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError:
            return True
    return False


def _prefix_lines(name: str, stream: IO[bytes] | None) -> None:
    if stream is None:
        return
    for raw in iter(stream.readline, b""):
        line = raw.decode("utf-8", "replace").rstrip()
        print(f"{name:>10} | {line}", flush=True)


def wait_for_port(host: str, port: int, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with contextlib.suppress(OSError), socket.create_connection((host, port), timeout=0.5):
            return True
        time.sleep(0.1)
    return False


@contextlib.contextmanager
def _stop_signals() -> Iterator[threading.Event]:
    stop = threading.Event()

    def on_signal(_sig: int, _frame: FrameType | None) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def wait_for_tokens(
    router: str, keys: list[str], timeout: float, give_up: Callable[[], str]
) -> list[str]:
    """Wait until a liveliness token is up on each of `keys`, or until `give_up()` says
    why not (a child died, Ctrl-C); return those still missing."""
    missing = list(keys)
    deadline = time.monotonic() + timeout
    session = None
    while session is None:  # the router is a child too: it may not listen yet
        if give_up() or time.monotonic() > deadline:
            return missing
        with contextlib.suppress(zenoh.ZError):
            session = zenoh.open(BusOptions(connect=[router], wait=False).zenoh_config())
    with session:
        while missing and time.monotonic() < deadline and not give_up():
            missing = [
                key
                for key in missing
                if not any(r.ok is not None for r in session.liveliness().get(key, timeout=0.5))
            ]
            if missing:
                time.sleep(0.1)
    return missing


def _restart(child: Child, stop: threading.Event) -> bool:
    """Start a crashed service again, after a back-off that grows with each restart in
    `RESTART_WINDOW`; False when it has crashed too often (or a stop came meanwhile)."""
    assert child.process is not None
    code = child.process.returncode
    now = time.monotonic()
    child.restarts = [at for at in child.restarts if at > now - RESTART_WINDOW]
    if len(child.restarts) >= RESTARTS:
        print(
            f"voicectl up: {child.name} exited with {code}, the {RESTARTS + 1}th time in "
            f"{RESTART_WINDOW:g} s; stopping the stack",
            flush=True,
        )
        return False
    child.restarts.append(now)
    print(
        f"voicectl up: {child.name} exited with {code}; restarting "
        f"({len(child.restarts)}/{RESTARTS})",
        flush=True,
    )
    if stop.wait(0.25 * 2 ** (len(child.restarts) - 1)):
        return True  # stopping: the main loop sees it
    child.start()
    return True


def _print_panel(web: PanelAddress) -> None:
    """The panel's address: with the token that logs in when a person reads it on a
    terminal; without it when the output may be kept (a pipe, a file, a journal)."""
    if sys.stdout.isatty():
        print(f"voicectl up: panel on {web.login}", flush=True)
        return
    print(f"voicectl up: panel on {web.address}", flush=True)
    print(
        "voicectl up: its token is not printed where it could be logged: "
        f"`{voicectl_command('token')}` prints it",
        flush=True,
    )


def run_stack(
    children: list[Child],
    web: PanelAddress | None,
    router: str,
    ready_tokens: list[str],
) -> int:
    """Start `children` in order, wait for a signal or a death, stop them in reverse order."""
    started: list[Child] = []
    exit_code = 0
    with _stop_signals() as stop:

        def dead() -> list[Child]:
            return [c for c in started if c.process is not None and c.process.poll() is not None]

        def give_up() -> str:
            if stop.is_set():
                return "stopped"
            return ", ".join(
                f"{c.name} exited with {c.process.returncode}" for c in dead() if c.process
            )

        try:
            for child in children:
                child.start()
                started.append(child)
            missing = wait_for_tokens(router, ready_tokens, START_TIMEOUT, give_up)
            if web is not None and not give_up():
                host = "127.0.0.1" if web.host in ("0.0.0.0", "::") else web.host
                deadline = time.monotonic() + 30.0
                while not give_up() and time.monotonic() < deadline:
                    if wait_for_port(host, web.port, timeout=0.2):
                        break
            reason = give_up()
            if reason:
                print(f"voicectl up: {reason} while starting; stopping the stack", flush=True)
                return 0 if reason == "stopped" else 1
            if missing:
                print(f"voicectl up: not up after {START_TIMEOUT:g} s: {', '.join(missing)}")
            if web is not None:
                _print_panel(web)
            print("voicectl up: ready; Ctrl-C stops everything", flush=True)
            while not stop.wait(0.2):
                if not all(_restart(child, stop) for child in dead()):
                    exit_code = 1
                    break
        finally:
            stop_all(started)
            print("voicectl up: stopped", flush=True)
    return exit_code
