"""Real ROS 2 in the tests: the venvs of harness/ros2_env.py, their CDR oracle, and a
network namespace with only loopback up for every process that starts a DDS participant.

The tests that need real ROS 2 are marked `ros2` and run when `VOICECTL_ROS2` is set
(scripts/test-ros2 sets it to `required`, which makes a missing venv a failure); the
README's test command leaves them to that step (docs/deploy.md, "Tests").
"""

from __future__ import annotations

import json
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

import pytest

from harness import ros2_env
from harness.processes import REPO

DISTROS = tuple(ros2_env.DISTROS)
"""Every distribution the tests run real ROS 2 of: jazzy, kilted."""


def env_of(distro: str, bare: bool = False) -> ros2_env.Ros2Env:
    """The made venv of `distro` (`bare`: PyPI's wheels alone, no nav2_msgs); skips the
    test when real ROS 2 was not asked for, fails it when it was asked for and is not made."""
    wanted = os.environ.get("VOICECTL_ROS2", "")
    if not wanted:
        pytest.skip("real ROS 2 runs in scripts/test-ros2 (or with VOICECTL_ROS2=1)")
    found = ros2_env.find(distro, bare)
    if found is None:
        missing_here(f"ROS 2 {distro}{' (bare)' if bare else ''} is not made: run scripts/ros2-env")
    return found


def missing_here(why: str) -> NoReturn:
    """Skip a real ROS 2 test for something this machine lacks; where real ROS 2 is
    required (scripts/test-ros2), fail it instead: a skip there would hide it."""
    if os.environ.get("VOICECTL_ROS2") == "required":
        pytest.fail(f"{why} (VOICECTL_ROS2=required)", pytrace=False)
    pytest.skip(why, allow_module_level=True)  # a module whose import needs it, too


class Oracle:
    """harness/ros2_oracle.py in a venv of real ROS 2: its CDR, asked line by line."""

    def __init__(self, env: ros2_env.Ros2Env) -> None:
        self.env = env
        self._process = subprocess.Popen(
            [str(env.python), "-m", "harness.ros2_oracle"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,  # rclpy says why a flipped byte does not decode
            text=True,
            cwd=REPO,
            env=env.environ(),
        )

    def _ask(self, request: dict[str, Any]) -> dict[str, Any]:
        assert self._process.stdin is not None
        assert self._process.stdout is not None
        self._process.stdin.write(json.dumps(request) + "\n")
        self._process.stdin.flush()
        line = self._process.stdout.readline()
        assert line, f"the ROS 2 {self.env.distro} oracle exited"
        reply: dict[str, Any] = json.loads(line)
        assert "error" not in reply, f"ROS 2 {self.env.distro} on {request['type']}: {reply}"
        return reply

    def decode(
        self, ros_type: str, cdr: bytes, probe: list[int] | None = None
    ) -> tuple[Any, list[int]]:
        """What real ROS reads in `cdr`, and which of the `probe` offsets it does not read."""
        request = {"op": "decode", "type": ros_type, "cdr": cdr.hex(), "probe": probe or []}
        reply = self._ask(request)
        return reply["values"], reply["ignored"]

    def encode(self, ros_type: str, values: dict[str, Any]) -> bytes:
        return bytes.fromhex(self._ask({"op": "encode", "type": ros_type, "values": values})["cdr"])

    def close(self) -> None:
        if self._process.stdin is not None:
            self._process.stdin.close()
        self._process.wait(timeout=10)
        if self._process.stdout is not None:
            self._process.stdout.close()


def oracle_of(distro: str) -> Iterator[Oracle]:
    oracle = Oracle(env_of(distro))
    try:
        yield oracle
    finally:
        oracle.close()


def type_hashes(share: Path, ros_type: str) -> set[str]:
    """The RIHS01 hashes rosidl wrote for `ros_type` into the type descriptions of a
    venv's `share/<package>/<kind>/` (an action's member types are in the action's file)."""
    package, kind, _ = ros_type.split("/")
    found = set()
    for description in (share / package / kind).glob("*.json"):
        for entry in json.loads(description.read_text())["type_hashes"]:
            if entry["type_name"] == ros_type:
                found.add(entry["hash_string"])
    return found
