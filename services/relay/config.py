"""The relay's command line: the bus, and the robot's names and domain on DDS."""

from __future__ import annotations

import argparse

from voicectl.shared.process import add_bus_arguments
from voicectl.shared.robot_options import add_robot_arguments


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="voicectl relay", description="The STOP relay of a robot on DDS, beside its executor."
    )
    add_bus_arguments(parser)
    add_robot_arguments(parser, detect=False, transport=False)
    return parser.parse_args(argv)
