"""An executor made from its config: the bindings loaded, the robot reached, the relays
for the panels, the service. `__main__` runs one; bench/robots.py hosts several."""

from __future__ import annotations

import logging

from voicectl.shared.bus import Bus
from voicectl.shared.keys import RobotKeys
from voicectl.shared.robot import TransportKind, detect_transport, open_transport

from .builtin import builtin_executors
from .config import ExecutorConfig
from .framework import Bindings, load_binding, load_bindings_file
from .photos import PhotoShelf
from .relays import MapRelay, PoseRelay
from .robot import RobotLink
from .runner import ExecutorService

_LOGGER = logging.getLogger(__name__)

NODE = "voicectl_executor"
"""The ROS node the executor appears as on the robot, where nodes are seen (rmw_zenoh)."""
DETECT_WAIT = 3.0
"""Seconds `--transport auto` waits for the robot's graph to announce itself."""


def load_bindings(config: ExecutorConfig) -> Bindings:
    """The built-in executors and those `config` binds; BindingError when one cannot be
    loaded. Before the bus opens: a mistake is told at once, router or not."""
    bindings = Bindings()
    for executor in builtin_executors(config.photos):
        bindings.bind(executor, executor.labels)
    for path in config.binding_files:
        for executor, labels in load_bindings_file(path):
            bindings.bind(executor, labels)
    for spec in config.bindings:
        bindings.bind(*load_binding(spec))
    return bindings


def build(
    bus: Bus, config: ExecutorConfig, bindings: Bindings, transport: TransportKind
) -> ExecutorService:
    """The executor `config` describes, on `bus`, reaching its robot by `transport`, not
    started."""
    reach = config.reach
    keys = RobotKeys(config.robot)
    robot = RobotLink(
        open_transport(bus, transport, NODE, reach.names.namespace, reach.domain_id, reach.distro),
        reach,
        on_change=lambda: service.publish_info(),
        result_grace=config.result_grace,
        limits=config.limits,
    )
    PhotoShelf(config.photos).serve(bus, keys)
    PoseRelay(bus, keys.pose, robot)
    MapRelay(bus, keys.map, robot)
    service = ExecutorService(
        bus,
        keys,
        robot,
        bindings,
        cancel_deadline=config.cancel_deadline,
        stall_limit=config.stall_limit,
    )
    return service


async def choose_transport(bus: Bus, config: ExecutorConfig) -> TransportKind:
    """The transport the config names, or with `auto` the one the robot's graph
    announces itself in; when it announces nothing on Zenoh, a plain ROS 2 node where
    rclpy can be imported, else the bridge."""
    reach = config.reach
    if reach.transport is not None:
        return reach.transport
    found = await detect_transport(bus, reach.names, reach.domain_id, DETECT_WAIT)
    if found is None:
        _LOGGER.warning(
            "the robot announced nothing in %g s and rclpy cannot be imported here; reaching "
            "it through the bridge (see --transport)",
            DETECT_WAIT,
        )
        return TransportKind.BRIDGE
    _LOGGER.info("the robot's graph speaks %s", found)  # ros2: none answered on Zenoh
    return found
