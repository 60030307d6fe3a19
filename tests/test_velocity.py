"""The last check before a velocity leaves (shared/robot/velocity.py, and every transport's
`publish`): no Twist or TwistStamped with an axis that is not a finite number reaches the
robot's bytes, whoever publishes it; zero velocity goes instead."""

from __future__ import annotations

import asyncio
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from harness.wait import async_wait_until
from voicectl.shared.errors import UnsafeCommand
from voicectl.shared.kinds import ON_ZENOH, CmdVelType, RosDistro, TransportKind
from voicectl.shared.robot import open_transport
from voicectl.shared.robot.velocity import AXES, stilled, unsafe_velocity
from voicectl.shared.ros2 import Ros2Codec, typestore

from .support import joined

AXIS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.just(0.0))
"""Any float, zero often."""


def velocity(kind: CmdVelType, axes: tuple[float, ...], frame: str = "base_link") -> bytes:
    """A velocity command with every axis set, as rosbags writes it."""
    store = typestore(RosDistro.JAZZY)
    vector = store.types["geometry_msgs/msg/Vector3"]
    twist = store.types["geometry_msgs/msg/Twist"](
        linear=vector(*axes[:3]), angular=vector(*axes[3:])
    )
    if kind is CmdVelType.TWIST:
        return bytes(store.serialize_cdr(twist, kind.ros_type))
    header = store.types["std_msgs/msg/Header"](
        stamp=store.types["builtin_interfaces/msg/Time"](sec=12, nanosec=5), frame_id=frame
    )
    message = store.types[kind.ros_type](header=header, twist=twist)
    return bytes(store.serialize_cdr(message, kind.ros_type))


@given(st.sampled_from(CmdVelType), st.tuples(*[AXIS] * 6), st.text(max_size=12))
def test_a_velocity_is_refused_exactly_when_an_axis_is_not_finite(
    kind: CmdVelType, axes: tuple[float, ...], frame: str
) -> None:
    payload = velocity(kind, axes, frame)
    refused = unsafe_velocity(kind.ros_type, payload)
    wrong = [axis for axis, value in zip(AXES, axes, strict=True) if not math.isfinite(value)]
    if not wrong:
        assert refused is None
        return
    assert refused is not None
    assert "\n" not in refused
    for axis in AXES:
        assert (f"{axis} " in refused) is (axis in wrong)
    still = stilled(kind.ros_type, payload)
    codec = Ros2Codec()
    assert codec.velocity_axes(kind, still) == (0.0,) * 6
    assert unsafe_velocity(kind.ros_type, still) is None
    if kind is CmdVelType.STAMPED:  # the header as it was
        assert codec.read_twist_stamped(still) == (0.0, 0.0)
        assert (
            still[: 4 + 12 + len(frame.encode()) + 1] == payload[: 4 + 12 + len(frame.encode()) + 1]
        )


def test_other_messages_and_unreadable_bytes_are_not_judged() -> None:
    codec = Ros2Codec()
    assert unsafe_velocity("nav_msgs/msg/Odometry", b"\x00\x01\x00\x00" + b"\xff" * 60) is None
    assert unsafe_velocity(CmdVelType.TWIST.ros_type, b"\x00\x01\x00\x00\x01") is None
    assert unsafe_velocity(CmdVelType.TWIST.ros_type, codec.twist(0.5, -1.0)) is None


@pytest.mark.parametrize("kind", list(ON_ZENOH), ids=str)
@pytest.mark.parametrize("cmd_vel", list(CmdVelType), ids=str)
async def test_no_transport_sends_a_velocity_that_is_not_a_number(
    router: str, kind: TransportKind, cmd_vel: CmdVelType
) -> None:
    """Published on the transport itself (below the executor's own checks), a NaN or
    infinite velocity raises UnsafeCommand, and the robot hears zero in its place; a
    finite one goes as it was. (The ros2 transport: tests/test_ros2_transport.py.)"""
    heard: list[tuple[float, ...]] = []
    codec = Ros2Codec()
    with joined(router) as sender_bus, joined(router) as robot_bus:
        robot = open_transport(robot_bus, kind, "robot_base")
        robot.subscribe(
            "cmd_vel",
            cmd_vel.ros_type,
            lambda raw: codec.velocity_axes(cmd_vel, raw),
            heard.append,
        )
        sender = open_transport(sender_bus, kind, "voicectl_test")
        calm = velocity(cmd_vel, (0.3, 0.0, 0.0, 0.0, 0.0, 0.2))
        warm = (0.1, 0.0, 0.0, 0.0, 0.0, 0.0)

        def warmed() -> bool:  # until the robot hears this sender at all
            sender.publish("cmd_vel", cmd_vel.ros_type, velocity(cmd_vel, warm))
            return bool(heard)

        await async_wait_until(warmed, 10.0, "the robot to hear the sender")
        for value in (math.nan, math.inf, -math.inf):
            wild = velocity(cmd_vel, (0.3, value, 0.0, 0.0, 0.0, 0.2))
            with pytest.raises(UnsafeCommand, match=r"linear\.y .*must be a finite number"):
                sender.publish("cmd_vel", cmd_vel.ros_type, wild)
        sender.publish("cmd_vel", cmd_vel.ros_type, calm)

        def tested() -> list[tuple[float, ...]]:
            return [axes for axes in heard if axes != warm]

        await async_wait_until(lambda: len(tested()) >= 4, 10.0, "four velocities at the robot")
        await asyncio.sleep(0.2)  # anything else sent would have come by now
    # Zero velocity goes at a stop's priority, ahead of the rest: compared as a set.
    assert sorted(tested()) == [(0.0,) * 6] * 3 + [(0.3, 0.0, 0.0, 0.0, 0.0, 0.2)]
