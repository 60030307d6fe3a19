"""How to reach one robot: through zenoh-bridge-ros2dds or on rmw_zenoh, its namespace (and
ROS domain), the names of its topics and action, and the message types they take.

`voicectl executor` and `voicectl sim` take the same flags, so that a simulator plays
exactly the robot an executor is configured for. An executor may leave these to be
detected ('auto'): the transport and the types of its topics from what the robot's graph
announces, the ROS distribution from a harmless get_result query.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar

from .kinds import ON_ZENOH, CameraType, CmdVelType, RosDistro, TransportKind
from .robot.keys import RmwZenohKeys, RobotNames, check_ros_name

AUTO = "auto"
_Kind = TypeVar("_Kind", RosDistro, CmdVelType, CameraType, TransportKind)


@dataclass(frozen=True)
class RobotOptions:
    names: RobotNames = field(default_factory=RobotNames)
    transport: TransportKind | None = TransportKind.BRIDGE
    """None: detect it."""
    domain_id: int = 0
    """The ROS domain, on rmw_zenoh."""
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


def add_robot_arguments(
    parser: argparse.ArgumentParser, detect: bool, transport: bool = True
) -> None:
    """The robot's flags; with `detect`, the transport and types default to 'auto';
    without `transport`, no --transport (the STOP relay has one way to the robot)."""
    group = parser.add_argument_group("the robot: its ROS 2 graph over Zenoh")
    if transport:
        _add_transport(group, detect)
    _add_rest(group, detect)


def _add_transport(group: argparse._ArgumentGroup, detect: bool) -> None:
    group.add_argument(
        "--transport",
        choices=[AUTO, *TransportKind] if detect else list(ON_ZENOH),
        default=AUTO if detect else TransportKind.BRIDGE.value,
        help="how the robot's ROS 2 graph is reached: zenoh-bridge-ros2dds ('bridge'), "
        "ROS 2 nodes on rmw_zenoh ('rmw-zenoh')"
        + (", or as a plain ROS 2 node on DDS with rclpy ('ros2')" if detect else "")
        + f" (default: {AUTO if detect else 'bridge'})",
    )


def _add_rest(group: argparse._ArgumentGroup, detect: bool) -> None:
    group.add_argument(
        "--domain-id",
        type=_domain_id,
        default=os.environ.get("ROS_DOMAIN_ID") or "0",  # argparse converts (and checks) it
        metavar="N",
        help="the ROS domain, on rmw_zenoh (default: $ROS_DOMAIN_ID, else 0)",
    )
    group.add_argument(
        "--namespace",
        type=_ros_name("ROS namespace", allow_empty=True),
        default="",
        help="the robot's namespace (default: none)",
    )
    names = RobotNames()
    for flag, default, what in (
        ("--cmd-vel", names.cmd_vel_name, "velocity topic"),
        ("--odom", names.odom_name, "odometry topic"),
        ("--camera", names.camera_name, "camera topic"),
        ("--navigate", names.navigate_name, "Nav2 NavigateToPose action"),
        ("--map", names.map_name, "occupancy grid (a Nav2 robot's map)"),
        ("--speed-limit", names.speed_limit_name, "Nav2 controller's speed limit topic"),
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
        names=RobotNames(
            args.namespace,
            cmd_vel_name=args.cmd_vel,
            odom_name=args.odom,
            camera_name=args.camera,
            navigate_name=args.navigate,
            map_name=args.map,
            speed_limit_name=args.speed_limit,
        ),
        transport=chosen(TransportKind, getattr(args, "transport", TransportKind.ROS2)),
        domain_id=args.domain_id,
        distro=chosen(RosDistro, args.distro),
        cmd_vel_type=chosen(CmdVelType, args.cmd_vel_type),
        camera_type=chosen(CameraType, args.camera_type),
    )


def _domain_id(text: str) -> int:
    try:
        return RmwZenohKeys(int(text)).domain_id
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"ROS domain id {text!r}: {exc}") from exc
