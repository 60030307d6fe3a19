"""`voicectl health`: 0 when the service is up, 1 when it is not, one line either way."""

from __future__ import annotations

import http.server
import threading
from collections.abc import Iterator

import pytest
import zenoh

from harness.ports import free_port
from voicectl.health import SERVICES, token_key
from voicectl.shared.bus import BusOptions
from voicectl.shared.keys import ConverterKeys, RobotKeys
from voicectl.shared.robot.keys import RobotNames

from .conftest import voicectl


def test_each_service_is_checked_by_its_own_token() -> None:
    assert token_key("converter", "r1") == ConverterKeys().alive()
    for service in ("stt", "supervisor", "executor"):
        assert token_key(service, "r1") == RobotKeys("r1").alive(service)
    assert token_key("sim", "r1", "bot1") == RobotNames("bot1").simulator
    assert token_key("router", "r1") is None
    assert set(SERVICES) == {"router", "converter", "stt", "supervisor", "executor", "sim", "web"}


@pytest.fixture
def client(router: str) -> Iterator[zenoh.Session]:
    session = zenoh.open(BusOptions(connect=[router]).zenoh_config())
    try:
        yield session
    finally:
        session.close()


def test_a_service_is_up_while_its_token_is_there(router: str, client: zenoh.Session) -> None:
    token = client.liveliness().declare_token(RobotKeys("r1").alive("stt"))
    up = voicectl("health", "stt", "--robot", "r1", "--connect", router)
    assert (up.returncode, up.stdout) == (0, "stt of robot 'r1' is up (voice/r1/alive/stt)\n")
    assert up.stderr == ""
    token.undeclare()
    down = voicectl("health", "stt", "--robot", "r1", "--connect", router)
    assert down.returncode == 1
    assert down.stderr == (
        "voicectl health: stt of robot 'r1' is not up: no liveliness token on voice/r1/alive/stt\n"
    )
    other = voicectl("health", "stt", "--robot", "r2", "--connect", router)
    assert other.returncode == 1, "another robot's token does not count"


def test_the_converter_and_the_simulator(router: str, client: zenoh.Session) -> None:
    tokens = [client.liveliness().declare_token(k) for k in (ConverterKeys().alive(),)]
    tokens.append(client.liveliness().declare_token(RobotNames("bot1").simulator))
    assert voicectl("health", "converter", "--connect", router).returncode == 0
    sim = voicectl("health", "sim", "--namespace", "bot1", "--connect", router)
    assert (sim.returncode, sim.stdout) == (
        0,
        "sim in namespace 'bot1' is up (bot1/voicectl_sim/alive)\n",
    )
    assert voicectl("health", "sim", "--connect", router).returncode == 1
    for token in tokens:
        token.undeclare()


def test_the_router_is_up_when_a_session_opens(router: str) -> None:
    up = voicectl("health", "router", "--connect", router)
    assert (up.returncode, up.stdout) == (0, f"router at {router} is up\n")


def test_without_a_router_nothing_is_up_and_the_status_is_1() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    down = voicectl("health", "supervisor", "--connect", endpoint)
    assert down.returncode == 1
    (line,) = down.stderr.splitlines()
    assert line.startswith(
        f"voicectl health: supervisor of robot 'robot' is not reachable: cannot reach the "
        f"router at {endpoint}"
    )


class _Health(http.server.BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        self.send_response(200 if self.path == "/api/health" else 404)
        self.end_headers()

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def panel() -> Iterator[str]:
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Health)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


def test_the_panel_is_up_when_its_health_address_answers(panel: str) -> None:
    up = voicectl("health", "web", "--url", f"{panel}/api/health")
    assert (up.returncode, up.stdout) == (0, f"panel at {panel}/api/health is up\n")
    wrong = voicectl("health", "web", "--url", f"{panel}/nothing")
    assert (wrong.returncode, wrong.stderr) == (
        1,
        f"voicectl health: panel at {panel}/nothing is not up: HTTP 404\n",
    )
    closed = f"http://127.0.0.1:{free_port()}/api/health"
    down = voicectl("health", "web", "--url", closed)
    assert down.returncode == 1
    assert down.stderr.startswith(f"voicectl health: panel at {closed} is not up: ")


def test_a_web_address_must_be_http() -> None:
    done = voicectl("health", "web", "--url", "file:///etc/passwd")
    assert done.returncode == 2
    assert "'file:///etc/passwd' is not an http:// or https:// address" in done.stderr


def test_without_a_name_every_service_is_checked_a_line_each(
    router: str, client: zenoh.Session, panel: str
) -> None:
    """`voicectl health` alone: one line per service on stdout, in SERVICES' order, and
    exit status 1 until every one is up."""
    url = ("--url", f"{panel}/api/health")
    tokens = [
        client.liveliness().declare_token(key)
        for key in (ConverterKeys().alive(), RobotKeys("r1").alive("supervisor"))
    ]
    some = voicectl("health", "--robot", "r1", "--connect", router, *url)
    assert some.returncode == 1
    assert some.stderr == ""
    lines = some.stdout.splitlines()
    assert lines == [
        f"up    router at {router} is up",
        "up    converter is up (voice/converter/alive)",
        "DOWN  stt of robot 'r1' is not up: no liveliness token on voice/r1/alive/stt",
        "up    supervisor of robot 'r1' is up (voice/r1/alive/supervisor)",
        "DOWN  executor of robot 'r1' is not up: no liveliness token on voice/r1/alive/executor",
        "DOWN  sim is not up: no liveliness token on voicectl_sim/alive",
        f"up    panel at {panel}/api/health is up",
    ]
    tokens += [
        client.liveliness().declare_token(key)
        for key in (
            RobotKeys("r1").alive("stt"),
            RobotKeys("r1").alive("executor"),
            RobotNames().simulator,
        )
    ]
    every = voicectl("health", "--robot", "r1", "--connect", router, *url)
    assert every.returncode == 0, every.stdout
    assert [line.split()[0] for line in every.stdout.splitlines()] == ["up"] * len(SERVICES)
    for token in tokens:
        token.undeclare()
