"""The executor's settings: its command line, and the frozen config it becomes."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

from voicectl.shared.config import data_dir
from voicectl.shared.process import add_bus_arguments, positive_float, robot_name
from voicectl.shared.robot_options import RobotOptions, add_robot_arguments, robot_options

from .robot import RESULT_GRACE
from .runner import STALL_LIMIT
from .speed import SAFE_LIMITS, SpeedLimits


@dataclass(frozen=True)
class ExecutorConfig:
    """One robot's executor: how it reaches the robot, what runs its orders, how fast."""

    robot: str = "robot"
    """Its name on the voice bus."""
    reach: RobotOptions = field(default_factory=RobotOptions)
    """Its ROS names, transport, domain and distribution."""
    bindings: tuple[str, ...] = ()
    """User executors, `MODULE:CLASS[=LABEL,...]`."""
    binding_files: tuple[Path, ...] = ()
    """YAML files of executor bindings with constructor arguments."""
    photo_dir: Path | None = None
    """Where `pic` keeps photos; None: the data directory's `photos`."""
    cancel_deadline: float = 2.0
    stall_limit: float = STALL_LIMIT
    result_grace: float = RESULT_GRACE
    limits: SpeedLimits = SAFE_LIMITS

    @property
    def photos(self) -> Path:
        return (self.photo_dir or data_dir() / "photos").expanduser()

    @classmethod
    def of(cls, args: argparse.Namespace) -> ExecutorConfig:
        """The config the command line (`parse_args`) gives."""
        return cls(
            robot=args.robot,
            reach=robot_options(args),
            bindings=tuple(args.executor),
            binding_files=tuple(args.executors),
            photo_dir=args.photo_dir,
            cancel_deadline=args.cancel_deadline,
            stall_limit=args.stall_limit,
            result_grace=args.result_grace,
            limits=SpeedLimits(
                linear=args.limit_linear,
                angular=args.limit_angular,
                linear_accel=args.limit_linear_accel,
                angular_accel=args.limit_angular_accel,
            ),
        )


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl executor",
        description="Run orders on one robot with the built-in and user executors.",
    )
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
    for flag, limit, unit in (
        ("--max-speed", "linear", "m/s"),
        ("--max-angular-speed", "angular", "rad/s"),
        ("--max-accel", "linear_accel", "m/s², speeding up"),
        ("--max-angular-accel", "angular_accel", "rad/s², speeding up"),
    ):
        default = getattr(SAFE_LIMITS, limit)
        limits.add_argument(
            flag,
            dest=f"limit_{limit}",
            type=positive_float,
            default=default,
            metavar=unit.split(",")[0],
            help=f"{unit} (default: {default:g})",
        )
    add_bus_arguments(parser)
    add_robot_arguments(parser, detect=True)
    return parser.parse_args(argv)
