"""The ros2 transport's place among the others, without real ROS 2 (tests/test_ros2_transport.py
has the robot): where rclpy is missing it says so in one line before anything waits for a
router; `auto` does not pick it there, and falls back to the bridge when no robot says
anything; and a process with Zenoh alone stops a robot on DDS through the STOP relay's
layout, the bridge's keys."""

from __future__ import annotations

import importlib.util
import re
import time

import pytest

from harness.processes import Processes
from harness.wait import async_wait_until
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import ExecutorInfo
from voicectl.shared.robot import TransportKind, detect_transport, transports
from voicectl.shared.robot.stop import RobotStop
from voicectl.shared.ros2 import CmdVelType, Ros2Codec

from .conftest import REPO, voicectl
from .support import joined, until_heard

NO_RCLPY = pytest.mark.skipif(
    importlib.util.find_spec("rclpy") is not None, reason="rclpy is installed here"
)


@NO_RCLPY
@pytest.mark.parametrize("command", [["executor", "--transport", "ros2"], ["relay"]])
def test_without_rclpy_the_ros2_transport_says_what_to_install_at_once(command: list[str]) -> None:
    # A router nobody runs: the answer comes before any wait for it.
    started = time.monotonic()
    done = voicectl(*command, "--connect", "tcp/127.0.0.1:9", timeout=30.0)
    assert done.returncode == 2, done
    (line,) = done.stderr.strip().splitlines()
    assert "rclpy cannot be imported" in line
    assert re.search(r"pip install (-e '[^']*|'voicectl)\[ros2\]'", line), line
    assert time.monotonic() - started < 10.0


@NO_RCLPY
async def test_auto_does_not_pick_ros2_where_rclpy_is_missing(router: str) -> None:
    from voicectl.shared.robot.keys import RobotNames

    assert transports()[TransportKind.ROS2].unavailable() is not None
    with joined(router) as bus:
        assert await detect_transport(bus, RobotNames(), 0, 0.2) is None


async def test_a_process_with_zenoh_alone_stops_a_dds_robot_on_the_relays_keys(
    router: str,
) -> None:
    """The supervisor's and the clients' stop of an executor on ros2 goes to the bridge's
    keys, where the robot's STOP relay listens: without rclpy in this process."""
    info = ExecutorInfo(
        transport=TransportKind.ROS2, namespace="bot1", cmd_vel_type=CmdVelType.STAMPED
    )
    heard: list[tuple[float, float]] = []
    codec = Ros2Codec()
    with joined(router) as relay, joined(router) as bus:
        relay.subscribe("bot1/cmd_vel", codec.read_twist_stamped, lambda _k, v: heard.append(v))
        await until_heard(bus, "bot1/cmd_vel")
        stop = RobotStop.of(info, bus)
        assert stop.transport.kind is TransportKind.BRIDGE
        stop.zero_velocity()
        await async_wait_until(lambda: heard, 5.0, "zero velocity on the relay's key")
        assert heard[0] == (0.0, 0.0)


def test_the_deploy_doc_s_ros2_commands_parse_as_written() -> None:
    """docs/deploy.md's commands for a robot on DDS, with HOST filled in: their flags are
    the ones the executor and the relay take."""
    from voicectl.services.executor.config import parse_args as executor_args
    from voicectl.services.relay.config import parse_args as relay_args

    doc = (REPO / "docs" / "deploy.md").read_text()
    section = doc[doc.index("## A robot on DDS") : doc.index("## Containers")]
    commands = [
        line.removeprefix(".venv/bin/voicectl ").replace("HOST", "127.0.0.1").split()
        for line in section.splitlines()
        if line.startswith(".venv/bin/voicectl ")
    ]
    assert {command[0] for command in commands} == {"executor", "relay"}
    for command in commands:
        parse = executor_args if command[0] == "executor" else relay_args
        parse(command[1:])


@NO_RCLPY  # with rclpy, `auto` would open a DDS participant here, outside any namespace
async def test_an_executor_left_to_find_a_silent_robot_falls_back_and_comes_online(
    router: str, processes: Processes
) -> None:
    """No robot on the bus: `auto` waits for the robot to say how it is reached, then for
    what cmd_vel takes, says each time what it falls back to (the bridge, Twist), stops
    with that, and comes online. (The other tests that run no robot give the executor
    both on its command line, `ROBOT_GIVEN`, and skip these waits.)"""
    executor = processes.executor(router, "r1")
    online = RobotKeys("r1").alive("executor")
    with joined(router) as bus:

        def executor_online() -> bool:
            replies = bus.session.liveliness().get(online, timeout=1)
            return any(reply.ok is not None for reply in replies)

        await async_wait_until(executor_online, 30.0, "the executor to come online")
    log = processes.log(executor)
    said = [
        log.index("the robot announced nothing in 3 s"),
        log.index("reaching it through the bridge"),
        log.index("has still not said what 'cmd_vel' takes; stopping with Twist"),
        log.index("robot halted at start"),
    ]
    assert said == sorted(said), log
