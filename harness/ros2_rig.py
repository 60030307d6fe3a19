"""A robot of real ROS 2 (harness/ros2_robot.py) in a network namespace with only loopback
up, its executor on `--transport ros2` and its STOP relay beside it in the namespace, and a
router, a supervisor and a converter outside: for tests/test_ros2_transport.py and
bench/stop_transports.py.

The router listens on loopback TCP for the processes outside the namespace (the supervisor,
the converter, the test) and on a Unix socket, which a namespace does not wall off, for
those inside. What the robot says (harness/ros2_robot.py: each zero velocity, each cancel,
stamped with CLOCK_MONOTONIC, the same clock in every process) is read from its log.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from harness import netns
from harness.client import Client, client_wait_ready
from harness.netns import LoopbackOnly
from harness.ports import free_port
from harness.processes import REPO, Processes
from harness.ros2_env import Ros2Env
from harness.wait import async_wait_until
from voicectl.shared.bus import BusOptions

ROBOT = "r1"
WAIT = 60.0


@dataclass
class DdsRobot:
    env: Ros2Env
    space: LoopbackOnly
    router: str
    """Where processes outside the namespace reach the router."""
    inside: str
    """Where processes inside reach it."""
    processes: Processes
    executor_args: Sequence[str]
    voicectl_env: Ros2Env | None = None
    """Where voicectl's own processes inside (the executor, the relay) run; None: `env`,
    the robot's."""
    executor: subprocess.Popen[bytes] | None = None
    relay: subprocess.Popen[bytes] | None = None

    def start_inside(
        self, module: str, *args: str, name: str, env: Ros2Env | None = None
    ) -> subprocess.Popen[bytes]:
        env = env or self.env
        return self.space.start(module, *args, name=name, python=env.python, env=env.environ())

    def start_executor(self) -> None:
        self.executor = self.start_inside(
            "voicectl.services.executor",
            *("--transport", "ros2", "--robot", ROBOT, "--connect", self.inside),
            *self.executor_args,
            name="executor",
            env=self.voicectl_env,
        )

    def events(self, what: str, since: float = 0.0) -> list[float]:
        """When the robot said `what` ('zero', 'cancel', 'canceled'...), since `since`."""
        found = []
        for line in self.space.log("robot").splitlines():
            if line.startswith("{"):
                event: dict[str, Any] = json.loads(line)
                if event["event"] == what and event["at"] >= since:
                    found.append(event["at"])
        return found

    async def ready(self, client: Client) -> None:
        """The robot, the relay (matched with the robot on DDS), the supervisor and the
        executor up."""
        await async_wait_until(lambda: self.events("ready"), WAIT, "the ROS 2 robot")
        await async_wait_until(
            lambda: "STOP relay ready" in self.space.log("relay"), WAIT, "the STOP relay"
        )
        await client_wait_ready(client)

    def dump(self) -> str:
        return f"{self.space.dump()}\n{self.processes.dump()}"


@contextlib.contextmanager
def dds_robot(
    env: Ros2Env,
    processes: Processes,
    logs: Path,
    executor_args: Sequence[str] = (),
    relay: str = "voicectl.services.relay",
    robot_args: Sequence[str] = (),
    voicectl_env: Ros2Env | None = None,
) -> Iterator[DdsRobot]:
    """Everything above, started; stopped (and the namespace deleted) whatever happens.
    RuntimeError when no namespace can be made here (not root, no iproute2). `relay`: the
    module the STOP relay runs (harness.blocking_relay: one whose loop can be blocked);
    `robot_args`: harness/ros2_robot.py's (--no-nav2); `voicectl_env`: where the executor
    and the relay run, when not in the robot's venv (a bare one: `ros2_env.BARE`)."""
    missing = netns.unavailable()
    if missing is not None:
        raise RuntimeError(missing)
    space = LoopbackOnly(logs / "robot")
    router = f"tcp/127.0.0.1:{free_port()}"
    inside = space.socket()
    options = BusOptions(mode="router", connect=[], listen=[router, inside])
    session = zenoh.open(options.zenoh_config())
    robot = DdsRobot(env, space, router, inside, processes, executor_args, voicectl_env)
    try:
        robot.start_inside("harness.ros2_robot", *robot_args, name="robot")
        robot.relay = robot.start_inside(
            relay, "--connect", inside, "--debug", name="relay", env=voicectl_env
        )
        robot.start_executor()
        processes.start("voicectl.services.supervisor", "--connect", router, "--robot", ROBOT)
        orders = str(REPO / "orders")
        processes.start("voicectl.services.converter", "--connect", router, "--orders", orders)
        yield robot
    except BaseException:
        print(robot.dump())
        raise
    finally:
        unclean = space.close()
        session.close()
        if unclean:
            raise AssertionError(f"did not stop cleanly: {unclean}\n{robot.dump()}")
