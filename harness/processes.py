"""Child processes for the tests and the benchmarks: `python -m <module>` from the
checkout, each with a log file of its own, and always stopped at the end (SIGTERM, then
SIGKILL to its whole session if it does not exit)."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

Process = subprocess.Popen[bytes]


class Processes:
    """The children started here, by name, with their logs under `logs` and their data
    (the supervisor's database) under `logs/data`."""

    def __init__(self, logs: Path) -> None:
        self.logs = logs
        self.started: list[tuple[str, Process, Path]] = []

    def start(
        self,
        module: str,
        *args: str,
        name: str | None = None,
        prefix: Sequence[str] = (),
        python: str | Path | None = None,
        env: Mapping[str, str] | None = None,
    ) -> Process:
        """`python -m module args`, run through `prefix` when given (a command that execs
        the next, as `ip netns exec NS` does), by another `python` (a venv of real ROS 2)
        and with another `env` when given; its output goes to its log."""
        name = name or module.rsplit(".", 1)[-1]
        log = self.logs / f"{name}-{len(self.started)}.log"
        env = {
            **(os.environ if env is None else env),
            "PYTHONUNBUFFERED": "1",
            "VOICECTL_DATA": str(self.logs / "data"),
        }
        with log.open("wb") as out:
            process = subprocess.Popen(
                [*prefix, str(python or sys.executable), "-m", module, *args],
                stdout=out,
                stderr=subprocess.STDOUT,
                cwd=REPO,
                env=env,
                start_new_session=True,
            )
        self.started.append((name, process, log))
        return process

    def supervisor(
        self, router: str, robot: str, db: Path, *args: str, name: str | None = None
    ) -> Process:
        """A supervisor on `router` serving `robot` from its start, with its database at
        `db` (which outlives it: a supervisor started again finds what this one stored)
        and `args`, its other flags."""
        return self.start(
            "voicectl.services.supervisor",
            *("--connect", router, "--robot", robot, "--db", str(db), *args),
            name=name,
        )

    def executor(self, router: str, robot: str, *args: str) -> Process:
        """An executor on `router` for `robot`, with `args`, its other flags."""
        return self.start(
            "voicectl.services.executor", "--connect", router, "--robot", robot, *args
        )

    def log(self, which: Process | str) -> str:
        """What a child (or the last one started under that name) has written so far."""
        for name, process, log in reversed(self.started):
            if process is which or name == which:
                return log.read_text(errors="replace")
        raise KeyError(which)

    @staticmethod
    def stop(process: Process, timeout: float = 10.0) -> int:
        """SIGTERM, wait, and SIGKILL its whole session if it does not stop; the exit code."""
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        return process.returncode

    @staticmethod
    def kill(process: Process) -> None:
        process.send_signal(signal.SIGKILL)
        process.wait()

    def stop_all(self) -> list[str]:
        """Stop every child, newest first; name those that did not exit 0 on SIGTERM."""
        unclean = []
        for name, process, _ in reversed(self.started):
            was_running = process.poll() is None
            code = self.stop(process)
            if was_running and code != 0:
                unclean.append(f"{name} exited {code}")
        return unclean

    def dump(self) -> str:
        """The end of every child's log, for a failed test's report."""
        return "\n".join(
            f"----- {name} -----\n{log.read_text(errors='replace')[-4000:]}"
            for name, _, log in self.started
        )


def rss_mb(pid: int, field: str = "VmRSS") -> float:
    """A process's resident memory (VmHWM: its peak), in MB; NaN once it has gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(field):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")
