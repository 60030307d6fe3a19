"""The zenoh-bridge-ros2dds configuration shipped for a Nav2 robot, read as the bridge
reads it (JSON5), and checked against the names voicectl uses and docs/deploy.md."""

from __future__ import annotations

import re
import shlex
from typing import Any

import json5
import pytest

from voicectl.services.executor.config import parse_args
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.robot_options import robot_options

from .conftest import REPO
from .test_docs import block_after

CONFIG = REPO / "deploy" / "zenoh-bridge-ros2dds.json5"
DEPLOY = REPO / "docs" / "deploy.md"
# The bridge's options, from its DEFAULT_CONFIG.json5 (1.x): a misspelt one is ignored
# silently by nothing but a reader like this test.
BRIDGE_OPTIONS = {
    "nodename",
    "namespace",
    "domain",
    "ros_localhost_only",
    "shm_enabled",
    "allow",
    "deny",
    "pub_max_frequencies",
    "pub_priorities",
    "reliable_routes_blocking",
    "queries_timeout",
    "transient_local_cache_multiplier",
    "work_thread_num",
    "max_block_thread_num",
}
INTERFACE_KINDS = {
    "publishers",
    "subscribers",
    "service_servers",
    "service_clients",
    "action_servers",
    "action_clients",
}


@pytest.fixture(scope="module")
def bridge() -> dict[str, Any]:
    config = json5.loads(CONFIG.read_text())
    plugin: dict[str, Any] = config["plugins"]["ros2dds"]
    return plugin


def allowed(bridge: dict[str, Any], kind: str, ros_name: str) -> bool:
    return any(re.fullmatch(pattern, ros_name) for pattern in bridge["allow"][kind])


def test_every_option_is_one_the_bridge_knows(bridge: dict[str, Any]) -> None:
    assert set(bridge) <= BRIDGE_OPTIONS
    assert set(bridge["allow"]) == INTERFACE_KINDS  # a kind left out would allow none
    for patterns in bridge["allow"].values():
        for pattern in patterns:
            re.compile(pattern)
    for limit in bridge["pub_max_frequencies"]:
        pattern, _, hertz = limit.rpartition("=")
        re.compile(pattern)
        assert float(hertz) > 0, limit


@pytest.mark.parametrize(
    "keys",
    [
        RobotNames(),
        RobotNames(
            cmd_vel_name="diff_drive_controller/cmd_vel",
            camera_name="front/image_raw/compressed",
        ),
    ],
    ids=["default", "remapped"],
)
def test_what_voicectl_uses_is_routed(bridge: dict[str, Any], keys: RobotNames) -> None:
    assert allowed(bridge, "subscribers", f"/{keys.cmd_vel_name}")
    assert allowed(bridge, "subscribers", f"/{keys.speed_limit_name}")  # Nav2's controller's
    assert allowed(bridge, "publishers", f"/{keys.odom_name}")
    assert allowed(bridge, "publishers", f"/{keys.camera_name}")
    assert allowed(bridge, "action_servers", f"/{keys.navigate_name}")
    assert any(
        re.fullmatch(p.rpartition("=")[0], f"/{keys.camera_name}")
        for p in bridge["pub_max_frequencies"]
    )


@pytest.mark.parametrize(
    ("kind", "ros_name"),
    [
        ("publishers", "/rosout"),
        ("publishers", "/parameter_events"),
        ("publishers", "/cmd_vel"),  # Nav2's own output must not cross
        ("subscribers", "/initialpose"),
        ("service_servers", "/bt_navigator/set_parameters"),
        ("action_servers", "/follow_waypoints"),
    ],
)
def test_nothing_else_of_the_robot_is_routed(
    bridge: dict[str, Any], kind: str, ros_name: str
) -> None:
    assert not allowed(bridge, kind, ros_name)


def test_the_documented_executor_matches_the_config(bridge: dict[str, Any]) -> None:
    bridge_line = block_after(DEPLOY, "On the robot, with Nav2 running", "sh").strip()
    assert "-c deploy/zenoh-bridge-ros2dds.json5" in bridge_line
    executor_line = block_after(DEPLOY, "and the executor, anywhere", "sh").strip()
    words = shlex.split(executor_line)
    assert words[:2] == [".venv/bin/voicectl", "executor"]
    options = robot_options(parse_args(words[2:]))
    assert options.names.namespace == bridge["namespace"].strip("/")
