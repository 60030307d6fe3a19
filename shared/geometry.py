"""Planar pose arithmetic shared by the simulator and the executor."""

from __future__ import annotations

import math

from .ros2 import Pose2D


def normalize_angle(angle: float) -> float:
    """The same angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def compose(base: Pose2D, relative: Pose2D) -> Pose2D:
    """`relative`, given in the frame of a robot standing at `base`, in the world frame."""
    cos, sin = math.cos(base.yaw), math.sin(base.yaw)
    return Pose2D(
        x=base.x + cos * relative.x - sin * relative.y,
        y=base.y + sin * relative.x + cos * relative.y,
        yaw=normalize_angle(base.yaw + relative.yaw),
    )
