"""`voicectl executor`: run orders on one robot with the built-in and user executors."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path

from shared.bus import Bus
from shared.config import data_dir
from shared.errors import ServiceError
from shared.keys import RobotKeys
from shared.process import (
    add_bus_arguments,
    open_bus,
    positive_float,
    robot_name,
    run_service,
    serve,
)
from shared.robot import TransportKind, detect_transport, open_transport, transports
from shared.robot_options import add_robot_arguments, robot_options

from .builtin import builtin_executors
from .framework import BindingError, Bindings, load_binding, load_bindings_file
from .photos import PhotoShelf
from .robot import RESULT_GRACE, SAFE_LIMITS, MapRelay, PoseRelay, RobotLink, SpeedLimits
from .runner import STALL_LIMIT, ExecutorService

_LOGGER = logging.getLogger(__name__)

NODE = "voicectl_executor"
"""The ROS node the executor appears as on the robot, where nodes are seen (rmw_zenoh)."""
DETECT_WAIT = 3.0
"""Seconds `--transport auto` waits for the robot's graph to announce itself."""


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="voicectl executor", description=__doc__)
    parser.add_argument(
        "--robot",
        default="robot",
        type=robot_name,
        help="robot name on the voice bus (default: robot)",
    )
    parser.add_argument(
        "--executor",
        action="append",
        default=[],
        metavar="MODULE:CLASS[=LABEL,...]",
        help="bind a user executor class to labels (repeatable)",
    )
    parser.add_argument(
        "--executors",
        action="append",
        default=[],
        type=Path,
        metavar="FILE",
        help="YAML file of executor bindings with constructor arguments (repeatable)",
    )
    parser.add_argument(
        "--photo-dir",
        type=Path,
        default=None,
        help="where the pic executor saves photos (default: data dir/photos)",
    )
    parser.add_argument(
        "--cancel-deadline",
        type=float,
        default=2.0,
        help="seconds an executor has to honour a cancel before the robot is halted",
    )
    parser.add_argument(
        "--stall-limit",
        type=float,
        default=STALL_LIMIT,
        help="seconds the event loop may stall (blocking code in an executor) before an "
        "order that commands the robot is halted",
    )
    parser.add_argument(
        "--result-grace",
        type=float,
        default=RESULT_GRACE,
        metavar="SECONDS",
        help="how long navigation's result may stay out of reach (a link down) before the "
        f"goal is cancelled and the order fails (default: {RESULT_GRACE:g})",
    )
    limits = parser.add_argument_group(
        "speed limits", "held to by every velocity the executor sends, whatever an order asks"
    )
    for flag, field, unit in (
        ("--max-speed", "linear", "m/s"),
        ("--max-angular-speed", "angular", "rad/s"),
        ("--max-accel", "linear_accel", "m/s², speeding up"),
        ("--max-angular-accel", "angular_accel", "rad/s², speeding up"),
    ):
        default = getattr(SAFE_LIMITS, field)
        limits.add_argument(
            flag,
            dest=f"limit_{field}",
            type=positive_float,
            default=default,
            metavar=unit.split(",")[0],
            help=f"{unit} (default: {default:g})",
        )
    add_bus_arguments(parser)
    add_robot_arguments(parser, detect=True)
    return parser.parse_args(argv)


def speed_limits(args: argparse.Namespace) -> SpeedLimits:
    return SpeedLimits(
        linear=args.limit_linear,
        angular=args.limit_angular,
        linear_accel=args.limit_linear_accel,
        angular_accel=args.limit_angular_accel,
    )


def photo_directory(args: argparse.Namespace) -> Path:
    return Path(args.photo_dir or data_dir() / "photos").expanduser()


def load_bindings(args: argparse.Namespace) -> Bindings:
    """The built-in executors and those `args` bind; BindingError when one cannot be
    loaded. Before the bus opens: a mistake is told at once, router or not."""
    bindings = Bindings()
    for executor in builtin_executors(photo_directory(args)):
        bindings.bind(executor, executor.labels)
    for path in args.executors:
        for executor, labels in load_bindings_file(path):
            bindings.bind(executor, labels)
    for spec in args.executor:
        bindings.bind(*load_binding(spec))
    return bindings


def executor_service(
    bus: Bus, args: argparse.Namespace, bindings: Bindings, transport: TransportKind
) -> ExecutorService:
    """The executor `args` describe, on `bus`, reaching its robot by `transport`, not
    started (bench/robots.py hosts several)."""
    options = robot_options(args)
    robot = RobotLink(
        open_transport(
            bus, transport, NODE, options.names.namespace, options.domain_id, options.distro
        ),
        options,
        on_change=lambda: service.publish_info(),
        result_grace=args.result_grace,
        limits=speed_limits(args),
    )
    PhotoShelf(photo_directory(args)).serve(bus, RobotKeys(args.robot))
    PoseRelay(bus, RobotKeys(args.robot).pose, robot)
    MapRelay(bus, RobotKeys(args.robot).map, robot)
    service = ExecutorService(
        bus,
        RobotKeys(args.robot),
        robot,
        bindings,
        cancel_deadline=args.cancel_deadline,
        stall_limit=args.stall_limit,
    )
    return service


async def main(args: argparse.Namespace) -> None:
    try:
        bindings = load_bindings(args)
    except BindingError as exc:
        raise ServiceError(str(exc)) from exc
    chosen = robot_options(args).transport
    problem = transports()[chosen].unavailable() if chosen is not None else None
    if problem is not None:
        raise ServiceError(f"--transport {chosen}: {problem}")
    with open_bus(args) as bus:
        transport = await choose_transport(bus, args)
        service = executor_service(bus, args, bindings, transport)
        await serve(service)
    if service.abandoned:
        # asyncio.run would wait for these forever: an executor that ignores cancellation
        # must not keep the process alive once the bus is closed.
        _LOGGER.warning(
            "exiting past %d executor task(s) that ignore cancel", len(service.abandoned)
        )
        logging.shutdown()
        os._exit(0)


async def choose_transport(bus: Bus, args: argparse.Namespace) -> TransportKind:
    """The transport `--transport` names, or with `auto` the one the robot's graph
    announces itself in; when it announces nothing on Zenoh, a plain ROS 2 node where
    rclpy can be imported, else the bridge."""
    options = robot_options(args)
    if options.transport is not None:
        return options.transport
    found = await detect_transport(bus, options.names, options.domain_id, DETECT_WAIT)
    if found is None:
        _LOGGER.warning(
            "the robot announced nothing in %g s and rclpy cannot be imported here; reaching "
            "it through the bridge (see --transport)",
            DETECT_WAIT,
        )
        return TransportKind.BRIDGE
    _LOGGER.info("the robot's graph speaks %s", found)  # ros2: none answered on Zenoh
    return found


def run(argv: list[str] | None = None) -> int:
    return run_service("voicectl executor", parse_args(argv), main)


if __name__ == "__main__":
    sys.exit(run())
