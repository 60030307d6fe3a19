"""The kinds of robot voicectl reaches: how, in which ROS 2 distribution, and what its
velocity and camera topics carry. Plain enums, without the codec: the messages that name
them are imported by every service."""

from __future__ import annotations

from enum import StrEnum
from typing import Self


class TransportKind(StrEnum):
    """How the robot's ROS 2 graph is reached: one member per transport of `TRANSPORTS`
    (`shared/robot/__init__.py`), the name messages and `--transport` know it by."""

    BRIDGE = "bridge"
    """zenoh-bridge-ros2dds in front of a DDS graph."""
    RMW_ZENOH = "rmw-zenoh"
    """ROS 2 nodes on rmw_zenoh: no bridge, no DDS."""
    ROS2 = "ros2"
    """A plain ROS 2 node on DDS (rclpy): no bridge, no Zenoh on the robot."""


ON_ZENOH = (TransportKind.BRIDGE, TransportKind.RMW_ZENOH)
"""The transports whose robots are on Zenoh: those voicectl's simulator plays, and those a
process with Zenoh alone reaches directly."""


class RosDistro(StrEnum):
    """The ROS 2 distributions whose message definitions voicectl speaks (Kilted's are
    Jazzy's for every message voicectl uses)."""

    HUMBLE = "humble"
    JAZZY = "jazzy"
    ROLLING = "rolling"
    """Nav2's NavigateToPose feedback has two more fields than Jazzy's (its result is
    Jazzy's): told apart by its type hash, on rmw_zenoh."""


class _TopicType(StrEnum):
    """A choice between message types for one topic, each with its ROS type name."""

    @property
    def ros_type(self) -> str:
        return _ROS_TYPES[self]

    @classmethod
    def of(cls, ros_type: str) -> Self | None:
        """The choice an announced type names, if it is one of these."""
        return next((kind for kind in cls if kind.ros_type == ros_type), None)


class CmdVelType(_TopicType):
    """What a robot's velocity topic takes: Humble's and most drivers' Twist, or the
    TwistStamped of Jazzy's ros2_control diff drive controller and Kilted's Nav2."""

    TWIST = "twist"
    STAMPED = "stamped"


class CameraType(_TopicType):
    """A camera topic's message: raw sensor_msgs/Image or a CompressedImage (JPEG, PNG)."""

    RAW = "raw"
    COMPRESSED = "compressed"


_ROS_TYPES: dict[_TopicType, str] = {
    CmdVelType.TWIST: "geometry_msgs/msg/Twist",
    CmdVelType.STAMPED: "geometry_msgs/msg/TwistStamped",
    CameraType.RAW: "sensor_msgs/msg/Image",
    CameraType.COMPRESSED: "sensor_msgs/msg/CompressedImage",
}
