"""compose.yaml and the Dockerfile, checked statically (no Docker engine runs here), and
the image built and run with testcontainers where an engine does run."""

from __future__ import annotations

import importlib
import os
import re
import socket
from typing import Any

import pytest
import yaml

from voicectl.cli import SERVICES

from .conftest import REPO

COMPOSE = yaml.safe_load((REPO / "compose.yaml").read_text())
DOCKERFILE = (REPO / "Dockerfile").read_text()


def services() -> dict[str, dict[str, Any]]:
    found: dict[str, dict[str, Any]] = COMPOSE["services"]
    return found


def test_every_voicectl_service_has_a_container() -> None:
    assert set(services()) == set(SERVICES)


@pytest.mark.parametrize("name", sorted(SERVICES))
def test_each_command_is_valid_for_its_service(name: str) -> None:
    command = services()[name]["command"]
    assert command[0] == name
    module = importlib.import_module(f"services.{name}.__main__")
    module.parse_args(command[1:])  # argparse exits (fails the test) on an unknown flag


def test_clients_connect_to_the_router_it_listens_on() -> None:
    listen = services()["router"]["command"]
    port = listen[listen.index("--listen") + 1].rsplit(":", 1)[1]
    for name, service in services().items():
        if name == "router":
            continue
        command = service["command"]
        assert command[command.index("--connect") + 1] == f"tcp/router:{port}", name
        assert "router" in service["depends_on"], name


def test_the_panel_needs_a_token_and_binds_to_loopback_on_the_host() -> None:
    web = services()["web"]
    assert "VOICECTL_TOKEN:?" in web["environment"]["VOICECTL_TOKEN"]
    assert all(p.startswith("127.0.0.1:") for p in web["ports"])


def test_the_image_carries_what_the_commands_use() -> None:
    copied = set(re.findall(r"^COPY (\S+)", DOCKERFILE, re.MULTILINE))
    assert {"shared", "services", "voicectl", "orders"} <= copied
    orders = services()["converter"]["command"]
    assert orders[orders.index("--orders") + 1] == "/app/orders"
    assert "WORKDIR /app" in DOCKERFILE


def _docker_engine() -> bool:
    """True if a Docker engine answers on its socket (asked without the docker library,
    which leaks a socket when none does)."""
    host = os.environ.get("DOCKER_HOST", "unix:///var/run/docker.sock")
    if not host.startswith("unix://"):
        return True  # a remote engine: let testcontainers find out
    with socket.socket(socket.AF_UNIX) as sock:
        sock.settimeout(2.0)
        try:
            sock.connect(host.removeprefix("unix://"))
            sock.sendall(b"GET /_ping HTTP/1.0\r\n\r\n")
            return sock.recv(64).startswith(b"HTTP/1.")
        except OSError:
            return False


@pytest.mark.skipif(not _docker_engine(), reason="no Docker engine runs here")
def test_image_builds_and_parses() -> None:  # pragma: no cover - needs an engine
    from testcontainers.core.container import DockerContainer
    from testcontainers.core.image import DockerImage
    from testcontainers.core.waiting_utils import wait_for_logs

    with DockerImage(path=str(REPO), tag="voicectl:test") as image:
        container = DockerContainer(str(image)).with_command("parse 'turn left'")
        with container:
            wait_for_logs(container, "rotation", timeout=60)
