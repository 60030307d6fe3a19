"""The ROS names of a robot's topics and action, and the keys and liveliness tokens each
Zenoh layout makes of them: built here and nowhere else, as voicectl's own keys are in
shared/keys.py.

zenoh-bridge-ros2dds uses a topic's ROS name as its key, as it is (`RobotNames`);
rmw_zenoh puts the name inside ``<domain>/<name>/<type>/<hash>`` (`RmwZenohKeys`). Each
announces the interfaces of the graph with liveliness tokens of its own shape
(`BridgeToken`, `RmwToken`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum

from ..keys import ANY

ACTION_MEMBERS = ("send_goal", "cancel_goal", "get_result", "feedback", "status")
"""The services and topics ROS 2 makes of every action, under ``<action>/_action/``."""


def action_member(action: str, member: str) -> str:
    """The name of one of an action's services or topics ('navigate_to_pose/_action/status')."""
    if member not in ACTION_MEMBERS:
        raise ValueError(f"unknown action member {member!r}")
    return f"{action.strip('/')}/_action/{member}"


_ROS_TOKEN = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def check_ros_name(name: str, what: str) -> str:
    """`name` without its leading '/', if ROS 2 accepts it as a topic, action or namespace
    ('bot1', 'diff_drive_controller/cmd_vel'); else ValueError naming `what`."""
    parts = name.strip("/").split("/") if name.strip("/") else []
    for part in parts:
        if not _ROS_TOKEN.match(part) or "__" in part:
            raise ValueError(
                f"{what} {name!r}: {part!r} is not a ROS 2 name; use letters, digits and "
                "single '_', not starting with a digit ('-' and '.' are not allowed)"
            )
    return "/".join(parts)


@dataclass(frozen=True)
class RobotNames:
    """The ROS names of one robot's topics and action, under its `namespace`, fully
    qualified without the leading '/' ('bot1/cmd_vel'): what zenoh-bridge-ros2dds uses as
    keys as they are, and rmw_zenoh inside its keys.

    The names can be remapped ('diff_drive_controller/cmd_vel'): ROS name ``/a/b`` under
    namespace ``/ns`` is ``ns/a/b``.
    """

    namespace: str = ""
    cmd_vel_name: str = "cmd_vel"
    odom_name: str = "odom"
    camera_name: str = "camera/image_raw"
    navigate_name: str = "navigate_to_pose"
    """Nav2's NavigateToPose action."""
    map_name: str = "map"
    """The occupancy grid a Nav2 robot's map server publishes."""
    speed_limit_name: str = "speed_limit"
    """Where Nav2's controller server takes a speed limit (its `speed_limit_topic`)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "namespace", check_ros_name(self.namespace, "ROS namespace"))
        names = ("cmd_vel_name", "odom_name", "camera_name", "navigate_name", "map_name")
        for field in (*names, "speed_limit_name"):
            name = check_ros_name(getattr(self, field), field.removesuffix("_name") + " name")
            if not name:
                raise ValueError(f"{field.removesuffix('_name')} name must not be empty")
            object.__setattr__(self, field, name)

    def topic(self, name: str) -> str:
        """The full name of a topic, service or action member `name` ('/cmd_vel' or 'cmd_vel')."""
        name = name.strip("/")
        return f"{self.namespace}/{name}" if self.namespace else name

    @property
    def cmd_vel(self) -> str:
        return self.topic(self.cmd_vel_name)

    @property
    def odom(self) -> str:
        return self.topic(self.odom_name)

    @property
    def tf(self) -> str:
        return self.topic("tf")

    @property
    def camera_image(self) -> str:
        return self.topic(self.camera_name)

    @property
    def map(self) -> str:
        return self.topic(self.map_name)

    @property
    def speed_limit(self) -> str:
        return self.topic(self.speed_limit_name)

    @property
    def any_speed_limit(self) -> str:
        """Any speed limit topic under the namespace, remapped or not."""
        return self.topic("**/speed_limit")

    @property
    def simulator(self) -> str:
        """Liveliness token of `voicectl sim` once it serves this namespace (the real
        bridge announces itself under ``@/<zid>/@ros2_lv/...`` instead)."""
        return self.topic("voicectl_sim/alive")

    def action(self, action: str, member: str) -> str:
        """One of an action's five routes: send_goal, get_result, cancel_goal, feedback, status."""
        return self.topic(action_member(action, member))

    def navigate(self, member: str) -> str:
        """A route of the robot's NavigateToPose action."""
        return self.action(self.navigate_name, member)

    @property
    def everything(self) -> str:
        """Every key under the namespace (every key at all for a robot without one)."""
        return self.topic("**")

    @property
    def any_cmd_vel(self) -> str:
        """Any velocity topic under the namespace, remapped or not."""
        return self.topic("**/cmd_vel")

    @property
    def any_action(self) -> str:
        """Any action's send_goal, get_result or cancel_goal under the namespace."""
        return self.topic("**/_action/*")


# --- what zenoh-bridge-ros2dds announces ------------------------------------------------------
# The bridge holds a liveliness token per ROS interface it discovered:
# ``@/<zid>/@ros2_lv/<kind>/<key>/<type>[/<qos>]``, '/' inside key and type written '§'.

BRIDGE_TOKENS = "@/*/@ros2_lv/**"
_BRIDGE_SLASH = "§"


def bridge_tokens(namespace: str) -> tuple[str, ...]:
    """The tokens a bridge running in `namespace` holds: its own, and those of the
    interfaces under its namespace (every token, for a bridge without a namespace)."""
    if not namespace:
        return (BRIDGE_TOKENS,)
    escaped = namespace.strip("/").replace("/", _BRIDGE_SLASH)
    return ("@/*/@ros2_lv", f"@/*/@ros2_lv/*/{escaped}{_BRIDGE_SLASH}$*/**")


class BridgeKind(StrEnum):
    """What kind of ROS interface a bridge token stands for."""

    PUBLISHER = "MP"
    SUBSCRIBER = "MS"
    SERVICE_SERVER = "SS"
    SERVICE_CLIENT = "SC"
    ACTION_SERVER = "AS"
    ACTION_CLIENT = "AC"


@dataclass(frozen=True)
class BridgeToken:
    """One ROS interface as the bridge announces it."""

    kind: BridgeKind
    key: str
    """The interface's key ('bot1/cmd_vel')."""
    ros_type: str
    """Its ROS type ('geometry_msgs/msg/TwistStamped')."""

    def token_key(self, zid: str, qos: str = ":1:0:0,10") -> str:
        """The token's own key expression, as the bridge running as `zid` declares it
        (topics carry a QoS chunk: keyless, reliable, volatile, keep last 10 by default)."""
        parts = ["@", zid, "@ros2_lv", self.kind.value]
        parts += [self.key.replace("/", _BRIDGE_SLASH), self.ros_type.replace("/", _BRIDGE_SLASH)]
        if self.kind in (BridgeKind.PUBLISHER, BridgeKind.SUBSCRIBER):
            parts.append(qos)
        return "/".join(parts)

    @staticmethod
    def parse(token_key: str) -> BridgeToken | None:
        """The interface behind a bridge token's key, or None for any other key (the
        bridge's own ``@/<zid>/@ros2_lv`` token, or something else)."""
        parts = token_key.split("/")
        if len(parts) < 6 or parts[0] != "@" or parts[2] != "@ros2_lv":
            return None
        try:
            kind = BridgeKind(parts[3])
        except ValueError:
            return None
        return BridgeToken(
            kind, parts[4].replace(_BRIDGE_SLASH, "/"), parts[5].replace(_BRIDGE_SLASH, "/")
        )


# --- what rmw_zenoh uses -------------------------------------------------------------------
# Read in ros2/rmw_zenoh's docs/design.md and rmw_zenoh_cpp/src/detail/liveliness_utils.cpp
# as released for Humble (0.1.9), Jazzy (0.2.10) and Kilted (0.6.7); the three agree on
# everything below but the type hash, which Humble does not have.
#
# Data:   ``<domain>/<name>/<DDS type>/<type hash>``, the name fully qualified without its
#         leading '/' ('bot1/cmd_vel'), the type as DDS writes it
#         ('geometry_msgs::msg::dds_::Twist_'), the hash 'RIHS01_<sha256>' or, on Humble,
#         'TypeHashNotSupported'. A service's key names the service type.
# Tokens: ``@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/
#         <node>[/<name>/<DDS type>/<type hash>/<qos>]``, every '/' inside a name written
#         '%' (namespace '/' is '%', '/bot1' is '%bot1').

RMW_LIVELINESS = "@ros2_lv"
RMW_NO_NAMESPACE = "%"
"""The root namespace '/', and the default enclave, as rmw_zenoh's tokens write them."""
RMW_QOS_DEFAULT = "::,10:,:,:,,"
"""QoS chunk of a token: reliable, volatile, keep last 10 (rclcpp's default profile and
every service's); an empty field is rmw_zenoh's own default."""
RMW_QOS_LATCHED = ":1:,1:,:,:,,"
"""Reliable, transient local, keep last 1: an action's status topic."""


class RmwKind(StrEnum):
    """What an rmw_zenoh liveliness token stands for (there is no action kind: an action is
    three services and two topics)."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIBER = "MS"
    SERVICE_SERVER = "SS"
    SERVICE_CLIENT = "SC"


def rmw_mangle(name: str) -> str:
    """A ROS name as one key chunk: every '/' written '%' ('' is the root, '%')."""
    return "%" + name.strip("/").replace("/", "%") if name.strip("/") else RMW_NO_NAMESPACE


@dataclass(frozen=True)
class RmwToken:
    """One entity of a ROS 2 graph as rmw_zenoh announces it."""

    zid: str
    """The Zenoh session of the process holding it."""
    node_id: int
    entity_id: int
    kind: RmwKind
    namespace: str
    """The node's namespace, '' or 'bot1'."""
    node: str
    name: str = ""
    """The topic's or service's full name, 'bot1/cmd_vel'; '' for a node."""
    dds_type: str = ""
    type_hash: str = ""
    qos: str = RMW_QOS_DEFAULT


@dataclass(frozen=True)
class RmwZenohKeys:
    """Keys of a ROS 2 graph whose nodes speak rmw_zenoh, in one ROS domain."""

    domain_id: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.domain_id <= 232:  # what ROS 2 allows (rcl's ROS_DOMAIN_ID check)
            raise ValueError(f"ROS domain id {self.domain_id} is not in 0..232")

    def data(self, name: str, dds_type: str, type_hash: str) -> str:
        """The key of a topic's samples or of a service's queries."""
        return f"{self.domain_id}/{name.strip('/')}/{dds_type}/{type_hash}"

    def data_any_hash(self, name: str, dds_type: str) -> str:
        """The same for whatever type hash the robot's side has: what is heard or asked."""
        return self.data(name, dds_type, ANY)

    @property
    def tokens(self) -> str:
        """Every liveliness token of the domain."""
        return f"{RMW_LIVELINESS}/{self.domain_id}/**"

    def token(self, token: RmwToken) -> str:
        """The key of `token`, as rmw_zenoh declares it."""
        parts = [
            RMW_LIVELINESS,
            str(self.domain_id),
            token.zid,
            str(token.node_id),
            str(token.entity_id),
            token.kind.value,
            RMW_NO_NAMESPACE,  # the enclave: rcl's default
            rmw_mangle(token.namespace),
            token.node,
        ]
        if token.kind is not RmwKind.NODE:
            parts += [rmw_mangle(token.name), token.dds_type, token.type_hash, token.qos]
        return "/".join(parts)

    def parse_token(self, key: str) -> RmwToken | None:
        """The entity behind a token's key, or None for another key or another domain."""
        parts = key.split("/")
        if len(parts) < 9 or parts[0] != RMW_LIVELINESS or parts[1] != str(self.domain_id):
            return None
        try:
            kind = RmwKind(parts[5])
            node_id, entity_id = int(parts[3]), int(parts[4])
        except ValueError:
            return None
        namespace = parts[7].replace("%", "/").strip("/")
        if kind is RmwKind.NODE:
            return RmwToken(parts[2], node_id, entity_id, kind, namespace, parts[8])
        if len(parts) < 13:
            return None
        return RmwToken(
            parts[2],
            node_id,
            entity_id,
            kind,
            namespace,
            parts[8],
            parts[9].replace("%", "/").strip("/"),
            parts[10],
            parts[11],
            parts[12],
        )
