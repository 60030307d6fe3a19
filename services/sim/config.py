"""The simulator's command line, and the `SimConfig` it becomes."""

from __future__ import annotations

import argparse

from voicectl.shared.process import add_bus_arguments, argument_type, positive_float
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot_options import add_robot_arguments, robot_options
from voicectl.shared.ros2 import CameraType, CmdVelType, RosDistro

from .node import SimConfig, SimFault
from .robot import Bounds, SpeedLimits

_bounds = argument_type(Bounds.parse)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="voicectl sim",
        description="A 2-D robot behind a simulated zenoh-bridge-ros2dds: cmd_vel, odom, "
        "a camera and Nav2's navigate_to_pose action. The robot flags choose which kind of "
        "robot it plays; --fault makes it misbehave.",
    )
    add_bus_arguments(parser)
    add_robot_arguments(parser, detect=False)
    parser.add_argument(
        "--fault",
        action="append",
        type=SimFault,
        choices=list(SimFault),
        default=[],
        help="misbehave this way (repeatable)",
    )
    parser.add_argument(
        "--time-scale",
        type=positive_float,
        default=1.0,
        metavar="FACTOR",
        help="simulated seconds per wall second (default: 1)",
    )
    parser.add_argument(
        "--bounds",
        type=_bounds,
        default=Bounds(),
        metavar="XMIN,YMIN,XMAX,YMAX",
        help="goals outside this rectangle are rejected (default: -10,-10,10,10)",
    )
    parser.add_argument(
        "--max-linear", type=positive_float, default=0.5, metavar="M/S", help="default: 0.5"
    )
    parser.add_argument(
        "--max-angular", type=positive_float, default=1.5, metavar="RAD/S", help="default: 1.5"
    )
    return parser


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def config_of(args: argparse.Namespace) -> SimConfig:
    """The simulated robot the command line (`parse_args`) describes."""
    robot = robot_options(args)
    return SimConfig(
        names=robot.names,
        cmd_vel_type=robot.cmd_vel_type or CmdVelType.TWIST,
        camera_type=robot.camera_type or CameraType.RAW,
        faults=frozenset(args.fault),
        time_scale=args.time_scale,
        bounds=args.bounds,
        limits=SpeedLimits(max_linear=args.max_linear, max_angular=args.max_angular),
        transport=robot.transport or TransportKind.BRIDGE,
        distro=robot.distro or RosDistro.JAZZY,
        domain_id=robot.domain_id,
    )
