"""What the container tests need from this machine: a Docker engine, Compose v2, and the
images' base (Docker Hub's, or one made by scripts/base-image where no registry answers).
Each check returns why the tests cannot run here, or None."""

from __future__ import annotations

import functools
import os
import shutil
import socket
import subprocess

import pytest

DEFAULT_BASE = "python:3.11-slim-bookworm"
"""The Dockerfile's BASE_IMAGE."""
ZENOH_IMAGE = "eclipse/zenoh:1.10.1"
"""compose.yaml's routers."""


def base_image() -> str:
    return os.environ.get("VOICECTL_BASE_IMAGE") or DEFAULT_BASE


@functools.cache
def engine_unavailable() -> str | None:
    """Why no Docker engine can be used, asked on its socket without the docker library
    (which leaks a socket when no engine answers)."""
    if shutil.which("docker") is None:
        return "no docker command here"
    host = os.environ.get("DOCKER_HOST", "unix:///var/run/docker.sock")
    if not host.startswith("unix://"):
        return None  # a remote engine: the commands find out
    with socket.socket(socket.AF_UNIX) as sock:
        sock.settimeout(2.0)
        try:
            sock.connect(host.removeprefix("unix://"))
            sock.sendall(b"GET /_ping HTTP/1.0\r\n\r\n")
            if sock.recv(64).startswith(b"HTTP/1."):
                return None
        except OSError:
            pass
    return "no Docker engine runs here"


def _present(image: str) -> bool:
    """Whether `image` is here, or could be pulled."""
    return (
        _docker("image", "inspect", image).returncode == 0
        or _docker("pull", image, timeout=180).returncode == 0
    )


@functools.cache
def images_unavailable() -> str | None:
    """Why the images cannot be built here with Compose, as the docs build them: no
    engine, no Compose v2, or no base image (neither here nor pullable)."""
    if why := engine_unavailable():
        return why
    if _docker("compose", "version").returncode != 0:
        return "no Compose v2 here (docker compose)"
    if not _present(base_image()):
        return f"no base image {base_image()}: run scripts/base-image, set VOICECTL_BASE_IMAGE"
    return None


@functools.cache
def stack_unavailable() -> str | None:
    """Why compose.yaml's stack cannot run here: no images, or no router image (Docker
    Hub's zenohd, or the stand-in of compose.standin.yaml named in COMPOSE_FILE)."""
    if why := images_unavailable():
        return why
    if "compose.standin.yaml" in os.environ.get("COMPOSE_FILE", ""):
        return None
    if not _present(ZENOH_IMAGE):
        return f"no {ZENOH_IMAGE}: set COMPOSE_FILE=compose.yaml:compose.standin.yaml"
    return None


def _docker(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    try:
        return subprocess.run(
            ["docker", *args], capture_output=True, text=True, timeout=timeout, check=False
        )
    except subprocess.TimeoutExpired:
        return subprocess.CompletedProcess(args, 124, "", "timed out")


def skip_unless(why: str | None) -> pytest.MarkDecorator:
    """Skip with `why` (a reason the tests cannot run here), unless VOICECTL_CONTAINERS is
    `required` (scripts/test-containers): then not running them is an error."""
    if why is not None and os.environ.get("VOICECTL_CONTAINERS") == "required":
        raise RuntimeError(f"the container tests must run here, but: {why}")
    return pytest.mark.skipif(why is not None, reason=f"{why}")
