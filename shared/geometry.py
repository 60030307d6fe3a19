"""Planar pose arithmetic shared by the simulator and the executor."""

from __future__ import annotations

import math

from .ros2 import OccupancyGrid, Pose2D


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


def map_cell(grid: OccupancyGrid, x: float, y: float) -> int | None:
    """The occupancy of the cell of `grid` at (x, y) in the grid's frame: -1 unknown, 0 free
    to 100 occupied; None outside the grid."""
    cos, sin = math.cos(grid.origin.yaw), math.sin(grid.origin.yaw)
    dx, dy = x - grid.origin.x, y - grid.origin.y
    column = math.floor((cos * dx + sin * dy) / grid.resolution)
    row = math.floor((-sin * dx + cos * dy) / grid.resolution)
    if not (0 <= column < grid.width and 0 <= row < grid.height):
        return None
    cell = grid.cells[row * grid.width + column]
    return cell - 256 if cell > 127 else cell  # int8
