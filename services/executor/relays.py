"""What the executor relays from the robot for voicectl's panels: its pose and its map."""

from __future__ import annotations

import asyncio
import base64
import io
import logging
import uuid
from collections.abc import Callable

import numpy as np
from PIL import Image as PilImage

from voicectl.shared.bus import Bus
from voicectl.shared.messages import RobotMap, RobotPose, TargetPose
from voicectl.shared.ros2 import (
    OccupancyGrid,
    Pose2D,
)

from .robot import OCCUPANCY_GRID, RobotLink

_LOGGER = logging.getLogger(__name__)

POSE_EVERY = 0.5
"""Seconds between two poses published for panels."""
MAP_EVERY = 2.0
"""Seconds between two maps relayed for panels (a SLAM map changes about once a second)."""


class PoseRelay:
    """The robot's pose for voicectl's panels (`voice/<robot>/robot/pose`), from the
    link's odometry, at most every `POSE_EVERY` seconds: the panel's, not the robot's."""

    def __init__(self, bus: Bus, key: str, link: RobotLink) -> None:
        self._bus = bus
        self._key = key
        self._sent = -POSE_EVERY
        self._run = uuid.uuid4().hex[:8]
        link.on_pose(self._on_pose)

    def _on_pose(self, pose: Pose2D) -> None:
        now = asyncio.get_running_loop().time()
        if now - self._sent >= POSE_EVERY:
            self._sent = now
            self._bus.publish(
                self._key,
                RobotPose(x=pose.x, y=pose.y, yaw=pose.yaw, run=self._run),
                superseded=True,
            )


class MapRelay:
    """The robot's own map for voicectl's panels (`voice/<robot>/robot/map`): its occupancy
    grid, subscribed on the robot only while someone listens to the relay (a map crosses
    the robot's link only for a panel that shows it), at most every `MAP_EVERY` seconds,
    as a PNG, kept for panels that open later."""

    def __init__(self, bus: Bus, key: str, link: RobotLink) -> None:
        self._link = link
        self._latest = bus.latest(key)
        self._unsubscribe: Callable[[], None] | None = None
        self._sent = -MAP_EVERY
        self._encoding: asyncio.Task[None] | None = None
        bus.watch_heard(key, self._on_heard)

    def _on_heard(self, heard: bool) -> None:
        if heard and self._unsubscribe is None:
            link = self._link
            self._unsubscribe = link.transport.subscribe(
                link.names.map,
                OCCUPANCY_GRID,
                link.codec.read_occupancy_grid,
                self._on_map,
                latched=True,
            )
        elif not heard and self._unsubscribe is not None:
            self._unsubscribe()
            self._unsubscribe = None

    def _on_map(self, grid: OccupancyGrid) -> None:
        loop = asyncio.get_running_loop()
        busy = self._encoding is not None and not self._encoding.done()
        if busy or loop.time() - self._sent < MAP_EVERY:
            return
        self._sent = loop.time()
        self._encoding = loop.create_task(self._relay(grid))

    async def _relay(self, grid: OccupancyGrid) -> None:
        png = await asyncio.to_thread(map_png, grid)  # a large map takes a while
        try:
            origin = TargetPose(
                frame=grid.frame, x=grid.origin.x, y=grid.origin.y, yaw=grid.origin.yaw
            )
        except ValueError as exc:  # a robot's map whose origin is not finite numbers
            _LOGGER.warning("the robot's map is not relayed: its origin is unusable: %s", exc)
            return
        self._latest.publish(
            RobotMap(
                width=grid.width,
                height=grid.height,
                resolution=grid.resolution,
                origin=origin,
                png=base64.b64encode(png).decode(),
            )
        )


def map_png(grid: OccupancyGrid) -> bytes:
    """An occupancy grid as an 8-bit grey PNG in map_server's colours: occupied black (0),
    free white (254), unknown grey (205), and shades between; row 0 first."""
    cells = np.frombuffer(grid.cells, dtype=np.int8).astype(np.int16)
    grey = np.where(cells < 0, 205, 254 - np.clip(cells, 0, 100) * 254 // 100).astype(np.uint8)
    image = PilImage.fromarray(grey.reshape(grid.height, grid.width), mode="L")
    encoded = io.BytesIO()
    image.save(encoded, format="PNG", optimize=True)
    return encoded.getvalue()
