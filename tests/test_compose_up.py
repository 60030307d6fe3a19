"""The repository's compose.yaml run for real with `docker compose` (profiles host and
sim): on the secured bus by default, its secrets made on the first start and kept on the
next, orders said in the panel's container and from this machine (with credentials made
portable) carried out by the simulator, the panel behind its token, history and secrets
kept across a restart, the panel's credentials moving nothing, no client without
credentials; and, with compose.open.yaml (the open bus of a lab), the robot stopped by
its own router's executor when its link to the host is cut. `docker compose down -v`
leaves nothing behind.

Needs a Docker engine, Compose v2 and the images' base (tests/containers.py); `.ci/run`
prepares them on a machine that has none. Where Docker Hub cannot be reached, it sets
COMPOSE_FILE=compose.yaml:compose.standin.yaml: voicectl's own router stands in for
the eclipse/zenoh image (docs/deploy.md).
"""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from harness.client import Client, client_wait_ready
from harness.ports import free_ports
from voicectl.shared.bus import BusOptions
from voicectl.shared.messages import OrderStatus

from .conftest import REPO
from .containers import base_image, skip_unless, stack_unavailable
from .support import on_bus

pytestmark = [skip_unless(stack_unavailable()), pytest.mark.timeout(900)]
"""A first build of the images takes minutes on a slow machine."""

LEASE = 3.0
"""The routers' lease (deploy/zenoh/*.json5): how long a cut link goes unnoticed."""
TOKEN = "compose-test-token"

WATCH = """
import json, sys, time, zenoh
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Ros2Codec
codec, seen = Ros2Codec(), []
if sys.argv[1].endswith(".json5"):  # a client configuration of the secured bus
    config = zenoh.Config.from_file(sys.argv[1])
else:
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([sys.argv[1]]))
with zenoh.open(config) as session:
    session.declare_subscriber(
        RobotNames().odom, lambda s: seen.append(codec.read_odometry(s.payload.to_bytes()))
    )
    time.sleep(float(sys.argv[2]))
odometry = seen[-1]
pose = odometry.pose
print(json.dumps([pose.x, pose.y, odometry.linear_x, odometry.angular_z, pose.yaw]))
"""
"""Run in the simulator's container, on the robot's side of the link: the robot's last
odometry (x, y, linear and angular speed, heading), as the secured router relays it (with
a client configuration), or the robot's own router on the open bus."""

INTRUDE = """
import json, time, zenoh
from voicectl.shared.keys import RobotKeys
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Ros2Codec
with zenoh.open(zenoh.Config.from_file("/etc/voicectl/bus/panel.json5")) as session:
    for _ in range(20):
        session.put(RobotNames().cmd_vel, Ros2Codec().twist(0.5, 0.0))
        time.sleep(0.05)
    asked = RobotKeys("robot").executor_execute
    replies = list(session.get(asked, payload=b"{}", timeout=2.0))
print(json.dumps(len(replies)))
"""
"""Run in the panel's container with the panel's credentials: drive the robot, and ask
the executor to run something; how many answers came."""


class Stack:
    """One compose project of the repository's compose.yaml, on ports of its own, with a
    fixed panel token; every command through `compose`."""

    def __init__(self, tmp_path: Path, *extra: str) -> None:
        self.project = f"voicectl-test-{uuid.uuid4().hex[:8]}"
        self.tmp_path = tmp_path
        # An overlay right after compose.yaml: the stand-in, if any, replaces its images.
        first, *rest = (os.environ.get("COMPOSE_FILE") or "compose.yaml").split(":")
        files = ":".join([first, *extra, *rest])
        self.router_port, self.panel_port = free_ports(2)
        self.log = tmp_path / "compose.log"
        self.env = {
            **os.environ,
            "COMPOSE_PROJECT_NAME": self.project,
            "COMPOSE_PROFILES": "host,sim",
            "VOICECTL_BASE_IMAGE": base_image(),
            "VOICECTL_ROUTER_PUBLISH": f"127.0.0.1:{self.router_port}",
            "VOICECTL_PANEL_PUBLISH": f"127.0.0.1:{self.panel_port}",
            "VOICECTL_TOKEN": TOKEN,
            "COMPOSE_FILE": files,
        }

    @property
    def router(self) -> str:
        return f"tcp/127.0.0.1:{self.router_port}"

    def compose(self, *args: str, timeout: float = 300.0, stdin: str | None = None) -> str:
        done = subprocess.run(
            ["docker", "compose", *args],
            input=stdin,
            capture_output=True,
            text=True,
            cwd=REPO,
            env=self.env,
            timeout=timeout,
        )
        with self.log.open("a") as log:
            log.write(f"$ docker compose {' '.join(args)}\n{done.stdout}{done.stderr}\n")
        assert done.returncode == 0, f"docker compose {args[0]}: {done.stderr[-2000:]}"
        return done.stdout

    def docker(self, *args: str, stdin: str | None = None) -> str:
        done = subprocess.run(
            ["docker", *args], input=stdin, capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 0, f"docker {args[0]}: {done.stderr[-2000:]}"
        return done.stdout

    def container(self, service: str) -> str:
        return f"{self.project}-{service}-1"

    @property
    def secured_router(self) -> str:
        return f"tls/127.0.0.1:{self.router_port}"

    def credentials(self, user: str) -> Path:
        """`user`'s client configuration made portable by the panel's container, as the
        docs say a host command gets it, saved mode 0600."""
        printed = self.compose(
            *("exec", "-T", "web", "voicectl", "bus-secrets", "/etc/voicectl/bus"),
            *("--client", user, "--endpoint", self.secured_router),
        )
        path = self.tmp_path / f"{user}.json5"
        path.touch(mode=0o600)
        path.write_text(printed)
        return path

    def odometry(self, listen: float = 0.3, via: str = "tcp/robot-side:7447") -> list[float]:
        """The simulator's last odometry, read beside it on the robot's network."""
        out = self.docker(
            *("exec", "-i", self.container("sim"), "python3", "-", via, str(listen)),
            stdin=WATCH,
        )
        found: list[float] = json.loads(out)
        return found

    def panel(self, path: str, token: str | None = TOKEN) -> tuple[int, object]:
        request = urllib.request.Request(f"http://127.0.0.1:{self.panel_port}{path}")
        if token is not None:
            request.add_header("Authorization", f"Bearer {token}")
        try:
            with urllib.request.urlopen(request, timeout=10) as answer:
                return answer.status, json.loads(answer.read())
        except urllib.error.HTTPError as error:
            return error.code, json.loads(error.read())

    def leftovers(self) -> list[str]:
        """Containers, networks and volumes of this project still on the engine."""
        label = f"label=com.docker.compose.project={self.project}"
        found = []
        for kind in ("container", "network", "volume"):
            listed = ["ls", "--all"] if kind == "container" else ["ls"]
            out = self.docker(kind, *listed, "--quiet", "--filter", label)
            found += [f"{kind} {name}" for name in out.split()]
        return found


@pytest.fixture
def stack(tmp_path: Path, request: pytest.FixtureRequest) -> Iterator[Stack]:
    stack = Stack(tmp_path, *getattr(request, "param", ()))
    stack.compose("build", "--quiet", timeout=900)
    try:
        yield stack
    finally:
        try:
            report = getattr(request.node, "rep_call", None)
            if report is not None and report.failed:  # what the services said, before down
                print(stack.compose("logs", "--no-color", "--tail", "60")[-12000:])
            stack.compose("down", "--volumes", "--remove-orphans", "--timeout", "10")
        finally:
            print(stack.log.read_text()[-6000:])
    assert stack.leftovers() == []


def say(stack: Stack, text: str, *bus: str) -> list[str]:
    """`voicectl say TEXT` from this machine, through the published router port (`bus`:
    the flags that reach it, plain by default)."""
    done = subprocess.run(
        [sys.executable, "-m", "voicectl", "say", text, *(bus or ("--connect", stack.router))],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    ids: list[str] = json.loads(done.stdout)["order_ids"]
    return ids


OBSERVER = "/etc/voicectl/bus/observer.json5"
"""The observer's client configuration, as the containers see it: odometry is read with it."""


def test_compose_up_is_secured_keeps_its_secrets_and_runs_orders(stack: Stack) -> None:
    started = time.monotonic()
    stack.compose("up", "--detach", "--wait", "--wait-timeout", "180", timeout=240)
    took = time.monotonic() - started
    print(f"docker compose up (secured): every container healthy in {took:.1f} s")
    states = [json.loads(line) for line in stack.compose("ps", "--format", "json").splitlines()]
    assert {s["Service"] for s in states} == {
        *("router", "converter", "stt", "supervisor", "web", "sim", "executor")
    }
    # Containers run as voicectl's user, not root.
    assert stack.docker("exec", stack.container("executor"), "id", "-u").strip() == "1000"
    # The panel's token, as the docs print it; the panel answers with it only.
    assert stack.compose("exec", "-T", "web", "voicectl", "token").strip() == TOKEN
    assert stack.panel("/api/state", token=None)[0] == 401
    status, state = stack.panel("/api/state")
    assert status == 200, state

    # A person's command in the panel's container acts as the operator.
    said = stack.compose("exec", "-T", "web", "voicectl", "say", "turn left")
    (turn,) = json.loads(said)["order_ids"]
    # And from this machine, with the operator's credentials made portable.
    operator = stack.credentials("operator")
    assert stat.S_IMODE(operator.stat().st_mode) == 0o600
    (move,) = say(stack, "move forward 1 meter", "--config", str(operator))
    bus = BusOptions(connect=[], config_file=operator, wait=False)

    async def carried_out(client: Client) -> None:
        await client_wait_ready(client)
        for order_id in (turn, move):
            record = await client.finished(order_id, timeout=30.0)
            assert record.status == OrderStatus.SUCCEEDED, record

    on_bus(bus, lambda b: carried_out(Client(b, "robot")))
    x, y, *_ = stack.odometry(via=OBSERVER, listen=1.0)
    assert abs(x) < 0.2, (x, y)  # a quarter turn left, then 1 m
    assert abs(y - 1.0) < 0.2, (x, y)

    # The panel's credentials: no velocity reaches the robot, no executor answers.
    replies = stack.compose("exec", "-T", "web", "python3", "-", stdin=INTRUDE)
    assert json.loads(replies) == 0
    x_after, y_after, linear, angular, _ = stack.odometry(via=OBSERVER, listen=1.0)
    assert (linear, angular) == (0.0, 0.0)
    assert abs(x_after - x) < 0.05
    assert abs(y_after - y) < 0.05
    # Without credentials nothing connects: the published port speaks TLS only.
    refused = subprocess.run(
        [sys.executable, "-m", "voicectl", "state", "--connect", stack.router],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=REPO,
    )
    assert refused.returncode != 0
    assert "cannot reach the router" in refused.stderr

    # A second start: the secrets are kept (the same passwords), and so is the history.
    secrets = stack.compose("exec", "-T", "web", "cat", "/etc/voicectl/bus/passwords")
    stack.compose("down", "--timeout", "10")
    stack.compose("up", "--detach", "--wait", "--wait-timeout", "180", timeout=240)
    assert "kept: made before" in stack.compose("logs", "bus-secrets")
    assert stack.compose("exec", "-T", "web", "cat", "/etc/voicectl/bus/passwords") == secrets

    async def remembered(client: Client) -> None:
        await client_wait_ready(client)
        ids = {record.id for record in (await client.history()).records}
        assert {turn, move} <= ids

    on_bus(bus, lambda b: remembered(Client(b, "robot")))  # the exported file still works


@pytest.mark.parametrize("stack", [("compose.open.yaml",)], indirect=True, ids=["open"])
def test_on_the_open_bus_a_cut_off_robot_is_stopped_by_its_own_router(stack: Stack) -> None:
    started = time.monotonic()
    stack.compose("up", "--detach", "--wait", "--wait-timeout", "180", timeout=240)
    took = time.monotonic() - started
    print(f"docker compose up (open): every container healthy in {took:.1f} s")
    states = [json.loads(line) for line in stack.compose("ps", "--format", "json").splitlines()]
    assert {s["Service"] for s in states} == {
        *("router", "converter", "stt", "supervisor", "web", "sim-router", "sim", "executor")
    }
    # Orders said on this machine, on the open router's published port, run on the robot.
    (turn,) = say(stack, "turn left")

    async def carried_out(client: Client) -> None:
        await client_wait_ready(client)
        record = await client.finished(turn, timeout=30.0)
        assert record.status == OrderStatus.SUCCEEDED, record

    on_bus(stack.router, lambda bus: carried_out(Client(bus, "robot")))

    # The robot's link to the host cut while it drives: its own router still joins the
    # executor and the simulator, and the executor, alone with the robot, stops it.
    (going,) = say(stack, "reach the bathroom")
    deadline = time.monotonic() + 20.0
    while stack.odometry()[2] < 0.2:
        assert time.monotonic() < deadline, "the robot never drove"
    site = f"{stack.project}_site"
    stack.docker("network", "disconnect", site, stack.container("sim-router"))
    cut = time.monotonic()
    try:
        while (odometry := stack.odometry())[2:4] != [0.0, 0.0]:
            assert time.monotonic() - cut < LEASE + 30.0, f"still driving: {odometry}"
        print(f"link cut to a standing robot: {time.monotonic() - cut:.1f} s")
        stood = odometry[:2]
        time.sleep(1.0)  # then it stays where it stopped, short of the bathroom (5, 2)
        assert stack.odometry(listen=0.5)[:2] == stood
        assert stood[0] < 4.5
        log = stack.compose("logs", "executor")
        assert f"supervisor lost while order {going} commanded the robot" in log
    finally:
        stack.docker("network", "connect", site, stack.container("sim-router"))

    async def failed(client: Client) -> None:
        await client_wait_ready(client)
        record = await client.finished(going)
        assert record.status != OrderStatus.SUCCEEDED, record

    on_bus(stack.router, lambda bus: failed(Client(bus, "robot")))
