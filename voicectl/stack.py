"""`voicectl up`: the whole local stack as child processes, stopped together."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from types import FrameType
from typing import IO

import zenoh

from shared.bus import BusOptions

STOP_TIMEOUT = 10.0


@dataclass(frozen=True)
class Panel:
    """Where the panel listens, and the address that logs a browser in."""

    host: str
    port: int
    address: str


@dataclass
class Child:
    """One service process of the stack, its output prefixed with its name."""

    name: str
    argv: list[str]
    process: subprocess.Popen[bytes] | None = None
    _pump: threading.Thread | None = field(default=None, repr=False)

    def start(self) -> None:
        # Own session: a Ctrl-C in the terminal reaches `voicectl up` alone, which then
        # stops the children in order (web first, router last).
        self.process = subprocess.Popen(
            [sys.executable, "-m", *self.argv],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self._pump = threading.Thread(
            target=_prefix_lines, args=(self.name, self.process.stdout), daemon=True
        )
        self._pump.start()

    def stop(self) -> int | None:
        process = self.process
        if process is None:
            return None
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                print(f"voicectl up: {self.name} did not stop in {STOP_TIMEOUT:g} s; killing")
                process.kill()
                process.wait()
        if self._pump is not None:
            self._pump.join(timeout=2.0)
        if process.stdout is not None:
            process.stdout.close()
        return process.returncode


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


def wait_for_tokens(router: str, keys: list[str], timeout: float) -> list[str]:
    """Wait until a liveliness token is up on each of `keys`; return those still missing."""
    missing = list(keys)
    deadline = time.monotonic() + timeout
    with zenoh.open(BusOptions(connect=[router]).zenoh_config()) as session:
        while missing and time.monotonic() < deadline:
            missing = [
                key
                for key in missing
                if not any(r.ok is not None for r in session.liveliness().get(key, timeout=1.0))
            ]
            if missing:
                time.sleep(0.1)
    return missing


def run_stack(
    children: list[Child],
    web: Panel | None,
    router: str,
    ready_tokens: list[str],
) -> int:
    """Start `children` in order, wait for a signal or a death, stop them in reverse order."""
    started: list[Child] = []
    exit_code = 0
    with _stop_signals() as stop:
        try:
            for child in children:
                child.start()
                started.append(child)
            missing = wait_for_tokens(router, ready_tokens, timeout=60.0)
            if missing:
                print(f"voicectl up: not up after 60 s: {', '.join(missing)}", flush=True)
            if web is not None:
                host = "127.0.0.1" if web.host in ("0.0.0.0", "::") else web.host
                if wait_for_port(host, web.port, timeout=30.0):
                    print(f"voicectl up: panel on {web.address}", flush=True)
                else:
                    print(f"voicectl up: the panel did not open port {web.port} in 30 s")
            print("voicectl up: ready; Ctrl-C stops everything", flush=True)
            while not stop.wait(0.2):
                dead = [
                    c for c in started if c.process is not None and c.process.poll() is not None
                ]
                if dead:
                    for child in dead:
                        assert child.process is not None
                        print(
                            f"voicectl up: {child.name} exited with {child.process.returncode};"
                            " stopping the stack",
                            flush=True,
                        )
                    exit_code = 1
                    break
        finally:
            for child in reversed(started):
                child.stop()
    print("voicectl up: stopped", flush=True)
    return exit_code
