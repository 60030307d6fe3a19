"""voicectl sim: run one simulated robot until SIGINT or SIGTERM."""

from __future__ import annotations

import argparse
import logging
import sys

from shared.bus import Bus
from shared.process import add_bus_arguments, open_bus, run_service, serve
from shared.robot import TransportKind, open_transport
from shared.robot_options import add_robot_arguments, robot_options
from shared.ros2 import CameraType, CmdVelType, Ros2Codec, RosDistro

from .node import SimConfig, SimFault, SimNode
from .robot import Bounds, SpeedLimits

_LOGGER = logging.getLogger(__name__)

NODE = "voicectl_sim"
"""The ROS node the simulated robot appears as, where nodes are seen (rmw_zenoh)."""


def _bounds(text: str) -> Bounds:
    try:
        return Bounds.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = 0.0
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return value


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
        type=_positive,
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
        "--max-linear", type=_positive, default=0.5, metavar="M/S", help="default: 0.5"
    )
    parser.add_argument(
        "--max-angular", type=_positive, default=1.5, metavar="RAD/S", help="default: 1.5"
    )
    return parser


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def sim_node(bus: Bus, args: argparse.Namespace) -> SimNode:
    """The simulated robot `args` describe, on `bus` (bench/robots.py hosts several)."""
    robot = robot_options(args)
    config = SimConfig(
        names=robot.names,
        cmd_vel_type=robot.cmd_vel_type or CmdVelType.TWIST,
        camera_type=robot.camera_type or CameraType.RAW,
        faults=frozenset(args.fault),
        time_scale=args.time_scale,
        bounds=args.bounds,
        limits=SpeedLimits(max_linear=args.max_linear, max_angular=args.max_angular),
    )
    distro = robot.distro or RosDistro.JAZZY
    kind = robot.transport or TransportKind.BRIDGE
    transport = open_transport(bus, kind, NODE, robot.names.namespace, robot.domain_id, distro)
    return SimNode(
        transport, Ros2Codec(distro), config, ready=lambda: bus.announce(robot.names.simulator)
    )


async def main(args: argparse.Namespace) -> None:
    with open_bus(args) as bus:
        await serve(sim_node(bus, args))


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl sim", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
