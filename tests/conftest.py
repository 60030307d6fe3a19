"""Shared fixtures: free loopback ports, a real Zenoh router, service processes that are
always stopped, and a Bus on the test's own event loop."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Coroutine, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn, TypeVar

import hypothesis
import pytest
import zenoh

from harness.ports import free_port, free_ports
from harness.processes import Processes
from harness.speech_set import Voice, real_recordings, speak
from harness.wait import async_wait_until, wait_until
from voicectl.shared.bus import Bus, BusOptions
from voicectl.shared.client import VoicectlClient
from voicectl.shared.messages import CancelAll, GetState, Release, StateReply
from voicectl.shared.robot import TransportKind

if TYPE_CHECKING:
    from .support import Site

REPO = Path(__file__).resolve().parents[1]

# Speed is measured in bench/, not here: on a busy machine hypothesis' default deadline (200
# ms per example) failed parses that take 2 ms on a quiet one.
hypothesis.settings.register_profile("voicectl", deadline=None)
hypothesis.settings.load_profile("voicectl")


Speak = Callable[..., Path]
T = TypeVar("T")


def cannot_run(why: str) -> NoReturn:
    """Skip the test, saying `why` it cannot run here; under CI (`CI` set), where every
    test is meant to run, fail it saying so instead (`.ci/run` lists every skip, and
    harness/skips.py fails the run on one that CI is meant to run)."""
    if os.environ.get("CI"):
        pytest.fail(f"{why} (CI is set: every test must run)", pytrace=False)
    pytest.skip(why)


@pytest.fixture(scope="session")
def anyio_backend() -> str:
    """Async tests run on asyncio, as the services do (anyio's plugin, in auto mode)."""
    return "asyncio"


@pytest.fixture(scope="session")
def speech(tmp_path_factory: pytest.TempPathFactory) -> Speak:
    """`speech(text, voice="flite:awb", speed=0)`: a WAV file of `text` spoken by a
    synthesizer (`flite:<voice>`, `festival:<voice>` or `espeak:<voice>` with `speed` in words
    per minute), 16 kHz mono with silence around it, made once per test run. Flite by
    default: the recogniser's second opinion cannot transcribe espeak-ng's formant speech,
    so espeak-ng commands are (rightly, for a voice no person has) mostly rejected."""
    directory = tmp_path_factory.mktemp("speech")

    def make(text: str, voice: str = "flite:awb", speed: int = 0) -> Path:
        source, _, name = voice.partition(":")
        return directory / speak(text, Voice(source, name, speed), directory).file

    return make


@pytest.fixture(scope="session")
def people(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """People's recordings from pocketsphinx's source distribution, by name ("real-goforward":
    a man saying "go forward ten meters"), fetched from PyPI once per test run."""
    directory = tmp_path_factory.mktemp("real") / "test"
    return {Path(u.file).stem: directory.parent / u.file for u in real_recordings(directory)}


@pytest.fixture
def router() -> Iterator[str]:
    """A real Zenoh router on a loopback port of its own; yields its endpoint."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    options = BusOptions(mode="router", connect=[], listen=[endpoint])
    session = zenoh.open(options.zenoh_config())
    try:
        yield endpoint
    finally:
        session.close()


class SmallDisk:
    """A filesystem of its own, small enough to fill: a tmpfs mounted for one test."""

    FILLER = "filler"

    def __init__(self, path: Path) -> None:
        self.path = path

    def fill(self) -> int:
        """Write until the disk refuses (ENOSPC); the bytes written."""
        written = 0
        fd = os.open(self.path / self.FILLER, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
        try:
            while True:
                written += os.write(fd, bytes(65536))
        except OSError as exc:
            if exc.errno != errno.ENOSPC:
                raise
        finally:
            os.close(fd)
        return written

    def free(self) -> None:
        """Give the space back."""
        (self.path / self.FILLER).unlink(missing_ok=True)


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[SmallDisk]:
    """A real 8 MB filesystem (tmpfs) at `tmp_path/disk`, unmounted after the test: what
    a full disk does to SQLite, for real (ENOSPC from the kernel), not a pragma's stand-in.
    Mounting needs root (CI runs as root); elsewhere the test is skipped, saying why."""
    path = tmp_path / "disk"
    path.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=8m,mode=0700", "tmpfs", str(path)],
        capture_output=True,
        text=True,
        check=False,
    )
    if mounted.returncode != 0:
        cannot_run(f"cannot mount a small tmpfs (needs root): {mounted.stderr.strip()}")
    try:
        yield SmallDisk(path)
    finally:
        subprocess.run(["umount", "--lazy", str(path)], check=False)


@pytest.fixture
def site(router: str, processes: Processes, tmp_path: Path) -> Site:
    """A router, and a supervisor with its database in `tmp_path`, started when asked."""
    from .support import Site  # support imports this module

    return Site(router, processes, tmp_path / "supervisor.sqlite3")


@pytest.fixture
def processes(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Processes]:
    procs = Processes(tmp_path)
    try:
        yield procs
    finally:
        unclean = procs.stop_all()
        report = getattr(request.node, "rep_call", None)
        if report is not None and report.failed:
            print(procs.dump())
    assert not unclean, f"processes did not stop cleanly: {unclean}\n{procs.dump()}"


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests that install voicectl afresh (a wheel in a new venv, `scripts/up` in a copy of
    the checkout) spend minutes in pip: they run in their own step, scripts/test-install,
    which CI runs after the README's test command (docs/deploy.md, "CI")."""
    if os.environ.get("VOICECTL_INSTALL"):
        return
    later = pytest.mark.skip(
        reason="installs voicectl afresh: runs in scripts/test-install (or with VOICECTL_INSTALL=1)"
    )
    for item in items:
        if item.get_closest_marker("install") is not None:
            item.add_marker(later)


@pytest.hookimpl(wrapper=True, tryfirst=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]):  # type: ignore[no-untyped-def]
    report = yield
    setattr(item, f"rep_{report.when}", report)
    return report


def voicectl(
    *args: str, timeout: float = 120.0, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run `voicectl ARGS...` from the repository and capture what it says."""
    command = [sys.executable, "-m", "voicectl", *args]
    return subprocess.run(
        command, capture_output=True, text=True, cwd=REPO, timeout=timeout, env=env, check=False
    )


@dataclass
class Stack:
    router: str
    port: int
    env: dict[str, str]
    process: subprocess.Popen[str]
    output: list[str] = field(default_factory=list)
    transport: TransportKind = TransportKind.BRIDGE
    """How the simulated robot shows its graph."""

    def voicectl(self, *args: str) -> subprocess.CompletedProcess[str]:
        return voicectl(*args, timeout=60, env=self.env)


@contextmanager
def started_stack(
    data: Path,
    transport: TransportKind = TransportKind.BRIDGE,
    orders: Path | None = REPO / "orders",
    command: Sequence[str] = (sys.executable, "-m", "voicectl"),
    cwd: Path = REPO,
    flags: Sequence[str] = (),
) -> Iterator[Stack]:
    """`voicectl up` (`command`, run in `cwd`: this checkout's by default) with its data in
    `data`, the simulator ten times faster than life, the `orders` (None: the ones the
    command ships) and its other `flags`, once it says it is ready; stopped with SIGINT, as a
    person would, and its output printed, on leaving."""
    router_port, port = free_ports(2)
    router = f"tcp/127.0.0.1:{router_port}"
    env = {**os.environ, "VOICECTL_DATA": str(data), "PYTHONUNBUFFERED": "1"}
    env.pop("VOICECTL_TOKEN", None)
    process = subprocess.Popen(
        [
            *command,
            "up",
            "--router",
            router,
            "--port",
            str(port),
            "--time-scale",
            "10",
            "--transport",
            transport.value,
            *(["--orders", str(orders)] if orders is not None else []),
            *flags,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        cwd=cwd,
        start_new_session=True,
    )
    running = Stack(router, port, env, process, transport=transport)

    def pump() -> None:
        assert process.stdout is not None
        for line in process.stdout:
            running.output.append(line.rstrip())

    reader = threading.Thread(target=pump, daemon=True)
    reader.start()
    try:
        wait_until(
            lambda: any("voicectl up: ready" in line for line in running.output) or process.poll(),
            60.0,
            "the stack to start",
        )
        assert process.poll() is None, "\n".join(running.output)
        yield running
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        reader.join(timeout=5)
        if process.stdout is not None:
            process.stdout.close()
        print("\n".join(running.output))


@pytest.fixture
def stack(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Stack]:
    """`voicectl up` with the simulator ten times faster than life; parametrize it
    (indirectly) with a transport to play a robot on rmw_zenoh."""
    transport: TransportKind = getattr(request, "param", TransportKind.BRIDGE)
    with started_stack(tmp_path / "data", transport) as running:
        yield running


@pytest.fixture
def photo_at_once_stack(tmp_path: Path) -> Iterator[Stack]:
    """`stack` with the shipped orders but for the tutorial's countdown before its photo
    (orders/tutorial.yaml's `wait: 5`, five seconds with nothing to look at): at once."""
    orders = tmp_path / "orders"
    shutil.copytree(REPO / "orders", orders)
    tutorial = orders / "tutorial.yaml"
    countdown = "      wait: 5\n"
    assert countdown in tutorial.read_text(), "the tutorial's photo order has changed"
    tutorial.write_text(tutorial.read_text().replace(countdown, "      wait: 0\n"))
    with started_stack(tmp_path / "data", orders=orders) as running:
        yield running


def on_stack_bus(stack: Stack, body: Callable[[Bus], Coroutine[Any, Any, T]]) -> T:
    """`body` run with a bus joined to the stack's router, in a thread of its own: a
    browser test's thread holds the event loop of Playwright's sync API."""
    from .support import on_bus  # support imports this module

    with ThreadPoolExecutor(1) as thread:
        return thread.submit(on_bus, stack.router, body).result(timeout=60)


def settle(stack: Stack) -> None:
    """The robot as the stack came up with it, but for its history and pose: the emergency
    stop released, the queue empty and no order running."""

    async def tidy(bus: Bus) -> None:
        client = VoicectlClient(bus)
        await client.ask("robot", Release())  # "was not on" when it was not
        await client.ask("robot", CancelAll())  # the running order too

        async def idle() -> bool:
            reply = await client.ask("robot", GetState())
            assert isinstance(reply, StateReply), reply
            known = reply.state
            return not (known.stopped or known.queue or known.current)

        await async_wait_until(idle, 30.0, "the robot released, with nothing to do")

    on_stack_bus(stack, tidy)


@pytest.fixture(scope="class")
def shared_stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    """One stack for the tests of a class (on each worker that runs some of them)."""
    with started_stack(tmp_path_factory.mktemp("stack") / "data") as running:
        yield running


class OnASettledStack:
    """For a class of tests that need of the stack only a robot released and idle, all its
    parts online (none moves the robot, restarts a part or reads the history): `stack` is
    one stack for them all, settled before each test, instead of one started for each
    (one on each worker that runs some of them: `--dist loadgroup`, which would keep a
    class on one worker, groups nothing with pytest 9.2, pytest-xdist issue 1386)."""

    @pytest.fixture
    def stack(self, shared_stack: Stack, request: pytest.FixtureRequest) -> Iterator[Stack]:
        assert shared_stack.process.poll() is None, "\n".join(shared_stack.output)
        settle(shared_stack)
        seen = len(shared_stack.output)
        yield shared_stack
        report = getattr(request.node, "rep_call", None)
        if report is not None and report.failed:  # what the stack said during the test
            print("\n".join(shared_stack.output[seen:]))
