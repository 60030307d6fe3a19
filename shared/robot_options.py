"""How to reach one robot through zenoh-bridge-ros2dds: its namespace, the names of its
topics and action, and the message types they take.

`voicectl executor` and `voicectl sim` take the same flags, so that a simulator plays
exactly the robot an executor is configured for. An executor may leave a type to be
detected ('auto'): from the bridge's liveliness tokens for topics, from a harmless
get_result query for the ROS distribution.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

from .keys import BridgeKeys, check_ros_name
from .ros2 import CameraType, CmdVelType, RosDistro

AUTO = "auto"
_Kind = TypeVar("_Kind", RosDistro, CmdVelType, CameraType)


@dataclass(frozen=True)
class RobotOptions:
    keys: BridgeKeys = field(default_factory=BridgeKeys)
    distro: RosDistro | None = None
    """None: detect it."""
    cmd_vel_type: CmdVelType | None = None
    camera_type: CameraType | None = None


def _ros_name(what: str, allow_empty: bool = False) -> Callable[[str], str]:
    def parse(text: str) -> str:
        try:
            name = check_ros_name(text, what)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from exc
        if not name and not allow_empty:
            raise argparse.ArgumentTypeError(f"{what} must not be empty")
        return name

    parse.__name__ = what  # argparse names the type in its own messages
    return parse


def add_robot_arguments(parser: argparse.ArgumentParser, detect: bool) -> None:
    """The robot's flags; with `detect`, types default to 'auto'."""
    group = parser.add_argument_group("the robot through zenoh-bridge-ros2dds")
    group.add_argument(
        "--namespace",
        type=_ros_name("ROS namespace", allow_empty=True),
        default="",
        help="the bridge's namespace for this robot (default: none)",
    )
    names = BridgeKeys()
    for flag, default, what in (
        ("--cmd-vel", names.cmd_vel_name, "velocity topic"),
        ("--odom", names.odom_name, "odometry topic"),
        ("--camera", names.camera_name, "camera topic"),
        ("--navigate", names.navigate_name, "Nav2 NavigateToPose action"),
    ):
        group.add_argument(
            flag,
            type=_ros_name(f"{flag[2:]} name"),
            default=default,
            metavar="NAME",
            help=f"the robot's {what} (default: {default})",
        )
    for flag, kinds, fixed, what in (
        ("--distro", RosDistro, RosDistro.JAZZY, "ROS 2 distribution (message layouts differ)"),
        ("--cmd-vel-type", CmdVelType, CmdVelType.TWIST, "what the velocity topic takes"),
        ("--camera-type", CameraType, CameraType.RAW, "what the camera topic carries"),
    ):
        choices = [kind.value for kind in kinds]
        group.add_argument(
            flag,
            choices=[AUTO, *choices] if detect else choices,
            default=AUTO if detect else fixed.value,
            help=f"{what} (default: {AUTO if detect else fixed.value})",
        )


def robot_options(args: argparse.Namespace) -> RobotOptions:
    def chosen(kind: type[_Kind], value: str) -> _Kind | None:
        return None if value == AUTO else kind(value)

    return RobotOptions(
        keys=BridgeKeys(
            args.namespace,
            cmd_vel_name=args.cmd_vel,
            odom_name=args.odom,
            camera_name=args.camera,
            navigate_name=args.navigate,
        ),
        distro=chosen(RosDistro, args.distro),
        cmd_vel_type=chosen(CmdVelType, args.cmd_vel_type),
        camera_type=chosen(CameraType, args.camera_type),
    )
