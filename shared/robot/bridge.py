"""A ROS 2 graph behind zenoh-bridge-ros2dds: a ROS name is its key, a payload is all.

The bridge routes an interface only once it has discovered it on the DDS side, and
announces each one with a liveliness token naming its ROS type (``@/<zid>/@ros2_lv/...``,
`BridgeToken`). Services answer Zenoh queries on their name; an action is its services
and topics under ``<action>/_action/``. Details of what a stock robot needs behind the
bridge are in docs/deploy.md.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterable
from typing import Self, TypeVar

from ..bus import Bus
from ..kinds import RosDistro, TransportKind
from .keys import BRIDGE_TOKENS, BridgeKind, BridgeToken
from .transport import (
    Announcements,
    Decode,
    Handle,
    Interface,
    RobotTransport,
    Role,
    Unsubscribe,
)

T = TypeVar("T")

_KINDS = {
    Role.PUBLISHER: BridgeKind.PUBLISHER,
    Role.SUBSCRIBER: BridgeKind.SUBSCRIBER,
    Role.SERVICE_SERVER: BridgeKind.SERVICE_SERVER,
    Role.SERVICE_CLIENT: BridgeKind.SERVICE_CLIENT,
    Role.ACTION_SERVER: BridgeKind.ACTION_SERVER,
    Role.ACTION_CLIENT: BridgeKind.ACTION_CLIENT,
}
_ROLES = {kind: role for role, kind in _KINDS.items()}


class BridgeTransport(RobotTransport):
    kind = TransportKind.BRIDGE

    def __init__(self, bus: Bus) -> None:
        self._bus = bus

    @classmethod
    def open(
        cls, bus: Bus, node: str, namespace: str, domain_id: int, distro: RosDistro | None
    ) -> Self:
        # The bridge is the node, the DDS domain its own setting, and a key a ROS name.
        return cls(bus)

    @classmethod
    def announcements(cls, domain_id: int, own: str) -> Announcements:
        def name_of(key: str) -> str | None:
            token = BridgeToken.parse(key)
            return None if token is None else token.key

        return Announcements(BRIDGE_TOKENS, name_of)

    def send(self, name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
        self._bus.publish_bytes(name, payload, urgent=urgent)

    def subscribe(
        self, name: str, ros_type: str, decode: Decode[T], handler: Handle[T], latched: bool = False
    ) -> Unsubscribe:
        return self._bus.subscribe(
            name, decode, lambda _key, message: handler(message), history=latched
        )

    async def call(
        self, name: str, service_type: str, request: bytes, timeout: float, urgent: bool = False
    ) -> bytes:
        return await self._bus.request_bytes(name, request, timeout, urgent=urgent)

    def call_and_forget(self, name: str, service_type: str, request: bytes, timeout: float) -> None:
        self._bus.query_and_forget(name, request, timeout)

    def serve(
        self, name: str, service_type: str, handler: Callable[[bytes], Awaitable[bytes | None]]
    ) -> None:
        self._bus.serve_bytes(name, handler)

    def offer(self, interface: Interface) -> None:
        token = BridgeToken(_KINDS[interface.role], interface.name, interface.ros_type)
        self._bus.announce(token.token_key(str(self._bus.session.zid())))

    def discover(self, handler: Callable[[Interface, bool], None]) -> None:
        def on_token(key: str, present: bool) -> None:
            token = BridgeToken.parse(key)
            if token is not None:
                handler(Interface(_ROLES[token.kind], token.key, token.ros_type), present)

        self._bus.watch(BRIDGE_TOKENS, on_token)

    # --- without the event loop: the STOP relay's side (services/relay) ------------------

    def subscribe_now(self, name: str, decode: Decode[T], handler: Handle[T]) -> Unsubscribe:
        """Like `subscribe`, but `handler(message)` runs on Zenoh's own thread, at once,
        whatever the loop is doing: it must be quick and thread-safe."""
        return self._bus.subscribe(
            name, decode, lambda _key, message: handler(message), on_loop=False
        )

    def serve_now(
        self, name: str, handler: Callable[[bytes, Callable[[bytes | None], None]], None]
    ) -> None:
        """Answer a service's CDR requests on Zenoh's own thread: `handler(request,
        reply)` hands it on at once and `reply` is called once, from any thread, with the
        answer (None: none)."""
        self._bus.serve_bytes_now(name, handler)

    # A key is a ROS name here, whatever the robot announces: nothing to learn or build for
    # it, and a topic's types share its key, so a stop sends in one type only.

    @classmethod
    def prepare(cls, distro: RosDistro, ros_types: Iterable[str]) -> None:
        pass

    def follow(self) -> None:
        pass

    def expect(self, interface: Interface) -> None:
        pass

    def subscriber_types(self, name: str) -> list[str]:
        return []
