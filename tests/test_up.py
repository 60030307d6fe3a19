"""`voicectl up` and the commands under faults: nothing hangs, nothing is left behind,
a second stack does not touch the first one's data."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from harness.client import Client
from harness.ports import free_port, free_ports
from harness.wait import wait_until
from voicectl.shared.bus import Bus
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import OrderStatus
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Ros2Codec
from voicectl.stack import Child, port_in_use, wait_for_port

from .conftest import REPO, Stack, started_stack, voicectl
from .support import on_bus
from .test_hints import BARE_PATH, hint, run_as_written

pytestmark = pytest.mark.e2e


def test_a_command_without_a_router_fails_in_seconds_naming_it() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    done = voicectl("state", "--connect", endpoint)
    assert time.monotonic() - started < 15.0
    assert done.returncode == 3
    path = os.environ["PATH"]
    up, router = (hint(f"voicectl_command('{c}')", REPO, path) for c in ("up", "router"))
    assert done.stderr.splitlines() == [
        f"voicectl state: cannot reach the router at {endpoint} "
        f"(waited 3 s; is {up} or {router} running?)"
    ]


def test_a_service_waiting_for_the_router_stops_on_sigterm(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with subprocess.Popen(
        [sys.executable, "-m", "voicectl.services.converter", "--connect", endpoint],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as process:
        try:
            # Well into the wait for the router: its first warning says so (after 10 s),
            # where a fixed sleep sent the signal before the handler was in place on a
            # busy machine.
            assert process.stdout is not None
            said = []
            for line in process.stdout:
                said.append(line)
                if "still waiting for the router" in line:
                    break
            else:
                raise AssertionError(f"it ended without waiting for the router: {said}")
            process.send_signal(signal.SIGTERM)
            rest, _ = process.communicate(timeout=10)
            output = "".join(said) + rest
        finally:
            if process.poll() is None:
                process.kill()
    assert process.returncode == 0
    assert "stopped (SIGTERM) while waiting for the router" in output


STORM = """
import asyncio, os, signal, threading
from voicectl.shared.process import wait_for_stop

async def main():
    loop = asyncio.get_running_loop()

    def storm():  # what Zenoh's threads do when thousands of tokens go at once
        for _ in range(100_000):
            loop.call_soon_threadsafe(lambda: None)

    def blocked_through_the_storm():
        thread = threading.Thread(target=storm)
        thread.start()
        thread.join()
        os.kill(os.getpid(), signal.SIGTERM)  # while the loop's wake-up pipe is full

    loop.call_soon(blocked_through_the_storm)
    await wait_for_stop()
    print("stopped", flush=True)

asyncio.run(main())
"""


def test_sigterm_is_not_lost_in_a_storm_of_callbacks() -> None:
    """A flood of 2,000 made-up robots going at once filled the supervisor's wake-up pipe
    with Zenoh's callbacks, and the SIGTERM that came then was lost: the supervisor ran
    on until SIGKILL. The same storm, made here on purpose: the service stops."""
    done = subprocess.run(
        [sys.executable, "-c", STORM],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,  # under a second, stopped; lost, it never ends
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == "stopped\n", done.stderr


def test_a_second_stack_refuses_to_start_on_a_busy_port(stack: Stack) -> None:
    router_busy = stack.voicectl("up", "--router", stack.router, "--port", str(free_port()))
    assert router_busy.returncode == 2
    assert router_busy.stderr.strip() == (
        f"voicectl up: {stack.router} is in use: is another voicectl up or router running there?"
    )
    other_router = f"tcp/127.0.0.1:{free_port()}"
    panel_busy = stack.voicectl("up", "--router", other_router, "--port", str(stack.port))
    assert panel_busy.returncode == 2
    assert f"port {stack.port} on 127.0.0.1 is in use" in panel_busy.stderr


def test_a_second_stack_on_the_same_data_stops_at_once(stack: Stack) -> None:
    started = time.monotonic()
    router_port, port = free_ports(2)
    second = stack.voicectl(
        "up",
        *("--router", f"tcp/127.0.0.1:{router_port}", "--port", str(port)),
        "--no-stt",
    )
    assert time.monotonic() - started < 40.0
    assert second.returncode == 1
    assert "is in use by another supervisor" in second.stdout
    assert "supervisor exited with 2 while starting; stopping the stack" in second.stdout
    # the first stack still serves
    assert stack.voicectl("state", "--connect", stack.router).returncode == 0


def pids(pattern: str) -> list[int]:
    """The processes whose command line matches `pattern` (a regular expression)."""
    found = subprocess.run(["pgrep", "-f", "--", pattern], capture_output=True, text=True)
    return [int(pid) for pid in found.stdout.split()]


def test_killing_up_leaves_no_service_behind(stack: Stack) -> None:
    assert len(pids(f"--connect {stack.router}")) >= 5
    os.kill(stack.process.pid, signal.SIGKILL)

    def none_left() -> bool:
        return not pids(f"--connect {stack.router}")

    # Each service notices and stops cleanly (halting the robot first): seconds apiece
    # on a loaded machine, so the bound is generous; what matters is that none is left.
    wait_until(none_left, 45.0, "every service of the killed stack to exit")


def test_ctrl_c_during_start_up_stops_everything(tmp_path: Path) -> None:
    router = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "VOICECTL_DATA": str(tmp_path / "data"), "PYTHONUNBUFFERED": "1"}
    lines: list[str] = []
    # The executor's start-up import takes a minute: the stack cannot be ready before.
    slow = ["--executor", "tests.slow_import_executor:Never", "--no-stt"]
    command = ["up", "--router", router, "--port", str(free_port()), *slow]
    with subprocess.Popen(
        [sys.executable, "-m", "voicectl", *command],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    ) as process:
        assert process.stdout is not None
        reader = threading.Thread(target=lambda: lines.extend(process.stdout or ()), daemon=True)
        reader.start()
        with interrupted(process, reader):
            # A child has said something: the stack is starting, and not ready yet.
            wait_until(lambda: any(" | " in line for line in lines), 60.0, "a child's output")
            assert not any("voicectl up: ready" in line for line in lines)
    output = "".join(lines)
    assert process.returncode == 0, output
    assert "voicectl up: stopped while starting; stopping the stack" in output
    assert "voicectl up: ready" not in output
    left = subprocess.run(
        ["pgrep", "-f", "--", f"--connect {router}"], capture_output=True, text=True, check=False
    )
    assert not left.stdout.strip()


def test_a_port_left_in_time_wait_is_free_but_a_listened_one_is_not() -> None:
    """`voicectl up` right after a clean stop: the old connections wait in TIME_WAIT on
    the router's port, which must not read as 'in use'; a listener still does."""
    with socket.socket() as listener:
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        assert port_in_use("127.0.0.1", port)
        client = socket.create_connection(("127.0.0.1", port))
        served, _ = listener.accept()
        served.close()  # the server side closes first: its port enters TIME_WAIT
        client.close()
    assert not port_in_use("127.0.0.1", port)


def test_a_crashed_service_is_restarted_and_the_stack_stays_up(stack: Stack) -> None:
    """One executor crash no longer takes the panel and the STOP path down with it."""

    def executor_pid() -> int | None:
        found = pids(f"voicectl.services.executor .*--connect {stack.router}")
        return found[0] if len(found) == 1 else None

    first = executor_pid()
    assert first is not None
    os.kill(first, signal.SIGKILL)
    wait_until(
        lambda: "voicectl up: executor exited with -9; restarting (1/5)" in stack.output,
        20.0,
        "the restart to be announced",
    )

    def online_again() -> bool:
        state = stack.voicectl("state", "--connect", stack.router)
        return state.returncode == 0 and json.loads(state.stdout)["executor_online"]

    wait_until(online_again, 40.0, "a new executor online")
    assert executor_pid() not in (None, first)
    assert stack.process.poll() is None
    assert wait_for_port("127.0.0.1", stack.port, timeout=5.0)  # the panel never left


def test_children_start_without_code_between_fork_and_exec(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A preexec_fn runs Python in the child of a threaded parent between fork and exec,
    which Python documents as unsafe (the old one even spawned ldconfig there): the
    child ties its life to `voicectl up` itself, told by VOICECTL_PARENT."""
    seen: dict[str, object] = {}

    class Recorder:
        def __init__(self, argv: list[str], **kwargs: object) -> None:
            seen.update(kwargs)
            self.stdout = None

    monkeypatch.setattr(subprocess, "Popen", Recorder)
    Child("sim", ["voicectl.services.sim"]).start()
    assert "preexec_fn" not in seen
    assert seen["start_new_session"] is True
    env = seen["env"]
    assert isinstance(env, dict)
    assert env["VOICECTL_PARENT"] == str(os.getpid())


def test_a_forged_owner_token_does_not_stop_the_stack(stack: Stack) -> None:
    """Issue 32, item 3: an owner token held by no supervisor made the stack's supervisor
    stand down at every restart, and after the sixth `voicectl up` stopped everything. Now
    the supervisor serving keeps the robot, and one (re)started beside the token serves."""

    async def forge(bus: Bus) -> None:
        bus.announce(RobotKeys("robot").supervisor_owner("0-forged"))
        (supervisor,) = pids(f"voicectl.services.supervisor .*--connect {stack.router}")
        os.kill(supervisor, signal.SIGKILL)
        await asyncio.to_thread(
            wait_until,
            lambda: "voicectl up: supervisor exited with -9; restarting (1/5)" in stack.output,
            20.0,
            "the restart to be announced",
        )
        await asyncio.to_thread(
            wait_until,
            lambda: stack.voicectl("state", "--connect", stack.router).returncode == 0,
            40.0,
            "the restarted supervisor to serve beside the forged token",
        )

    on_bus(stack.router, forge)
    assert stack.process.poll() is None
    assert not any("stopping the stack" in line for line in stack.output)
    assert any("Zenoh id 0-forged, which does not answer" in line for line in stack.output)


@pytest.mark.parametrize("output", ["pipe", "terminal"])
def test_the_login_address_goes_to_a_terminal_never_to_a_log(tmp_path: Path, output: str) -> None:
    """The token in the panel's address logs a person in with one click; where the
    output may be kept (a pipe, a file, a journal) the address comes without it, and the
    command that prints it runs as written (from a clone, with nothing on PATH)."""
    router_port, port = free_ports(2)
    data = tmp_path / "data"
    env = {**os.environ, "VOICECTL_DATA": str(data), "PYTHONUNBUFFERED": "1", "PATH": BARE_PATH}
    env.pop("VOICECTL_TOKEN", None)
    command = ["up", "--router", f"tcp/127.0.0.1:{router_port}", "--port", str(port), "--no-stt"]
    reading, writing = os.openpty() if output == "terminal" else os.pipe()
    said: list[str] = []

    def read() -> None:
        while True:
            try:
                chunk = os.read(reading, 4096)
            except OSError:  # a terminal whose other side closed
                return
            if not chunk:
                return
            said.append(chunk.decode("utf-8", "replace"))

    process = subprocess.Popen(
        [sys.executable, "-m", "voicectl", *command],
        cwd=REPO,
        env=env,
        stdout=writing,
        stderr=writing,
        start_new_session=True,
    )
    os.close(writing)
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        with interrupted(process, reader):
            wait_until(
                lambda: "voicectl up: ready" in "".join(said) or process.poll() is not None,
                60.0,
                "the stack to start",
            )
    finally:
        os.close(reading)
    lines = "".join(said).replace("\r\n", "\n").splitlines()
    assert process.returncode == 0, lines
    token = (data / "token").read_text().strip()
    address = f"http://127.0.0.1:{port}/"
    if output == "terminal":
        assert f"voicectl up: panel on {address}#token={token}" in lines
    else:
        assert f"voicectl up: panel on {address}" in lines
        said = lines[lines.index(f"voicectl up: panel on {address}") + 1]
        assert said.endswith("` prints it"), said
        command = said.split("`")[1]
        printed = run_as_written(command, REPO, BARE_PATH, VOICECTL_DATA=str(data))
        assert printed.stdout.strip() == token, (command, printed.stderr)
        assert not [line for line in lines if token in line]


@contextlib.contextmanager
def interrupted(process: subprocess.Popen[Any], reader: threading.Thread) -> Iterator[None]:
    """Ctrl-C `process` (as a terminal does) once the block has run, and wait for it and
    its output; its whole group killed if it is still there, on failure too."""
    try:
        yield
        process.send_signal(signal.SIGINT)
        process.wait(timeout=30)
        reader.join(timeout=10)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def test_the_speed_limits_of_up_reach_its_executor_and_nav2(tmp_path: Path) -> None:
    """Issue 43: `voicectl up` took no speed limits. Its --max-speed (or VOICECTL_MAX_SPEED)
    now reaches its executor, which tells the robot's navigation (the simulator plays Nav2's
    controller) before each goal: "reach the kitchen" drives at 0.2 m/s at most."""
    extra = ("--no-stt", "--no-web", "--max-speed", "0.2")
    with started_stack(tmp_path / "data", flags=extra) as stack:

        async def drive(bus: Bus) -> list[float]:
            loop = asyncio.get_running_loop()
            driven: list[tuple[float, float]] = []
            bus.subscribe(
                RobotNames().odom,
                Ros2Codec().read_odometry,
                lambda _key, odom: driven.append((loop.time(), odom.linear_x)),
            )
            said = await asyncio.to_thread(
                stack.voicectl, "say", "--connect", stack.router, "reach the kitchen"
            )
            assert said.returncode == 0, said.stderr
            [order_id] = json.loads(said.stdout)["order_ids"]
            client = Client(bus, "robot")
            record = await client.finished(order_id, timeout=60.0)
            assert record.status is OrderStatus.SUCCEEDED, record
            return [speed for _, speed in driven]

        driven = on_bus(stack.router, drive)
    assert 0.15 < max(driven) <= 0.2 + 1e-9, max(driven)
    assert any("navigation held to 0.2 m/s (speed_limit)" in line for line in stack.output)
