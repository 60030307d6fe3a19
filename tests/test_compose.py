"""compose.yaml, the Dockerfile and the router's configuration, checked statically (no
Docker engine runs here), and the images built and run with testcontainers where an
engine does run.

Compose files are read as `docker compose` reads them: `${VAR:-default}` becomes its
default (nothing set in the environment), profiles enable services, .env sets the
profiles of a plain `docker compose up`.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import os
import re
import shlex
import socket
from pathlib import Path
from typing import Any

import json5
import pytest
import yaml
import zenoh

from shared.bus import BusOptions
from voicectl.cli import SERVICES, build_parser

from .conftest import REPO, free_port, voicectl

VARIABLE = re.compile(r"\$\{(\w+)(?:(:?[-?])([^}]*))?\}")
ROLES = {
    "host": {"router", "converter", "stt", "supervisor", "web"},
    "sim": {"sim", "executor"},
    "robot": {"robot-executor", "bridge"},
}
"""Which containers each profile runs (compose.yaml's header and docs/deploy.md)."""


def interpolate(value: Any, env: dict[str, str]) -> Any:
    """`value` with every ${...} replaced as Compose does, from `env`."""
    if isinstance(value, dict):
        return {key: interpolate(item, env) for key, item in value.items()}
    if isinstance(value, list):
        return [interpolate(item, env) for item in value]
    if not isinstance(value, str):
        return value

    def one(found: re.Match[str]) -> str:
        name, operator, argument = found.groups()
        given = env.get(name)
        if operator in (":-", "-"):
            return given if given or (operator == "-" and given is not None) else argument
        if operator in (":?", "?"):
            if not given:
                raise KeyError(f"{name} is required: {argument}")
            return given
        return given or ""

    return VARIABLE.sub(one, value)


def load(*files: str, env: dict[str, str] | None = None) -> dict[str, dict[str, Any]]:
    """The services of `files` merged as `docker compose -f ... -f ...` merges them
    (mappings merged, a command replaced, volumes added)."""
    merged: dict[str, dict[str, Any]] = {}
    for name in files:
        document = yaml.safe_load((REPO / name).read_text())
        for service, settings in document["services"].items():
            base = merged.setdefault(service, {})
            for key, value in settings.items():
                if isinstance(value, dict) and isinstance(base.get(key), dict):
                    base[key] = {**base[key], **value}
                elif key == "volumes" and key in base:
                    base[key] = base[key] + value
                else:
                    base[key] = value
    found: dict[str, dict[str, Any]] = interpolate(merged, env or {})
    return found


SERVICES_COMPOSED = load("compose.yaml")
VOICECTL = {
    name: service
    for name, service in SERVICES_COMPOSED.items()
    if service["image"].startswith("voicectl")
}
DOCKERFILE = (REPO / "Dockerfile").read_text()
ROUTER_CONFIG = REPO / "deploy" / "zenoh" / "router.json5"
BRIDGE_CONFIG = REPO / "deploy" / "zenoh-bridge-ros2dds.json5"


def flag(command: list[str], name: str) -> str:
    return command[command.index(name) + 1]


def enabled(profiles: set[str]) -> set[str]:
    return {name for name, s in SERVICES_COMPOSED.items() if set(s["profiles"]) & profiles}


def default_profiles() -> set[str]:
    """What `docker compose up` enables without --profile: COMPOSE_PROFILES in .env."""
    settings = dict(
        line.split("=", 1)
        for line in (REPO / ".env").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    )
    return set(settings["COMPOSE_PROFILES"].split(","))


# --- profiles -----------------------------------------------------------------------------------


def test_each_container_has_one_role() -> None:
    assert {name: s["profiles"] for name, s in SERVICES_COMPOSED.items()} == {
        name: [role] for role, names in ROLES.items() for name in names
    }


def test_compose_up_runs_the_whole_stack_with_the_simulator() -> None:
    assert default_profiles() == {"host", "sim"}
    running = enabled(default_profiles())
    commands = {SERVICES_COMPOSED[name]["command"][0] for name in running & set(VOICECTL)}
    # Every voicectl service but the router, which is zenohd's.
    assert commands == set(SERVICES) - {"router"}
    assert SERVICES_COMPOSED["router"]["image"].startswith("eclipse/zenoh:")


def test_the_robot_runs_its_executor_next_to_the_bridge_instead_of_the_simulator() -> None:
    robot = enabled({"robot"})
    assert robot == {"robot-executor", "bridge"}
    assert SERVICES_COMPOSED["robot-executor"]["command"][0] == "executor"
    assert "sim" not in enabled({"host", "robot"})


DOCUMENTED_PROFILES = [{"host", "sim"}, {"host", "robot"}, {"host"}, {"robot"}]
"""The machines compose.yaml and docs/deploy.md describe: one with the simulator, one
with a real robot, and the host and the robot of two machines."""


@pytest.mark.parametrize("profiles", DOCUMENTED_PROFILES, ids=lambda p: "+".join(sorted(p)))
def test_every_required_dependency_runs_on_the_same_machine(profiles: set[str]) -> None:
    running = enabled(profiles)
    for name in running:
        for needed, how in SERVICES_COMPOSED[name].get("depends_on", {}).items():
            if how.get("required", True):
                assert needed in running, f"{name} needs {needed}, not run with {profiles}"


# --- voicectl's containers ----------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(VOICECTL))
def test_each_command_is_valid_for_its_service(name: str) -> None:
    command = VOICECTL[name]["command"]
    assert command[0] in SERVICES
    module = importlib.import_module(f"services.{command[0]}.__main__")
    module.parse_args(command[1:])  # argparse exits (fails the test) on an unknown flag


def test_images_by_role() -> None:
    stages = set(re.findall(r"^FROM \S+ AS (\S+)$", DOCKERFILE, re.MULTILINE))
    assert {"robot", "host"} <= stages
    for name, service in VOICECTL.items():
        role = "robot" if "robot" in service["profiles"] else "host"
        assert service["build"] == {"context": ".", "target": role}, name
        assert service["image"] == (
            "voicectl-robot:latest" if role == "robot" else "voicectl:latest"
        )
    assert re.findall(r"^FROM .*$", DOCKERFILE, re.MULTILINE)[-1].endswith(" AS host")


def test_the_robot_image_installs_no_extra() -> None:
    stage = DOCKERFILE.split(" AS robot\n", 1)[1].split("\nFROM ", 1)[0]
    installs = re.findall(r"pip install (.*)", stage)
    assert installs == ["/wheels/voicectl-*.whl && rm -rf /wheels"]
    host = DOCKERFILE.split(" AS host\n", 1)[1]
    assert "ARG VOICECTL_EXTRAS=host\n" in host
    assert '[${VOICECTL_EXTRAS}]"' in host


def test_the_image_is_built_from_what_it_needs() -> None:
    copied = set(re.findall(r"^COPY ([^-\s]\S*) ", DOCKERFILE, re.MULTILINE))
    assert copied == {"pyproject.toml", "shared", "services", "voicectl", "orders"}
    assert "pip wheel --no-deps" in DOCKERFILE
    assert " -e " not in DOCKERFILE, "installed, not editable"
    # The context is an allow-list: what is copied, the README the wheel's metadata
    # reads, and nothing else (no .env, no data, no models).
    ignored = [line for line in (REPO / ".dockerignore").read_text().splitlines() if line]
    assert next(line for line in ignored if not line.startswith("#")) == "*"
    allowed = {line[1:].rstrip("/") for line in ignored if line.startswith("!")}
    assert allowed == copied | {"README.md"}


def test_clients_connect_to_the_router() -> None:
    router = SERVICES_COMPOSED["router"]
    port = json5.loads(ROUTER_CONFIG.read_text())["listen"]["endpoints"][0].rsplit(":", 1)[1]
    (published,) = router["ports"]
    address, _, inside = published.rpartition(":")
    assert inside == port
    for name, service in VOICECTL.items():
        connect = flag(service["command"], "--connect")
        if service.get("network_mode") == "host":  # the robot's: through the published port
            assert connect == f"tcp/{address}", name
        else:
            assert connect == f"tcp/router:{port}", name
            assert service["depends_on"]["router"] == {"condition": "service_started"}, name
    bridge = SERVICES_COMPOSED["bridge"]
    assert flag(bridge["command"], "--connect") == f"tcp/{address}"


def test_the_router_is_published_on_loopback_unless_chosen() -> None:
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    (ports,) = document["services"]["router"]["ports"]
    assert ports == "${VOICECTL_ROUTER_PUBLISH:-127.0.0.1:7447}:7447"
    assert all(p.startswith("127.0.0.1:") for p in SERVICES_COMPOSED["web"]["ports"])


def test_the_panel_keeps_a_token_of_its_own_unless_given_one() -> None:
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    web = document["services"]["web"]
    assert web["environment"] == {"VOICECTL_TOKEN": "${VOICECTL_TOKEN:-}"}
    assert "web-data:/data" in web["volumes"]
    assert "VOICECTL_DATA=/data" in DOCKERFILE


def test_the_converter_reads_a_mounted_orders_directory() -> None:
    converter = SERVICES_COMPOSED["converter"]
    orders = flag(converter["command"], "--orders")
    (mount,) = converter["volumes"]
    source, target, mode = mount.split(":")
    assert (target, mode) == (orders, "ro")
    assert (REPO / source).is_dir()


# --- health -------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(VOICECTL))
def test_each_container_is_healthy_when_voicectl_health_says_so(name: str) -> None:
    service = VOICECTL[name]
    command = service["command"]
    test = service["healthcheck"]["test"]
    assert test[:3] == ["CMD", "voicectl", "health"], name
    args = build_parser().parse_args(test[2:])
    assert args.service == command[0], name
    if command[0] == "web":
        assert args.url == f"http://127.0.0.1:{flag(command, '--port')}/api/health"
        return
    assert args.connect == [flag(command, "--connect")], name
    if "--robot" in command:
        assert args.robot == flag(command, "--robot"), name
    if "--namespace" in command and command[0] == "sim":
        assert args.namespace == flag(command, "--namespace"), name


def test_depends_on_names_existing_services_and_waits_for_health() -> None:
    for name, service in SERVICES_COMPOSED.items():
        for needed, how in service.get("depends_on", {}).items():
            assert needed in SERVICES_COMPOSED, f"{name} depends on unknown {needed}"
            assert how["condition"] in ("service_started", "service_healthy"), name
            if how["condition"] == "service_healthy":
                assert "healthcheck" in SERVICES_COMPOSED[needed], f"{needed} has no check"
    assert "healthcheck" not in SERVICES_COMPOSED["router"]


def test_the_panel_starts_after_the_services_it_shows() -> None:
    depends = SERVICES_COMPOSED["web"]["depends_on"]
    for needed in ("converter", "stt", "supervisor"):
        assert depends[needed] == {"condition": "service_healthy"}
    # The executor is on this machine, or on the robot (then neither of these runs here).
    for executor in ("executor", "robot-executor"):
        assert depends[executor] == {"condition": "service_healthy", "required": False}


# --- zenohd -------------------------------------------------------------------------------------


def test_the_router_is_zenohd_with_the_repositorys_config() -> None:
    router = SERVICES_COMPOSED["router"]
    image, _, version = router["image"].partition(":")
    assert image == "eclipse/zenoh"
    # Zenoh 1.x routers and clients speak the same protocol.
    assert version.split(".")[0] == importlib.metadata.version("eclipse-zenoh")[0] == "1"
    config = flag(router["command"], "--config")
    assert f"./deploy/zenoh/router.json5:{config}:ro" in router["volumes"]


def test_the_router_config_is_a_router_with_explicit_endpoints_and_timestamps() -> None:
    config = json5.loads(ROUTER_CONFIG.read_text())
    assert config["mode"] == "router"
    assert config["listen"]["endpoints"] == ["tcp/0.0.0.0:7447"]
    assert config["scouting"]["multicast"]["enabled"] is False
    # voicectl's publishers that keep their last sample for late subscribers need them.
    assert config["timestamping"]["enabled"] is True
    assert config["adminspace"]["permissions"]["write"] is False


def test_zenoh_reads_the_router_config_and_routes_for_voicectl() -> None:
    """The file as Zenoh itself reads it (unknown keys are errors), as a running router
    that `voicectl health` reaches."""
    config = zenoh.Config.from_file(str(ROUTER_CONFIG))
    assert json.loads(config.get_json("timestamping/enabled")) is True
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    config.insert_json5("listen/endpoints", json.dumps([endpoint]))
    with zenoh.open(config) as router:
        assert router.zid()
        client = zenoh.open(BusOptions(connect=[endpoint]).zenoh_config())
        try:
            token = client.liveliness().declare_token("voice/converter/alive")
            done = voicectl("health", "converter", "--connect", endpoint)
            assert (done.returncode, done.stderr) == (0, "")
            token.undeclare()
        finally:
            client.close()


# --- the robot ----------------------------------------------------------------------------------


def test_the_bridge_reaches_the_robots_ros_graph_and_the_router() -> None:
    bridge = SERVICES_COMPOSED["bridge"]
    image, _, version = bridge["image"].partition(":")
    assert (image, version.split(".")[0]) == ("eclipse/zenoh-bridge-ros2dds", "1")
    config = flag(bridge["command"], "--config")
    assert f"./deploy/zenoh-bridge-ros2dds.json5:{config}:ro" in bridge["volumes"]
    environment = bridge["environment"]
    assert environment["RMW_IMPLEMENTATION"] == "rmw_cyclonedds_cpp"
    assert environment["ROS_DISTRO"] in ("humble", "jazzy")
    assert environment["ROS_DOMAIN_ID"] == str(
        json5.loads(BRIDGE_CONFIG.read_text())["plugins"]["ros2dds"]["domain"]
    )
    # DDS discovery needs the robot's own network.
    assert bridge["network_mode"] == "host"


def test_the_executor_and_the_bridge_agree_on_the_namespace() -> None:
    bridge = SERVICES_COMPOSED["bridge"]["command"]
    executor = SERVICES_COMPOSED["robot-executor"]["command"]
    shipped = json5.loads(BRIDGE_CONFIG.read_text())["plugins"]["ros2dds"]["namespace"]
    assert flag(bridge, "--namespace") == "/" + flag(executor, "--namespace") == shipped
    robot = load("compose.yaml", env={"ROS_NAMESPACE": "tb4"})
    assert flag(robot["bridge"]["command"], "--namespace") == "/tb4"
    assert flag(robot["robot-executor"]["command"], "--namespace") == "tb4"


def test_on_two_machines_the_robot_connects_to_the_hosts_router() -> None:
    split = load("compose.yaml", env={"VOICECTL_ROUTER": "tcp/192.168.1.20:7447"})
    for name in ("bridge", "robot-executor"):
        assert flag(split[name]["command"], "--connect") == "tcp/192.168.1.20:7447", name
    health = split["robot-executor"]["healthcheck"]["test"]
    assert flag(health, "--connect") == "tcp/192.168.1.20:7447"


# --- Vosk ---------------------------------------------------------------------------------------


def test_vosk_with_a_mounted_model() -> None:
    services = load("compose.yaml", "compose.vosk.yaml", env={"VOSK_MODEL": "small-en"})
    stt = services["stt"]
    args = importlib.import_module("services.stt.__main__").parse_args(stt["command"][1:])
    assert (args.engine, args.vosk_model) == ("vosk", Path("/models/small-en"))
    assert "./models:/models:ro" in stt["volumes"]
    assert stt["build"] == {
        "context": ".",
        "target": "host",
        "args": {"VOICECTL_EXTRAS": "host,vosk"},
    }
    # Its own image: the other services keep theirs.
    assert stt["image"] != services["converter"]["image"]
    with pytest.raises(KeyError, match="VOSK_MODEL is required"):
        load("compose.yaml", "compose.vosk.yaml")


# --- the documentation --------------------------------------------------------------------------


def containers_section() -> str:
    text = (REPO / "docs" / "deploy.md").read_text()
    return text.split("\n## Containers\n", 1)[1].split("\n## ", 1)[0]


def documented_commands() -> list[list[str]]:
    blocks = re.findall(r"```sh\n(.*?)```", containers_section(), re.DOTALL)
    lines = [line for block in blocks for line in block.splitlines() if line.strip()]
    return [shlex.split(line, comments=True) for line in lines if not line.startswith("#")]


def test_the_docs_commands_name_what_exists() -> None:
    """Every docker command of the docs' Containers section uses profiles, services,
    files, stages and voicectl arguments that exist."""
    commands = documented_commands()
    assert commands, "no commands in the Containers section"
    profiles_seen = []
    for words in commands:
        words = [w for w in words if not re.fullmatch(r"[A-Z_]+=\S*", w)]  # VAR=value
        if words[:2] == ["docker", "build"]:
            target = flag(words, "--target")
            assert f" AS {target}\n" in DOCKERFILE
            continue
        if words[:2] != ["docker", "compose"]:
            continue
        rest = words[2:]
        profiles = set()
        while rest and rest[0] in ("--profile", "-f"):
            option, value, rest = rest[0], rest[1], rest[2:]
            if option == "-f":
                assert (REPO / value).is_file(), value
            else:
                assert value in ROLES, value
                profiles.add(value)
        profiles_seen.append(profiles or default_profiles())
        verb, *arguments = rest
        assert verb in ("up", "build", "exec", "logs", "ps", "down"), verb
        if verb == "exec":
            service, program, *args = arguments
            assert service in SERVICES_COMPOSED
            assert program == "voicectl"
            build_parser().parse_args(args)
    for profiles in profiles_seen:
        assert profiles in DOCUMENTED_PROFILES


# --- with a Docker engine -----------------------------------------------------------------------


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


needs_docker = pytest.mark.skipif(not _docker_engine(), reason="no Docker engine runs here")


@needs_docker
def test_host_image_builds_and_parses() -> None:  # pragma: no cover - needs an engine
    from testcontainers.core.container import DockerContainer
    from testcontainers.core.image import DockerImage
    from testcontainers.core.waiting_utils import wait_for_logs

    with DockerImage(path=str(REPO), tag="voicectl:test", target="host") as image:
        # The orders packaged in the wheel: no source tree in the image.
        container = DockerContainer(str(image)).with_command("parse 'turn left'")
        with container:
            wait_for_logs(container, "rotation", timeout=60)


@needs_docker
def test_robot_image_builds_and_runs_the_executor() -> None:  # pragma: no cover - needs an engine
    from testcontainers.core.container import DockerContainer
    from testcontainers.core.image import DockerImage
    from testcontainers.core.waiting_utils import wait_for_logs

    with DockerImage(path=str(REPO), tag="voicectl-robot:test", target="robot") as image:
        container = DockerContainer(str(image)).with_command("health --help")
        with container:
            wait_for_logs(container, "usage: voicectl health", timeout=60)
        container = DockerContainer(str(image)).with_command("parse 'turn left'")
        with container:
            wait_for_logs(container, "pip install 'voicectl\\[host\\]'", timeout=60)
