"""The simulated robot's world as its map server would publish it: an occupancy grid.

Walls around the bounds and a few partitions, none across the straight lines between
the demo orders' places (base, kitchen, bathroom, dumpster), since the simulated
navigator drives straight: a map is for people to see where things are, and the robot
here does not plan around walls.
"""

from __future__ import annotations

import numpy as np

from voicectl.shared.ros2 import OccupancyGrid, Pose2D

from .robot import Bounds

RESOLUTION = 0.1
"""Metres per cell: a 20 m world is 200 x 200 cells."""
WALL = 0.15
"""Metres: half a wall's thickness."""
OCCUPIED, FREE = 100, 0
PARTITIONS = (
    ((-10.0, 7.5), (-2.0, 7.5)),
    ((-4.0, -10.0), (-4.0, -3.0)),
    ((3.0, -5.0), (10.0, -5.0)),
    ((8.0, 1.0), (8.0, 10.0)),
)
"""Inner walls, as segments (x, y) to (x, y) in metres."""


def floor_plan(bounds: Bounds) -> OccupancyGrid:
    """The map of the world inside `bounds`: its outer walls and the partitions in it."""
    width = round((bounds.xmax - bounds.xmin) / RESOLUTION)
    height = round((bounds.ymax - bounds.ymin) / RESOLUTION)
    xs = bounds.xmin + (np.arange(width) + 0.5) * RESOLUTION
    ys = bounds.ymin + (np.arange(height) + 0.5) * RESOLUTION
    x, y = np.meshgrid(xs, ys)  # row r is y = ys[r]: row 0 at the origin, as ROS has it
    occupied = (
        (x - bounds.xmin < 2 * WALL)
        | (bounds.xmax - x < 2 * WALL)
        | (y - bounds.ymin < 2 * WALL)
        | (bounds.ymax - y < 2 * WALL)
    )
    for (x0, y0), (x1, y1) in PARTITIONS:
        occupied |= _near_segment(x, y, x0, y0, x1, y1) < WALL
    cells = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    return OccupancyGrid(
        width=width,
        height=height,
        resolution=RESOLUTION,
        origin=Pose2D(bounds.xmin, bounds.ymin, 0.0),
        cells=cells.tobytes(),
    )


def _near_segment(
    x: np.ndarray, y: np.ndarray, x0: float, y0: float, x1: float, y1: float
) -> np.ndarray:
    """Distance of every point to the segment (x0, y0)-(x1, y1)."""
    dx, dy = x1 - x0, y1 - y0
    along = np.clip(((x - x0) * dx + (y - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
    distance: np.ndarray = np.hypot(x - (x0 + along * dx), y - (y0 + along * dy))
    return distance
