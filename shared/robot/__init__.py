"""The robot side of voicectl: one seam for every way of reaching a ROS 2 graph.

- `transport.py`: the seam (`RobotTransport`) and what it speaks of (ROS names and types,
  discovered `Interface`s);
- `bridge.py`: zenoh-bridge-ros2dds; `rmw_zenoh.py`: ROS 2 nodes on rmw_zenoh, no bridge;
- `action.py`: a ROS 2 action client on the seam (send goal, feedback, status, get
  result, cancel), with which the executor runs Nav2's goals and the stop cancels them;
- `stop.py`: stopping a robot, written once on top of the seam, for the executor, the
  supervisor and the clients alike.

`open_transport` is the one place that knows every transport: a new one is a module and a
case here.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

from .kinds import TransportKind
from .transport import Interface, RobotTransport, Role

if TYPE_CHECKING:  # the messages import this package's kinds; the bus imports the messages
    from ..bus import Bus
    from ..keys import RobotNames
    from ..ros2 import RosDistro

__all__ = [
    "Interface",
    "RobotTransport",
    "Role",
    "TransportKind",
    "open_transport",
]

_OPEN: weakref.WeakKeyDictionary[Bus, dict[tuple[object, ...], RobotTransport]] = (
    weakref.WeakKeyDictionary()
)


def open_transport(
    bus: Bus,
    kind: TransportKind,
    node: str,
    namespace: str = "",
    domain_id: int = 0,
    distro: RosDistro | None = None,
) -> RobotTransport:
    """The transport of `kind` on `bus`, this process appearing as ROS node `node` where
    the layout has nodes; the same one for the same arguments, so that repeated stops
    declare nothing twice."""
    from .bridge import BridgeTransport
    from .rmw_zenoh import RmwZenohTransport

    opened = _OPEN.setdefault(bus, {})
    key = (kind, node, namespace, domain_id, distro)
    if key not in opened:
        match kind:
            case TransportKind.BRIDGE:
                opened[key] = BridgeTransport(bus)
            case TransportKind.RMW_ZENOH:
                opened[key] = RmwZenohTransport(bus, node, namespace, domain_id, distro)
    return opened[key]


async def detect_transport(
    bus: Bus, names: RobotNames, domain_id: int, timeout: float
) -> TransportKind | None:
    """Which layout the robot's graph announces itself in: the first liveliness token,
    of zenoh-bridge-ros2dds or of rmw_zenoh, naming one of the robot's topics or its
    action; None if none came within `timeout` seconds."""
    import asyncio

    from ..keys import ACTION_MEMBERS, BRIDGE_TOKENS, BridgeToken, RmwZenohKeys

    wanted = {names.cmd_vel, names.odom, names.topic(names.navigate_name)}
    wanted |= {names.navigate(member) for member in ACTION_MEMBERS}
    found: asyncio.Future[TransportKind] = asyncio.get_running_loop().create_future()
    rmw = RmwZenohKeys(domain_id)
    own = str(bus.session.zid())

    def decide(kind: TransportKind) -> None:
        if not found.done():
            found.set_result(kind)

    def on_bridge(key: str, present: bool) -> None:
        token = BridgeToken.parse(key)
        if present and token is not None and token.key in wanted:
            decide(TransportKind.BRIDGE)

    def on_rmw(key: str, present: bool) -> None:
        token = rmw.parse_token(key)
        if present and token is not None and token.zid != own and token.name in wanted:
            decide(TransportKind.RMW_ZENOH)

    stops = [bus.watch(BRIDGE_TOKENS, on_bridge), bus.watch(rmw.tokens, on_rmw)]
    try:
        async with asyncio.timeout(timeout):
            return await found
    except TimeoutError:
        return None
    finally:
        for stop in stops:
            stop()
