"""A simulated robot made from its config, on a bus: `__main__` runs one, bench/robots.py
hosts several."""

from __future__ import annotations

from voicectl.shared.bus import Bus
from voicectl.shared.robot import open_transport
from voicectl.shared.ros2 import Ros2Codec

from .node import SimConfig, SimNode

NODE = "voicectl_sim"
"""The ROS node the simulated robot appears as, where nodes are seen (rmw_zenoh)."""


def build(bus: Bus, config: SimConfig) -> SimNode:
    """The simulated robot `config` describes, on `bus`, not started."""
    names = config.names
    transport = open_transport(
        bus, config.transport, NODE, names.namespace, config.domain_id, config.distro
    )
    return SimNode(
        transport, Ros2Codec(config.distro), config, ready=lambda: bus.announce(names.simulator)
    )
