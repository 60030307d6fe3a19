"""A ROS 2 graph whose nodes speak rmw_zenoh: voicectl as one more node, with no bridge.

What rmw_zenoh puts on the wire, as read in ros2/rmw_zenoh's docs/design.md and its
rmw_zenoh_cpp sources as released for Humble (0.1.9), Jazzy (0.2.10) and Kilted (0.6.7):

- Keys ``<domain>/<name>/<DDS type>/<type hash>`` (`RmwZenohKeys`). What voicectl
  publishes goes to the exact key the robot's side announced (its token carries its type
  hash), as this transport has seen it since it was opened or as the executor saw it
  (`expect`), or, before either is known, to the key of the type hash this distribution
  computes (`shared.ros2.type_hash`). A service call asks that exact key too, as rmw_zenoh's
  clients do (complete queryables only, one reply per key). What it hears, it hears
  whatever the hash.
- An attachment on every publication, query and reply, in zenoh's own serialization:
  int64 sequence number (per publisher or client, from 1), int64 source timestamp in
  nanoseconds since the epoch, then the 16-byte source GID as a sequence (a 0x10 length
  byte first): 33 bytes. Subscribers drop samples without one. A service's reply carries
  the request's sequence number and the client's GID, with a timestamp of its own.
- GIDs: XXH3-128 of the entity's liveliness token, low half first, little-endian.
- Services are queryables declared complete (rmw_zenoh's clients ask only those); an action
  is its three services and two topics under ``<action>/_action/``.
- A transient local publication (an action's status) is Zenoh's advanced publisher with a
  cache of its depth: a late subscriber asking for history gets the last status.
- A liveliness token per node and per publisher, subscription, client and server
  (``@ros2_lv/...``), from which `ros2 node list` and `ros2 topic info` on the robot show
  voicectl, and from which voicectl learns what the robot offers, with which types and
  hashes. A ROS client sees a service only once a server's token is there.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import struct
import threading
import time
import weakref
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import Self, TypeVar

import xxhash

from ..bus import Bus
from ..kinds import CmdVelType, TransportKind
from ..ros2 import (
    NO_TYPE_HASH,
    RosDistro,
    dds_type_name,
    distro_from_hash,
    ros_type_of,
    type_hash,
)
from ..wire import Kept
from .keys import (
    RMW_QOS_DEFAULT,
    RMW_QOS_LATCHED,
    RmwKind,
    RmwToken,
    RmwZenohKeys,
)
from .transport import (
    Announcements,
    Decode,
    Handle,
    Interface,
    RobotTransport,
    Role,
    Unsubscribe,
    action_members,
    action_of,
)

_LOGGER = logging.getLogger(__name__)

T = TypeVar("T")

GID_SIZE = 16
_ATTACHMENT = struct.Struct(f"<qqB{GID_SIZE}s")


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh sends beside every payload."""

    sequence: int
    timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        return _ATTACHMENT.pack(self.sequence, self.timestamp_ns, GID_SIZE, self.gid)

    @staticmethod
    def decode(raw: bytes) -> Attachment:
        """ValueError for bytes of another layout (rmw_zenoh before Jazzy 0.2.4 and Humble
        0.1.2 wrote a key before each field, and is not spoken here)."""
        if len(raw) != _ATTACHMENT.size:
            raise ValueError(f"an rmw_zenoh attachment is {_ATTACHMENT.size} bytes, not {len(raw)}")
        sequence, timestamp, size, gid = _ATTACHMENT.unpack(raw)
        if size != GID_SIZE:
            raise ValueError(f"GID of {size} bytes in an rmw_zenoh attachment, not {GID_SIZE}")
        return Attachment(sequence, timestamp, gid)


def gid_of(token_key: str) -> bytes:
    """An entity's GID as rmw_zenoh derives it from its liveliness token."""
    return xxhash.xxh3_128(token_key.encode()).intdigest().to_bytes(GID_SIZE, "little")


class _Entity:
    """One publisher, subscription, client or server of this process: its token, its GID
    and its sequence numbers."""

    def __init__(self, token_key: str) -> None:
        self.token_key = token_key
        self.gid = gid_of(token_key)
        self._sequence = itertools.count(1)  # next() is atomic: any thread may send

    def attachment(self) -> bytes:
        return Attachment(next(self._sequence), time.time_ns(), self.gid).encode()


_IDS: weakref.WeakKeyDictionary[Bus, itertools.count[int]] = weakref.WeakKeyDictionary()
"""Node and entity ids, one counter per Zenoh session as rmw_zenoh keeps one per context:
the graph tells nodes apart by (session, node id)."""

_KINDS = {
    RmwKind.PUBLISHER: Role.PUBLISHER,
    RmwKind.SUBSCRIBER: Role.SUBSCRIBER,
    RmwKind.SERVICE_SERVER: Role.SERVICE_SERVER,
    RmwKind.SERVICE_CLIENT: Role.SERVICE_CLIENT,
}


class RmwZenohTransport(RobotTransport):
    """This process as one rmw_zenoh node, `node` in the robot's `namespace`."""

    kind = TransportKind.RMW_ZENOH

    def __init__(
        self,
        bus: Bus,
        node: str,
        namespace: str = "",
        domain_id: int = 0,
        distro: RosDistro | None = None,
    ) -> None:
        self._bus = bus
        self.keys = RmwZenohKeys(domain_id)
        self._node = node
        self._namespace = namespace
        self.distro = distro
        """The robot's distribution as configured, or as its tokens' hashes say; None until
        known (Jazzy's hashes are sent meanwhile)."""
        self._configured = distro is not None
        self._learnt: RosDistro | None = None
        """The distribution the robot's tokens name, configured or not."""
        self._zid = str(bus.session.zid())
        self._ids = _IDS.setdefault(bus, itertools.count())
        self._node_id = next(self._ids)
        self._entities: dict[tuple[RmwKind, str, str], _Entity] = {}
        self._lock = threading.Lock()
        self._announced: dict[tuple[str, str], str] = {}
        """(name, DDS type) -> the type hash the robot's side announced for it."""
        self._expected: dict[tuple[str, str], str] = {}
        """The same as another process saw it (`expect`): until this one has seen it."""
        self._subscribed: dict[str, list[str]] = {}
        """Topic name -> the ROS types the robot's subscribers of it announced."""
        node_token = RmwToken(
            self._zid, self._node_id, self._node_id, RmwKind.NODE, namespace, node
        )
        bus.announce(self.keys.token(node_token))
        self._following = False
        """The robot's tokens are watched (`follow`, `discover`): what they say is learnt."""
        self._kept: dict[str, Kept] = {}
        """Transient local publications, by key: their publishers keep the last sample."""

    @classmethod
    def open(
        cls, bus: Bus, node: str, namespace: str, domain_id: int, distro: RosDistro | None
    ) -> Self:
        return cls(bus, node, namespace, domain_id, distro)

    @classmethod
    def announcements(cls, domain_id: int, own: str) -> Announcements:
        keys = RmwZenohKeys(domain_id)

        def name_of(key: str) -> str | None:
            token = keys.parse_token(key)
            if token is None or token.zid == own or not token.name:  # not the robot's, a node
                return None
            return token.name

        return Announcements(keys.tokens, name_of)

    @classmethod
    def prepare(cls, distro: RosDistro, ros_types: Iterable[str]) -> None:
        for ros_type in ros_types:
            type_hash(distro, ros_type)

    # --- keys and entities --------------------------------------------------------------

    def _hash(self, name: str, ros_type: str) -> str:
        key = (name, dds_type_name(ros_type))
        announced = self._announced.get(key) or self._expected.get(key)
        return announced or type_hash(self.distro or RosDistro.JAZZY, ros_type)

    def _exact(self, name: str, ros_type: str) -> str:
        return self.keys.data(name, dds_type_name(ros_type), self._hash(name, ros_type))

    def _any_hash(self, name: str, ros_type: str) -> str:
        return self.keys.data_any_hash(name, dds_type_name(ros_type))

    def entity(self, kind: RmwKind, name: str, ros_type: str) -> _Entity:
        """This process's entity of that kind on that name, its token declared on first use."""
        with self._lock:
            known = self._entities.get((kind, name, ros_type))
            if known is not None:
                return known
            qos = RMW_QOS_LATCHED if _latched(name) else RMW_QOS_DEFAULT
            token = RmwToken(
                self._zid,
                self._node_id,
                next(self._ids),
                kind,
                self._namespace,
                self._node,
                name,
                dds_type_name(ros_type),
                self._hash(name, ros_type),
                qos,
            )
            entity = self._entities[(kind, name, ros_type)] = _Entity(self.keys.token(token))
        self._bus.announce(entity.token_key)
        _LOGGER.debug("rmw_zenoh entity %s", entity.token_key)
        return entity

    # --- the seam -----------------------------------------------------------------------

    def send(self, name: str, ros_type: str, payload: bytes, urgent: bool = False) -> None:
        entity = self.entity(RmwKind.PUBLISHER, name, ros_type)
        key = self._exact(name, ros_type)
        if _latched(name):
            with self._lock:
                kept = self._kept.get(key)
                if kept is None:
                    kept = self._kept[key] = self._bus.keeping(key, depth=1)
            kept.put(payload, attachment=entity.attachment())
            return
        self._bus.publish_bytes(key, payload, urgent=urgent, attachment=entity.attachment())

    def subscribe(
        self, name: str, ros_type: str, decode: Decode[T], handler: Handle[T], latched: bool = False
    ) -> Unsubscribe:
        # A transient local publisher of rmw_zenoh is Zenoh's advanced publisher with a
        # cache: a subscriber with history gets what it keeps.
        self.entity(RmwKind.SUBSCRIBER, name, ros_type)
        key = self._any_hash(name, ros_type)
        return self._bus.subscribe(
            key, decode, lambda _key, message: handler(message), history=latched
        )

    async def call(
        self, name: str, service_type: str, request: bytes, timeout: float, urgent: bool = False
    ) -> bytes:
        entity = self.entity(RmwKind.SERVICE_CLIENT, name, service_type)
        return await self._bus.request_bytes(
            self._exact(name, service_type),
            request,
            timeout,
            urgent=urgent,
            attachment=entity.attachment(),
            complete=True,
        )

    def call_and_forget(self, name: str, service_type: str, request: bytes, timeout: float) -> None:
        entity = self.entity(RmwKind.SERVICE_CLIENT, name, service_type)
        self._bus.query_and_forget(
            self._exact(name, service_type),
            request,
            timeout,
            attachment=entity.attachment(),
            complete=True,
        )

    def serve(
        self, name: str, service_type: str, handler: Callable[[bytes], Awaitable[bytes | None]]
    ) -> None:
        self.entity(RmwKind.SERVICE_SERVER, name, service_type)
        self._bus.serve_bytes(
            self._exact(name, service_type), handler, complete=True, reply_attachment=_reply_to
        )

    def offer(self, interface: Interface) -> None:
        match interface.role:
            case Role.PUBLISHER:
                self.entity(RmwKind.PUBLISHER, interface.name, interface.ros_type)
            case Role.SUBSCRIBER:
                self.entity(RmwKind.SUBSCRIBER, interface.name, interface.ros_type)
            case Role.SERVICE_SERVER:
                self.entity(RmwKind.SERVICE_SERVER, interface.name, interface.ros_type)
            case Role.SERVICE_CLIENT:
                self.entity(RmwKind.SERVICE_CLIENT, interface.name, interface.ros_type)
            case Role.ACTION_SERVER | Role.ACTION_CLIENT:
                server = interface.role is Role.ACTION_SERVER
                for member in action_members(interface.name, interface.ros_type):
                    kind = (
                        (RmwKind.SERVICE_SERVER if server else RmwKind.SERVICE_CLIENT)
                        if member.service
                        else (RmwKind.PUBLISHER if server else RmwKind.SUBSCRIBER)
                    )
                    self.entity(kind, member.name, member.ros_type)

    def expect(self, interface: Interface) -> None:
        if interface.type_hash and interface.role in (Role.SUBSCRIBER, Role.SERVICE_SERVER):
            self._expected[(interface.name, dds_type_name(interface.ros_type))] = (
                interface.type_hash
            )

    def subscriber_types(self, name: str) -> list[str]:
        return list(self._subscribed.get(name, ()))

    def follow(self) -> None:
        if self._start_following():
            self._bus.watch(self.keys.tokens, self._on_token)

    def _start_following(self) -> bool:
        with self._lock:
            started, self._following = not self._following, True
        return started

    def discover(self, handler: Callable[[Interface, bool], None]) -> None:
        self._start_following()  # this watch learns as well: `follow` need not add one

        def on_token(key: str, present: bool) -> None:
            token = self._robot_token(key)
            if token is None:
                return
            try:
                ros_type = ros_type_of(token.dds_type)
            except ValueError:
                return
            if present:  # learnt before the handler hears of it, whichever watch came first
                self._learn(token)
            role = _KINDS[token.kind]
            handler(Interface(role, token.name, ros_type, token.type_hash), present)
            action = action_of(token.name, ros_type)
            if action is not None and role in (Role.SERVICE_SERVER, Role.SERVICE_CLIENT):
                whole = Role.ACTION_SERVER if role is Role.SERVICE_SERVER else Role.ACTION_CLIENT
                handler(Interface(whole, action[0], action[1], token.type_hash), present)

        self._bus.watch(self.keys.tokens, on_token)

    def _robot_token(self, key: str) -> RmwToken | None:
        """The entity a token announces, unless it is a node or this process's own."""
        token = self.keys.parse_token(key)
        if token is None or token.zid == self._zid or token.kind is RmwKind.NODE:
            return None
        return token

    def _on_token(self, key: str, present: bool) -> None:
        token = self._robot_token(key)
        if token is not None and present:
            self._learn(token)

    def _learn(self, token: RmwToken) -> None:
        """Note the robot's type hash for a name, the types its subscribers take, and its
        distribution from the hash. Kept when the token goes: a robot restarting comes
        back on the same key, and a stop meanwhile goes to the best key known."""
        if token.kind in (RmwKind.SUBSCRIBER, RmwKind.SERVICE_SERVER):
            self._announced[(token.name, token.dds_type)] = token.type_hash
        if token.kind is RmwKind.SUBSCRIBER:
            with contextlib.suppress(ValueError):  # a type name voicectl cannot read
                ros_type = ros_type_of(token.dds_type)
                types = self._subscribed.setdefault(token.name, [])
                if ros_type not in types:
                    types.append(ros_type)
        with contextlib.suppress(ValueError):  # a type name voicectl cannot read
            ros_type = ros_type_of(token.dds_type)
            # What the robot serves and publishes; not what voicectl's own processes ask,
            # hear or drive with (their hashes are their guesses).
            robot_side = token.kind is RmwKind.SERVICE_SERVER or (
                token.kind is RmwKind.PUBLISHER and CmdVelType.of(ros_type) is None
            )
            if robot_side:
                self._learn_distro(ros_type, token.type_hash)

    def _learn_distro(self, ros_type: str, announced: str) -> None:
        """The distribution a hash names, if it names one alone (Nav2's feedback tells
        Rolling from Jazzy; a Twist, the same in both, says only 'Jazzy or later')."""
        found = distro_from_hash(ros_type, announced)
        learnt = self._learnt
        if found is None:
            if learnt is None and announced != NO_TYPE_HASH:
                learnt = RosDistro.JAZZY  # a hash: Jazzy or later, until one tells
        elif not (learnt is RosDistro.ROLLING and found is RosDistro.JAZZY):
            learnt = found  # (a Jazzy hash of a type Rolling did not change says nothing)
        if learnt is None or learnt is self._learnt:
            return
        self._learnt = learnt
        _LOGGER.info("the robot's rmw_zenoh speaks ROS 2 %s (from its tokens)", learnt.title())
        if not self._configured:
            self.distro = learnt

    def announced_distro(self) -> RosDistro | None:
        return self._learnt


def _latched(name: str) -> bool:
    """Whether topic `name` is transient local: an action's status, as rcl_action makes it."""
    return name.endswith("/_action/status")


def _reply_to(asked: bytes | None) -> bytes:
    """A reply's attachment: the request's sequence number and client GID, a new time."""
    try:
        request = Attachment.decode(asked or b"")
    except ValueError:
        request = Attachment(0, 0, bytes(GID_SIZE))
    return Attachment(request.sequence, time.time_ns(), request.gid).encode()
