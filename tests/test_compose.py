"""compose.yaml (the secured bus), compose.open.yaml (the open bus of a lab), the
Dockerfile and the routers' configurations, checked statically (no Docker engine runs
here), and the images built and run with testcontainers where an engine does run.

Compose files are read as `docker compose` reads them: `${VAR:-default}` becomes its
default (nothing set in the environment), profiles enable services, .env sets the
profiles of a plain `docker compose up`.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

import json5
import pytest
import yaml
import zenoh

from harness.ports import free_port
from harness.wait import wait_until
from voicectl.bus_secrets import CONTAINER_DIR, DEFAULT_ROBOT, BusRobot, client_files
from voicectl.cli import SERVICES, build_parser
from voicectl.services.executor.config import limits_of
from voicectl.services.executor.config import parse_args as parse_executor_args
from voicectl.services.executor.speed import SAFE_LIMITS, SpeedLimits
from voicectl.shared.bus import BusOptions

from .conftest import REPO, voicectl
from .containers import base_image, images_unavailable, skip_unless

VARIABLE = re.compile(r"\$\{(\w+)(?:(:?[-?])([^}]*))?\}")
ROLES = {
    "host": {"bus-secrets", "router", "converter", "stt", "supervisor", "web"},
    "sim": {"sim", "executor"},
    "robot": {"robot-router", "robot-executor", "robot-listen", "bridge"},
    "open": {"sim-router"},
}
"""Which containers each profile runs (compose.yaml's header and docs/deploy.md); `open`
is no role: the simulated robot's own router, which compose.open.yaml puts in `sim`."""


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
    (mappings merged, a command replaced, volumes added, networks joined)."""
    merged: dict[str, dict[str, Any]] = {}
    for name in files:
        document = yaml.safe_load((REPO / name).read_text())
        for service, settings in document["services"].items():
            base = merged.setdefault(service, {})
            for key, value in settings.items():
                if key == "networks" and isinstance(value, list):
                    value = dict.fromkeys(value)
                if isinstance(value, dict) and isinstance(base.get(key), dict):
                    base[key] = {**base[key], **value}
                elif key == "volumes" and key in base:
                    base[key] = base[key] + value
                else:
                    base[key] = value
    found: dict[str, dict[str, Any]] = interpolate(merged, env or {})
    return found


SERVICES_COMPOSED = load("compose.yaml")
OPEN = load("compose.yaml", "compose.open.yaml")
"""The stack on the open bus, as a lab runs it."""
VOICECTL = {
    name: service
    for name, service in SERVICES_COMPOSED.items()
    if service["image"].startswith("voicectl")
}
RUNNING = {name: service for name, service in VOICECTL.items() if name != "bus-secrets"}
"""voicectl's containers that run a service (bus-secrets runs once at each start)."""
CONTAINER_DIR_RO = f"bus-secrets:{CONTAINER_DIR}:ro"
DOCKERFILE = (REPO / "Dockerfile").read_text()
ROUTER_CONFIG = REPO / "deploy" / "zenoh" / "router.json5"
ROBOT_ROUTER_CONFIG = REPO / "deploy" / "zenoh" / "robot-router.json5"
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
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
    commands = {SERVICES_COMPOSED[name]["command"][0] for name in running & set(RUNNING)}
    # Every voicectl service but the router, which is zenohd's, the STOP relay, which runs
    # on a robot on DDS beside its executor (the simulator is on Zenoh), and the listener,
    # which needs a robot's sound device (the robot profile runs it).
    assert commands == set(SERVICES) - {"router", "relay", "listen"}
    assert SERVICES_COMPOSED["router"]["image"].startswith("eclipse/zenoh:")


def test_the_robot_runs_its_executor_next_to_the_bridge_instead_of_the_simulator() -> None:
    robot = enabled({"robot"})
    assert robot == {"robot-router", "robot-executor", "robot-listen", "bridge"}
    assert SERVICES_COMPOSED["robot-executor"]["command"][0] == "executor"
    assert "sim" not in enabled({"host", "robot"})


def test_the_robot_s_speed_limits_reach_its_executor() -> None:
    """Issue 43: the robot profile took no speed limits. Set where `docker compose` runs,
    they reach the robot's executor; unset, it holds the safe ones."""
    given = {"VOICECTL_MAX_SPEED": "0.3", "VOICECTL_MAX_ANGULAR_SPEED": "0.8"}
    for env, expected in ((given, SpeedLimits(linear=0.3, angular=0.8)), ({}, SAFE_LIMITS)):
        executor = load("compose.yaml", env=env)["robot-executor"]
        args = parse_executor_args(executor["command"][1:])
        assert limits_of(args, executor["environment"]) == expected


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
    if name == "bus-secrets":
        build_parser().parse_args(command)  # a voicectl command, not a service
        return
    assert command[0] in SERVICES
    module = importlib.import_module(f"voicectl.services.{command[0]}.__main__")
    module.parse_args(command[1:])  # argparse exits (fails the test) on an unknown flag


def test_images_by_role() -> None:
    stages = set(re.findall(r"^FROM \S+ AS (\S+)$", DOCKERFILE, re.MULTILINE))
    assert {"robot", "listen", "host"} <= stages
    images = {
        "robot": "voicectl-robot:latest",
        "listen": "voicectl-listen:latest",
        "host": "voicectl:latest",
    }
    for name, service in VOICECTL.items():
        role = "robot" if "robot" in service["profiles"] else "host"
        if service["command"][0] == "listen":
            role = "listen"
        assert service["build"] == {
            "context": ".",
            "target": role,
            "args": {"BASE_IMAGE": "python:3.11-slim-bookworm"},
            "secrets": ["ca"],
        }, name
        assert service["image"] == images[role]
    assert re.findall(r"^FROM .*$", DOCKERFILE, re.MULTILINE)[-1].endswith(" AS host")


def stage(name: str) -> str:
    """The Dockerfile's stage `name`, from its FROM line to the next."""
    found = re.search(rf"^FROM (\S+) AS {name}\n(.*?)(?=^FROM |\Z)", DOCKERFILE, re.M | re.S)
    assert found, name
    return found.group(0)


def installer() -> Any:
    """deploy/install.py, the images' installer, as a module."""
    spec = importlib.util.spec_from_file_location("install", REPO / "deploy" / "install.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def requirements(*extras: str) -> list[str]:
    """What the images install for `extras`, by name."""
    found = installer().requirements(REPO / "pyproject.toml", list(extras))
    return [re.split(r"[<>=\[ ]", need, maxsplit=1)[0] for need in found]


def test_the_robot_image_installs_no_extra() -> None:
    core = requirements()
    assert core == [re.split(r"[<>=]", d)[0] for d in PYPROJECT["project"]["dependencies"]]
    host = requirements("host")
    assert set(core) < set(host)
    assert {"pocketsphinx", "starlette", "rapidfuzz"} <= set(host) - set(core)
    assert set(requirements("host", "vosk")) - set(host) == {"vosk"}
    # The robot's dependencies are installed without extras; the host's with its own.
    assert stage("robot-deps").rstrip().endswith("install.py deps /tmp/build/pyproject.toml")
    assert "ARG VOICECTL_EXTRAS=host\n" in stage("host-deps")
    assert 'pyproject.toml "$VOICECTL_EXTRAS"' in stage("host-deps")
    assert "COPY --from=robot-install /opt/voicectl" in stage("robot")
    assert "COPY --from=host-install /opt/voicectl" in stage("host")
    for role in ("robot", "host"):
        assert "install.py voicectl /tmp/wheels" in stage(f"{role}-install")


def test_dependencies_are_a_layer_keyed_on_pyproject_alone() -> None:
    """A change to the source rebuilds voicectl's own layer, not its dependencies."""
    for role in ("robot", "host"):
        assert "COPY" not in stage(f"{role}-deps")
        assert stage(f"{role}-deps").startswith("FROM venv AS")
    assert re.findall(r"^COPY (.*)$", stage("venv"), re.M) == [
        "pyproject.toml deploy/install.py /tmp/build/"
    ]


def test_the_base_is_pinned_and_nothing_is_declared_a_volume() -> None:
    assert "ARG BASE_IMAGE=python:3.11-slim-bookworm\n" in DOCKERFILE
    assert "FROM ${BASE_IMAGE} AS base" in DOCKERFILE
    # Data volumes are declared where they are used (compose.yaml), not for every container.
    assert "VOLUME" not in DOCKERFILE


def test_a_ca_bundle_reaches_pip_as_a_secret_never_as_a_layer() -> None:
    # Each step that downloads (each role's dependencies, the wheel's build backend)
    # mounts the secret; nothing copies a CA into an image.
    downloads = re.findall(r"install\.py (?:deps|wheel) ", DOCKERFILE)
    assert len(downloads) == 4  # robot, listen and host dependencies; the wheel
    assert DOCKERFILE.count("RUN --mount=type=secret,id=ca") == 4
    assert "/run/secrets/ca" in (REPO / "deploy" / "install.py").read_text()
    assert not re.search(r"^COPY .*(ca|cert)", DOCKERFILE, re.M | re.I)
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    assert document["secrets"] == {"ca": {"file": "${VOICECTL_CA:-/dev/null}"}}


def test_the_image_is_built_from_what_it_needs() -> None:
    copied = {
        source
        for line in re.findall(r"^COPY (?!--)(.*)$", DOCKERFILE, re.MULTILINE)
        for source in line.split()[:-1]
    }
    assert copied == {
        "pyproject.toml",
        "deploy/install.py",
        "README.md",
        "shared",
        "services",
        "voicectl",
        "orders",
    }
    assert "install.py wheel " in DOCKERFILE
    assert " -e " not in DOCKERFILE, "installed, not editable"
    # The context is an allow-list: what is copied, the README the wheel's metadata
    # reads, and nothing else (no .env, no data, no models).
    ignored = [line for line in (REPO / ".dockerignore").read_text().splitlines() if line]
    assert next(line for line in ignored if not line.startswith("#")) == "*"
    allowed = {line[1:].rstrip("/") for line in ignored if line.startswith("!")}
    assert allowed == copied


USER_OF = {
    "converter": "converter",
    "stt": "stt",
    "supervisor": "supervisor",
    "web": "panel",
    "executor": "executor",
    "sim": "robot",
}
"""Whose credentials each container of the stack starts with (voicectl bus-secrets)."""


def test_on_the_secured_bus_the_host_and_the_simulated_robot_join_the_router() -> None:
    """compose.yaml: each service of the host and of the simulated robot connects to the
    secured router with its own credentials (the file names the router); a real robot's
    services to the robot's own router, which connects to the host's published port."""
    for name in (*ROLES["host"] - {"bus-secrets", "router"}, *ROLES["sim"]):
        command = SERVICES_COMPOSED[name]["command"]
        assert flag(command, "--config") == f"{CONTAINER_DIR}/{USER_OF[name]}.json5", name
        assert "--connect" not in command, name
        assert SERVICES_COMPOSED[name]["depends_on"]["router"] == {"condition": "service_started"}
    robot_router = SERVICES_COMPOSED["robot-router"]["command"]
    (published,) = SERVICES_COMPOSED["router"]["ports"]
    assert flag(robot_router, "--connect") == f"tcp/{published.rpartition(':')[0]}"
    for name in ("bridge", "robot-executor", "robot-listen"):
        service = SERVICES_COMPOSED[name]
        assert flag(service["command"], "--connect") == flag(robot_router, "--listen"), name
        assert service["depends_on"]["robot-router"] == {"condition": "service_started"}


def test_on_the_open_bus_each_machine_joins_its_own_router() -> None:
    """compose.open.yaml: the host's services to the host's router; the robot's to the
    robot's router (by its name on the robot's network alone), which connects to the
    host's (on its network, or through the published port)."""
    port = json5.loads(ROUTER_CONFIG.read_text())["listen"]["endpoints"][0].rsplit(":", 1)[1]
    (published,) = OPEN["router"]["ports"]
    assert published.rpartition(":")[2] == port
    sim_router = OPEN["sim-router"]
    assert sim_router["profiles"] == ["sim"]
    assert flag(sim_router["command"], "--connect") == f"tcp/router:{port}"
    (alias,) = sim_router["networks"]["robot"]["aliases"]
    inside = "tcp/" + alias + ":" + flag(sim_router["command"], "--listen").rsplit(":", 1)[1]
    for name in ROLES["host"] - {"bus-secrets", "router"}:
        assert flag(OPEN[name]["command"], "--connect") == f"tcp/router:{port}", name
        assert "--config" not in OPEN[name]["command"], name
    for name in ROLES["sim"]:
        assert flag(OPEN[name]["command"], "--connect") == inside, name
        assert OPEN[name]["depends_on"]["sim-router"] == {"condition": "service_started"}
    assert OPEN["web"]["environment"]["ZENOH_CONFIG"] == ""  # commands typed: no file
    for name in ROLES["host"] | ROLES["sim"]:  # every command still parses
        command = OPEN[name]["command"]
        if OPEN[name]["image"].startswith("voicectl") and name != "bus-secrets":
            importlib.import_module(f"voicectl.services.{command[0]}.__main__").parse_args(
                command[1:]
            )


def test_the_robots_router_is_on_both_networks_and_its_services_reach_it_on_the_robots() -> None:
    """So that cutting the robot's link (its router off the site's network) leaves the
    executor with the robot, as on a real robot (tests/test_compose_up.py cuts it)."""
    assert set(OPEN["sim-router"]["networks"]) == {"robot", "site"}
    assert set(SERVICES_COMPOSED["sim-router"]["networks"]) == {"robot", "site"}
    assert SERVICES_COMPOSED["sim-router"]["profiles"] == ["open"]  # not on the secured bus
    for name in enabled({"host", "sim"}) - {"bus-secrets"}:
        assert set(SERVICES_COMPOSED[name]["networks"]) == {"site"}, name
    for name in enabled({"robot"}):
        assert SERVICES_COMPOSED[name]["network_mode"] == "host", name
    assert json5.loads(ROBOT_ROUTER_CONFIG.read_text())["mode"] == "router"


def test_the_router_is_published_on_loopback_unless_chosen() -> None:
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    (ports,) = document["services"]["router"]["ports"]
    assert ports == "${VOICECTL_ROUTER_PUBLISH:-127.0.0.1:7447}:7447"
    assert all(p.startswith("127.0.0.1:") for p in SERVICES_COMPOSED["web"]["ports"])


def test_the_panel_keeps_a_token_of_its_own_unless_given_one() -> None:
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    web = document["services"]["web"]
    assert web["environment"] == {
        "VOICECTL_TOKEN": "${VOICECTL_TOKEN:-}",
        # What a person types in it (`docker compose exec web voicectl ...`): the operator.
        "ZENOH_CONFIG": f"{CONTAINER_DIR}/operator.json5",
    }
    assert "web-data:/data" in web["volumes"]
    assert "VOICECTL_DATA=/data" in DOCKERFILE


def test_the_converter_reads_a_mounted_orders_directory() -> None:
    converter = SERVICES_COMPOSED["converter"]
    orders = flag(converter["command"], "--orders")
    mount, secrets = converter["volumes"]
    assert secrets == CONTAINER_DIR_RO
    source, target, mode = mount.split(":")
    assert (target, mode) == (orders, "ro")
    assert (REPO / source).is_dir()


# --- health -------------------------------------------------------------------------------------


HEARTBEAT = "/tmp/voicectl/alive"


@pytest.mark.parametrize("name", sorted(RUNNING))
def test_each_container_is_healthy_while_its_service_beats(name: str) -> None:
    """Every voicectl container checks its service's heartbeat file, often (the check
    costs nothing) and with no start_interval (Docker Engine 25 and later only)."""
    check = RUNNING[name]["healthcheck"]
    assert check["test"][0] == "CMD-SHELL"
    assert (
        "$$VOICECTL_HEARTBEAT"
        in yaml.safe_load((REPO / "compose.yaml").read_text())["x-healthcheck"]["test"][1]
    )
    assert "start_interval" not in check
    assert check["interval"] == "2s"
    assert f"VOICECTL_HEARTBEAT={HEARTBEAT}" in DOCKERFILE


def heartbeat_check() -> str:
    """The containers' check, as the shell in them runs it."""
    command: str = VOICECTL["converter"]["healthcheck"]["test"][1]
    return command.replace("$$", "$")


def test_the_check_passes_while_a_service_runs_and_fails_once_it_stopped(tmp_path: Path) -> None:
    """The containers' check command run against a real voicectl router, the process
    every service's wait goes through (`wait_for_stop`)."""
    beat = tmp_path / "voicectl" / "alive"
    environment = {**os.environ, "VOICECTL_HEARTBEAT": str(beat)}

    def check() -> int:
        return subprocess.run(["sh", "-c", heartbeat_check()], env=environment).returncode

    assert check() != 0
    router = subprocess.Popen(
        [sys.executable, "-m", "voicectl", "router", "--listen", f"tcp/127.0.0.1:{free_port()}"],
        env=environment,
        cwd=REPO,
    )
    try:
        wait_until(lambda: check() == 0, 20.0, "the router's heartbeat")
        old = time.time() - 60
        os.utime(beat, (old, old))  # as if its loop had stopped a minute ago
        assert check() != 0
        wait_until(lambda: check() == 0, 10.0, "the next beat")
    finally:
        router.terminate()
        router.wait(10)
    assert router.returncode == 0
    assert not beat.exists()
    assert check() != 0


def test_depends_on_names_existing_services_and_waits_for_health() -> None:
    for services in (SERVICES_COMPOSED, OPEN):
        for name, service in services.items():
            for needed, how in service.get("depends_on", {}).items():
                assert needed in services, f"{name} depends on unknown {needed}"
                condition = how["condition"]
                assert condition in ("service_started", "service_healthy", *DONE), name
                if condition == "service_healthy":
                    assert "healthcheck" in services[needed], f"{needed} has no check"
                if condition in DONE:  # a step that runs once and ends: the secrets
                    assert needed == "bus-secrets", name
    assert "healthcheck" not in SERVICES_COMPOSED["router"]
    assert "restart" not in SERVICES_COMPOSED["bus-secrets"]


DONE = ("service_completed_successfully",)


def test_every_service_of_the_host_and_the_simulator_waits_for_the_secrets() -> None:
    for name in (ROLES["host"] | ROLES["sim"]) - {"bus-secrets"}:
        depends = SERVICES_COMPOSED[name]["depends_on"]
        assert depends["bus-secrets"] == {"condition": "service_completed_successfully"}, name


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
    # The open bus: the repository's plain configuration.
    config = flag(OPEN["router"]["command"], "--config")
    assert f"./deploy/zenoh/router.json5:{config}:ro" in OPEN["router"]["volumes"]


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


def test_on_two_machines_the_robots_router_connects_to_the_hosts() -> None:
    split = load("compose.yaml", env={"VOICECTL_ROUTER": "tcp/192.168.1.20:7447"})
    router = split["robot-router"]["command"]
    assert flag(router, "--connect") == "tcp/192.168.1.20:7447"
    for name in ("bridge", "robot-executor"):
        assert flag(split[name]["command"], "--connect") == flag(router, "--listen"), name


# --- Vosk ---------------------------------------------------------------------------------------


def test_vosk_with_a_mounted_model() -> None:
    services = load("compose.yaml", "compose.vosk.yaml", env={"VOSK_MODEL": "small-en"})
    stt = services["stt"]
    args = importlib.import_module("voicectl.services.stt.__main__").parse_args(stt["command"][1:])
    assert (args.engine, args.vosk_model) == ("vosk", Path("/models/small-en"))
    assert args.config == Path(f"{CONTAINER_DIR}/stt.json5")  # on the secured bus too
    assert "./models:/models:ro" in stt["volumes"]
    assert stt["build"] == {
        "context": ".",
        "target": "host",
        "args": {"BASE_IMAGE": "python:3.11-slim-bookworm", "VOICECTL_EXTRAS": "host,vosk"},
        "secrets": ["ca"],
    }
    # Its own image: the other services keep theirs.
    assert stt["image"] != services["converter"]["image"]
    with pytest.raises(KeyError, match="VOSK_MODEL is required"):
        load("compose.yaml", "compose.vosk.yaml")


# --- the secured bus ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(USER_OF))
def test_on_the_secured_bus_each_service_has_its_own_credentials(name: str) -> None:
    service = SERVICES_COMPOSED[name]
    command = service["command"]
    importlib.import_module(f"voicectl.services.{command[0]}.__main__").parse_args(command[1:])
    assert flag(command, "--config") == f"{CONTAINER_DIR}/{USER_OF[name]}.json5"
    assert CONTAINER_DIR_RO in service["volumes"]
    assert USER_OF[name] in client_files([BusRobot(DEFAULT_ROBOT)])
    if "--robot" in command:  # the robot those files are for
        assert flag(command, "--robot") == DEFAULT_ROBOT


def test_the_secrets_are_made_on_the_first_start_and_kept_after() -> None:
    """`bus-secrets` runs before the router and every service at each start, and makes
    nothing when the volume holds secrets: the running services' passwords stay good."""
    maker = SERVICES_COMPOSED["bus-secrets"]
    assert maker["profiles"] == ["host"]
    assert maker["build"] == SERVICES_COMPOSED["converter"]["build"]
    assert maker["command"][:2] == ["bus-secrets", CONTAINER_DIR]
    assert "--if-missing" in maker["command"]
    assert flag(maker["command"], "--host") == "router"
    # The robot every service of the stack names, with users of its own.
    assert flag(maker["command"], "--robot") == DEFAULT_ROBOT
    assert maker["volumes"] == [f"bus-secrets:{CONTAINER_DIR}"]  # the only one writing
    assert maker["network_mode"] == "none"
    assert f"mkdir -p /data {CONTAINER_DIR}" in DOCKERFILE
    document = yaml.safe_load((REPO / "compose.yaml").read_text())
    assert "bus-secrets" in document["volumes"]


def test_the_secured_router_runs_the_shipped_secure_configuration() -> None:
    router = SERVICES_COMPOSED["router"]
    assert flag(router["command"], "--config") == f"{CONTAINER_DIR}/router.json5"
    assert router["volumes"] == [CONTAINER_DIR_RO]
    assert router["depends_on"]["bus-secrets"] == {"condition": "service_completed_successfully"}
    assert "ports" in router  # the published port speaks TLS


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
        files = []
        while rest and rest[0] in ("--profile", "-f"):
            option, value, rest = rest[0], rest[1], rest[2:]
            if option == "-f":
                assert (REPO / value).is_file(), value
                files.append(value)
            else:
                assert value in ROLES, value
                profiles.add(value)
        profiles_seen.append(profiles or default_profiles())
        verb, *arguments = rest
        assert verb in ("up", "build", "exec", "run", "logs", "ps", "down"), verb
        if verb == "run":
            *_, service = arguments
            assert service in load(*(files or ["compose.yaml"]), env={"VOSK_MODEL": "m"}), service
        if verb == "exec":
            service, program, *args = [a for a in arguments if a != "-T"]
            assert service in SERVICES_COMPOSED
            assert program == "voicectl"
            build_parser().parse_args(args)
    for profiles in profiles_seen:
        assert profiles in DOCUMENTED_PROFILES


# --- with a Docker engine -----------------------------------------------------------------------

needs_images = skip_unless(images_unavailable())
BUILD_TIMEOUT = pytest.mark.timeout(900)
"""A first build downloads and installs every dependency: minutes on a slow machine."""


def build(*services: str) -> None:
    """Build the images of compose.yaml's `services` as the docs say: Compose builds
    with the engine's BuildKit (the Dockerfile's build secret needs it) without buildx,
    and hands it VOICECTL_CA and VOICECTL_BASE_IMAGE."""
    done = subprocess.run(
        ["docker", "compose", "--profile", "robot", "build", "--quiet", *services],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "VOICECTL_BASE_IMAGE": base_image()},
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-3000:]


def output(image: str, *command: str) -> str:
    """What a container of `image` printed, run with testcontainers (no reaper: nothing
    to pull) until it exited."""
    from testcontainers.core.container import DockerContainer
    from testcontainers.core.wait_strategies import ContainerStatusWaitStrategy

    os.environ.setdefault("TESTCONTAINERS_RYUK_DISABLED", "true")
    container = DockerContainer(image).with_command(list(command))
    container.waiting_for(ContainerStatusWaitStrategy())
    with container:
        wrapped = container.get_wrapped_container()
        wrapped.wait(timeout=60)
        return bytes(wrapped.logs()).decode()


@needs_images
@BUILD_TIMEOUT
def test_host_image_builds_and_parses() -> None:
    build("converter")
    # The orders packaged in the wheel: no source tree in the image.
    assert "rotation" in output("voicectl:latest", "parse", "turn left")


@needs_images
@BUILD_TIMEOUT
def test_listen_image_builds_and_says_in_one_line_that_no_microphone_is_there() -> None:
    """The robot's ear without the host's /dev/snd (none here): one line, naming it."""
    build("robot-listen")
    assert "usage: voicectl listen" in output("voicectl-listen:latest", "listen", "--help")
    said = output("voicectl-listen:latest", "listen", "mic", "--connect", "tcp/127.0.0.1:9")
    assert said.strip().splitlines()[-1].startswith("voicectl listen: "), said
    assert "microphone" in said or "sound device" in said, said


@needs_images
@BUILD_TIMEOUT
def test_robot_image_builds_and_runs_the_executor() -> None:
    build("robot-executor")
    assert "usage: voicectl health" in output("voicectl-robot:latest", "health", "--help")
    assert "usage: voicectl executor" in output("voicectl-robot:latest", "executor", "--help")
    # The host's commands say which extra they lack, in one line (the image has no pip).
    said = output("voicectl-robot:latest", "parse", "turn left")
    assert "lacks voicectl's [converter] extra (this installation has no pip" in said
    size = subprocess.run(
        ["docker", "image", "inspect", "--format", "{{.Size}}", "voicectl-robot:latest"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    print(f"robot image: {int(size) / 1e6:.0f} MB on {base_image()}")
    assert int(size) <= 250e6
