"""The whole local stack for a benchmark: `voicectl up` with a data directory and free
ports of its own (`stack_up`), and its services by name (`children`)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

from harness.ports import free_ports
from harness.processes import REPO


def children(pid: int) -> dict[str, int]:
    """The stack's services by name (from their command lines), with their pids."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            status = (entry / "status").read_text()
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        parent = next(
            int(line.split()[1]) for line in status.splitlines() if line.startswith("PPid")
        )
        if parent == pid and len(argv) > 2 and argv[1] == b"-m":
            found[argv[2].decode().rsplit(".", 1)[-1]] = int(entry.name)
    return found


@contextlib.contextmanager
def stack_up(
    prefix: str, *flags: str
) -> Iterator[tuple[subprocess.Popen[str], list[str], Path, int, str]]:
    """`voicectl up` with a data directory and free ports of its own, once it says it is
    ready: the process, its output lines (kept as they come), the data directory, the
    panel's port and the router's endpoint. Exits saying why when it does not come up. On
    leaving, the stack is stopped with SIGINT, as a person would, and its data directory
    removed, however the benchmark ended."""
    with tempfile.TemporaryDirectory(prefix=prefix, ignore_cleanup_errors=True) as data:
        port, router_port = free_ports(2)
        router = f"tcp/127.0.0.1:{router_port}"
        env = {**os.environ, "VOICECTL_DATA": data, "PYTHONUNBUFFERED": "1"}
        env.pop("VOICECTL_TOKEN", None)
        up_command = ["voicectl", "up", "--router", router, "--port", str(port), *flags]
        up = subprocess.Popen(
            [sys.executable, "-m", *up_command],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            cwd=REPO,
        )
        lines: list[str] = []
        ready = threading.Event()

        def pump() -> None:
            assert up.stdout is not None
            for line in up.stdout:
                lines.append(line.rstrip())
                if "voicectl up: ready" in line:
                    ready.set()

        threading.Thread(target=pump, daemon=True).start()
        try:
            if not ready.wait(120):
                sys.exit("the stack did not come up:\n" + "\n".join(lines[-30:]))
            yield up, lines, Path(data), port, router
        finally:
            up.send_signal(signal.SIGINT)
            up.wait(60)
