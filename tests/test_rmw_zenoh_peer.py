"""voicectl's rmw_zenoh layout against an independent implementation of it: PyPI's
`zenoh-ros2-sdk` (ROBOTIS), a Python peer that speaks rmw_zenoh's keys, attachments and
liveliness tokens without ROS 2, here given the message definitions of real ROS 2 (the
Kilted wheels' `share/`, harness/ros2_env.py) instead of fetching them.

Both ways: the SDK subscribes to the simulator's odometry, drives it on cmd_vel, and calls
its navigation's cancel service; and voicectl's transport calls a cancel service the SDK
serves (on the exact key, as rmw_zenoh's clients ask) and hears what it publishes."""

from __future__ import annotations

import asyncio
import re
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from harness.wait import async_wait_until
from voicectl.shared.robot import TransportKind, open_transport
from voicectl.shared.ros2 import CANCEL_GOAL, Ros2Codec

from .conftest import Processes
from .ros2_support import env_of, missing_here
from .support import joined

pytestmark = pytest.mark.ros2

try:
    import zenoh_ros2_sdk as sdk
except ImportError as exc:  # the test extra installs it
    missing_here(f"zenoh-ros2-sdk does not import: {exc}")

PACKAGES = (
    "builtin_interfaces",
    "std_msgs",
    "geometry_msgs",
    "nav_msgs",
    "action_msgs",
    "unique_identifier_msgs",
    "service_msgs",
)


def _qualified(text: str, package: str, own: set[str]) -> str:
    """A definition whose fields of the package's own message types name it."""
    return re.sub(
        r"^([A-Z]\w*)\b",
        lambda m: f"{package}/{m[1]}" if m[1] in own else m[1],
        text,
        flags=re.MULTILINE,
    )


def _not_definitions(_folder: str, names: list[str]) -> list[str]:
    return [n for n in names if "." in n and not n.endswith((".msg", ".srv"))]


@pytest.fixture
def peer(router: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Any]:
    """The SDK's process-wide session on `router`, closed afterwards. It reads the message
    definitions of real ROS 2, a service's halves as messages of their own too, where it
    would otherwise clone them from the network: git may not (it only names a local
    file), so a definition missing here fails the test instead of being fetched."""
    monkeypatch.setenv("GIT_ALLOW_PROTOCOL", "file")
    definitions = tmp_path / "definitions"
    share = env_of("kilted").share
    for package in PACKAGES:
        shutil.copytree(share / package, definitions / package, ignore=_not_definitions)
        for service in (definitions / package).glob("srv/*.srv"):
            # Its own messages named in full: the SDK would look for them under srv/.
            own = {m.stem for m in (definitions / package).glob("msg/*.msg")}
            text = _qualified(service.read_text(), package, own)
            service.write_text(text)
            request, response = text.split("\n---\n")
            service.with_name(f"{service.stem}_Request.msg").write_text(request)
            service.with_name(f"{service.stem}_Response.msg").write_text(response)
    sdk.message_registry._registry = None
    sdk.get_registry(str(definitions))
    host, port = router.removeprefix("tcp/").rsplit(":", 1)
    session = sdk.ZenohSession.get_instance(host, int(port))
    try:
        yield session
    finally:
        session.close()
        sdk.ZenohSession._instance = None  # a new one for the next test's router


def endpoint(router: str) -> dict[str, Any]:
    host, port = router.removeprefix("tcp/").rsplit(":", 1)
    return {"router_ip": host, "router_port": int(port)}


async def test_an_independent_rmw_zenoh_peer_drives_the_simulated_robot(
    router: str, processes: Processes, peer: Any
) -> None:
    processes.start("voicectl.services.sim", "--connect", router, "--transport", "rmw-zenoh")
    odometry: list[Any] = []
    where = endpoint(router)
    heard = sdk.ROS2Subscriber("/odom", "nav_msgs/msg/Odometry", odometry.append, **where)
    drive = sdk.ROS2Publisher("/cmd_vel", "geometry_msgs/msg/Twist", **where)
    cancel = sdk.ROS2ServiceClient(
        "/navigate_to_pose/_action/cancel_goal", CANCEL_GOAL, timeout=5.0, **where
    )
    try:
        await async_wait_until(lambda: odometry, 30.0, "odometry through the SDK")

        vector = sdk.get_message_class("geometry_msgs/msg/Vector3")

        def driving() -> bool:
            drive.publish(linear=vector(x=0.3, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
            return odometry[-1].twist.twist.linear.x > 0.2

        await async_wait_until(driving, 10.0, "the robot to drive on the SDK's cmd_vel")
        message = sdk.get_message_class
        goal_info = message("action_msgs/msg/GoalInfo")(
            goal_id=message("unique_identifier_msgs/msg/UUID")(uuid=np.zeros(16, dtype=np.uint8)),
            stamp=message("builtin_interfaces/msg/Time")(sec=0, nanosec=0),
        )
        answer = await asyncio.to_thread(cancel.call, goal_info=goal_info)
        assert answer is not None, "the simulator did not answer the SDK's cancel"
        assert answer.return_code == 0
    finally:
        for entity in (heard, drive, cancel):
            entity.close()


async def test_voicectl_calls_and_hears_an_independent_rmw_zenoh_peer(
    router: str, peer: Any
) -> None:
    codec = Ros2Codec()
    asked: list[Any] = []

    def on_cancel(request: Any) -> Any:
        asked.append(request)
        return server.response_msg_class(return_code=2, goals_canceling=[])

    where = endpoint(router)
    server = sdk.ROS2ServiceServer(
        "/navigate_to_pose/_action/cancel_goal", CANCEL_GOAL, on_cancel, **where
    )
    status = sdk.ROS2Publisher("/cmd_vel_echo", "geometry_msgs/msg/Twist", **where)
    try:
        with joined(router) as bus:
            transport = open_transport(bus, TransportKind.RMW_ZENOH, "voicectl_stop", "")
            transport.follow()
            heard: list[tuple[float, float]] = []
            transport.subscribe(
                "cmd_vel_echo", "geometry_msgs/msg/Twist", codec.read_twist, heard.append
            )

            async def answered() -> bytes | None:
                try:
                    return await transport.call(
                        "navigate_to_pose/_action/cancel_goal",
                        CANCEL_GOAL,
                        codec.cancel_goal_request(),
                        2.0,
                    )
                except Exception:
                    return None

            replies: list[bytes] = []

            async def reply() -> bool:
                got = await answered()
                if got is not None:
                    replies.append(got)
                return bool(replies)

            await async_wait_until(reply, 20.0, "the SDK's server to answer voicectl")
            assert codec.read_cancel_goal_response(replies[0]).return_code == 2
            assert asked

            vector = sdk.get_message_class("geometry_msgs/msg/Vector3")

            def echoed() -> bool:
                status.publish(
                    linear=vector(x=0.25, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.5)
                )
                return bool(heard)

            await async_wait_until(echoed, 10.0, "voicectl to hear the SDK's publication")
            assert heard[0] == (0.25, 0.5)
    finally:
        server.close()
        status.close()
