"""The robot side of voicectl: one seam for every way of reaching a ROS 2 graph.

- `transport.py`: the seam (`RobotTransport`) and what it speaks of (ROS names and types,
  discovered `Interface`s, a layout's `Announcements`);
- `bridge.py`: zenoh-bridge-ros2dds; `rmw_zenoh.py`: ROS 2 nodes on rmw_zenoh, no bridge;
  `keys.py`: the keys and liveliness tokens of those layouts;
- `action.py`: a ROS 2 action client on the seam (send goal, feedback, status, get
  result, cancel), with which the executor runs Nav2's goals and the stop cancels them;
- `stop.py`: stopping a robot, written once on top of the seam, for the executor, the
  supervisor and the clients alike.

`TRANSPORTS` is the one registry of transports: each entry names a `RobotTransport` class,
which says how it is opened and how a robot announces itself in its layout.
`open_transport`, `detect_transport` and the stop go through the registry and name no
transport. A new transport is a module with its class, its member of `TransportKind`
(`kinds.py`: the name messages and `--transport` know it by; the flag's help in
`shared/robot_options.py` describes each in words) and one entry here; what the tests need
to play it is in docs/architecture.md ("Where to add").
"""

from __future__ import annotations

import functools
import importlib
import weakref
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..kinds import TransportKind
from .keys import ACTION_MEMBERS, RobotNames
from .transport import Interface, RobotTransport, Role

if TYPE_CHECKING:  # the messages import this package's kinds; the bus imports the messages
    from ..bus import Bus
    from ..ros2 import RosDistro

__all__ = [
    "TRANSPORTS",
    "Interface",
    "RobotTransport",
    "Role",
    "TransportKind",
    "detect_transport",
    "open_transport",
    "transports",
]

TRANSPORTS = (
    "bridge:BridgeTransport",
    "rmw_zenoh:RmwZenohTransport",
    "dds:Ros2Transport",
)
"""Every robot transport, as 'module:class' in this package, imported when first used
(a transport imports the bus, which imports the messages, which import this package).
In this order `detect_transport` listens to their layouts."""

_OPEN: weakref.WeakKeyDictionary[Bus, dict[tuple[object, ...], RobotTransport]] = (
    weakref.WeakKeyDictionary()
)


@functools.cache
def transports() -> dict[TransportKind, type[RobotTransport]]:
    """The classes of `TRANSPORTS` by their kind, in its order."""
    found: dict[TransportKind, type[RobotTransport]] = {}
    for entry in TRANSPORTS:
        module, name = entry.split(":")
        cls = getattr(importlib.import_module(f".{module}", __name__), name)
        if not (isinstance(cls, type) and issubclass(cls, RobotTransport)):
            raise TypeError(f"transport {entry!r} is not a RobotTransport")
        if cls.kind in found:
            raise TypeError(f"transport {entry!r} has kind {cls.kind!r} of another one")
        found[cls.kind] = cls
    return found


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
    opened = _OPEN.setdefault(bus, {})
    key = (kind, node, namespace, domain_id, distro)
    if key not in opened:
        opened[key] = transports()[kind].open(bus, node, namespace, domain_id, distro)
    return opened[key]


async def detect_transport(
    bus: Bus, names: RobotNames, domain_id: int, timeout: float
) -> TransportKind | None:
    """Which layout the robot's graph announces itself in: the first liveliness token, of
    any transport's layout, naming one of the robot's topics or its action. If none came
    within `timeout` seconds, the first transport whose graph is not on Zenoh that this
    process can reach (a ROS 2 environment: rclpy), else None."""
    import asyncio

    wanted = {names.cmd_vel, names.odom, names.topic(names.navigate_name)}
    wanted |= {names.navigate(member) for member in ACTION_MEMBERS}
    found: asyncio.Future[TransportKind] = asyncio.get_running_loop().create_future()
    own = str(bus.session.zid())
    announced = {kind: cls.announcements(domain_id, own) for kind, cls in transports().items()}
    layouts = {kind: layout for kind, layout in announced.items() if layout is not None}

    def watcher(kind: TransportKind) -> Callable[[str, bool], None]:
        name_of = layouts[kind].name_of

        def on_token(key: str, present: bool) -> None:
            if present and name_of(key) in wanted and not found.done():
                found.set_result(kind)

        return on_token

    stops = [bus.watch(layout.tokens, watcher(kind)) for kind, layout in layouts.items()]
    try:
        async with asyncio.timeout(timeout):
            return await found
    except TimeoutError:
        off_zenoh = (kind for kind, layout in announced.items() if layout is None)
        return next((kind for kind in off_zenoh if not transports()[kind].unavailable()), None)
    finally:
        for stop in stops:
            stop()
