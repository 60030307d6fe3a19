"""The executor's settings: its command line, and the frozen config it becomes."""

from __future__ import annotations

import argparse
import os
from collections.abc import Mapping
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
            limits=args.limits,
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
    add_limit_arguments(parser)
    add_bus_arguments(parser)
    add_robot_arguments(parser, detect=True)
    args = parser.parse_args(argv)
    try:
        args.limits = limits_of(args)
    except ValueError as exc:
        parser.error(str(exc))
    return args


LIMITS = (
    ("--max-speed", "linear", "m/s", "VOICECTL_MAX_SPEED"),
    ("--max-angular-speed", "angular", "rad/s", "VOICECTL_MAX_ANGULAR_SPEED"),
    ("--max-accel", "linear_accel", "m/s², speeding up", "VOICECTL_MAX_ACCEL"),
    ("--max-angular-accel", "angular_accel", "rad/s², speeding up", "VOICECTL_MAX_ANGULAR_ACCEL"),
)
"""The speed limits' flags, their `SpeedLimits` fields, units and environment variables."""


def add_limit_arguments(parser: argparse.ArgumentParser) -> None:
    """The speed limits' flags (the executor's, and `voicectl up`'s, which passes them on)."""
    group = parser.add_argument_group(
        "speed limits",
        "held to by every velocity the executor sends, whatever an order asks; Nav2's "
        "controller gets the top speed on its speed_limit topic before each goal. Each "
        "flag has an environment variable: VOICECTL_MAX_SPEED, ...; a flag wins over it",
    )
    for flag, limit, unit, variable in LIMITS:
        group.add_argument(
            flag,
            dest=f"limit_{limit}",
            type=positive_float,
            default=None,
            metavar=unit.split(",")[0],
            help=f"{unit} (default: ${variable}, else {getattr(SAFE_LIMITS, limit):g})",
        )


def limits_of(args: argparse.Namespace, environ: Mapping[str, str] = os.environ) -> SpeedLimits:
    """The limits the flags give, else their environment variables, else `SAFE_LIMITS`;
    ValueError naming the variable whose value is not a number above 0."""
    values: dict[str, float] = {}
    for _flag, limit, _unit, variable in LIMITS:
        given: float | None = getattr(args, f"limit_{limit}")
        text = environ.get(variable, "").strip()
        if given is None and text:
            try:
                given = positive_float(text)
            except argparse.ArgumentTypeError as exc:
                raise ValueError(f"{variable}: {exc}") from None
        values[limit] = given if given is not None else getattr(SAFE_LIMITS, limit)
    return SpeedLimits(**values)


def limit_flags(limits: SpeedLimits) -> list[str]:
    """`limits` as the executor's flags, for whoever starts one (`voicectl up`)."""
    return [
        part
        for flag, limit, _unit, _variable in LIMITS
        for part in (flag, repr(getattr(limits, limit)))
    ]
