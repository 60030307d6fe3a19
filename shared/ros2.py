"""ROS 2 messages voicectl exchanges with a robot, as the CDR that zenoh-bridge-ros2dds carries.

Every payload is plain little-endian CDR with its 4-byte encapsulation header (``00 01 00 00``),
encoded and decoded by `rosbags`; nothing here packs bytes by hand. Callers deal in plain
Python values (`Pose2D`, `bytes` goal ids, `GoalStatus`) and never see a rosbags class.

Nav2's ``nav2_msgs/action/NavigateToPose`` is in no rosbags store, so it is registered from
its ``.action`` text, together with the wrapper types ROS 2's action machinery derives from it
(``_SendGoal_Request`` ...). Its Result differs between distributions: Humble's is
``std_msgs/Empty result``; Jazzy's is ``uint16 error_code`` plus ``string error_msg``.
"""

from __future__ import annotations

import functools
import math
import uuid
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, NamedTuple, TypeVar

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from .errors import VoicectlError

# Re-exported: every module that speaks ROS 2 messages names these.
from .kinds import CameraType as CameraType
from .kinds import CmdVelType as CmdVelType
from .kinds import RosDistro as RosDistro

GOAL_ID_SIZE = 16
CANCEL_ALL = bytes(GOAL_ID_SIZE)
"""The all-zero goal id: with a zero stamp, a cancel request for every goal (action_msgs)."""


class CdrError(VoicectlError):
    """Bytes that are not the CDR encoding of the ROS 2 message that was expected."""


class GoalStatus(IntEnum):
    """action_msgs/msg/GoalStatus.status."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    @property
    def terminal(self) -> bool:
        return self in (GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED)


class CancelCode(IntEnum):
    """action_msgs/srv/CancelGoal_Response.return_code."""

    NONE = 0
    """One or more goals are now canceling."""
    REJECTED = 1
    UNKNOWN_GOAL_ID = 2
    GOAL_TERMINATED = 3


NAVIGATION_ERRORS = {
    100: "controller: unknown",
    101: "controller: invalid controller",
    102: "controller: TF error",
    103: "controller: invalid path",
    104: "controller: patience exceeded",
    105: "controller: failed to make progress",
    106: "controller: no valid control",
    107: "controller: timed out",
    200: "planner: unknown",
    201: "planner: invalid planner",
    202: "planner: TF error",
    203: "planner: start outside the map",
    204: "planner: goal outside the map",
    205: "planner: start occupied",
    206: "planner: goal occupied",
    207: "planner: timed out",
    208: "planner: no valid path",
    9000: "navigator: unknown",
    9001: "navigator: failed to load the behaviour tree",
    9002: "navigator: TF error",
    9003: "navigator: timed out",
}
"""What Nav2's NavigateToPose result codes mean. Humble's result has none. Jazzy passes on
the code of the behaviour tree's FollowPath (100s) or ComputePathToPose (200s), the lowest
one set, and no message; Kilted adds the navigator's own 9000s and an error message."""


def new_goal_id() -> bytes:
    """A fresh random goal id, as an action client makes one per goal."""
    return uuid.uuid4().bytes


# --- plain values ---------------------------------------------------------------------------
# Decoded messages are named tuples: unpack them, or read their fields by name.


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A planar pose."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0
    """Heading in radians, counter-clockwise from +x."""


class Odometry(NamedTuple):
    """What nav_msgs/msg/Odometry says about a planar base."""

    pose: Pose2D
    linear_x: float
    angular_z: float
    stamp_s: float
    """Header stamp in seconds."""


class GoalRequest(NamedTuple):
    """A NavigateToPose goal as sent to send_goal."""

    goal_id: bytes
    frame: str
    """The goal pose's frame id ('map', 'odom', 'base_link')."""
    pose: Pose2D


class NavigateResult(NamedTuple):
    """A get_result reply: how the goal ended, and Jazzy's error details."""

    status: GoalStatus
    error_code: int = 0
    """Always 0 on Humble, whose Result carries nothing."""
    error_msg: str = ""


class NavigateFeedback(NamedTuple):
    goal_id: bytes
    pose: Pose2D
    distance_remaining: float


class CancelRequest(NamedTuple):
    goal_id: bytes
    """`CANCEL_ALL` (all zeros) selects goals by `stamp_s` alone."""
    stamp_s: float = 0.0
    """Non-zero: also cancel every goal accepted at or before this time."""


class CancelResponse(NamedTuple):
    return_code: CancelCode
    goal_ids: tuple[bytes, ...] = ()
    """The goals now canceling."""


class Image(NamedTuple):
    width: int
    height: int
    encoding: str
    data: bytes
    """Rows of `width` pixels, top row first, no padding."""


class CompressedImage(NamedTuple):
    format: str
    """image_transport's description: 'rgb8; jpeg compressed bgr8', 'bgr8; png compressed bgr8'."""
    data: bytes
    """The encoded file (JPEG, PNG...)."""


# Bytes per pixel of the encodings `Ros2Codec.image` writes.
class OccupancyGrid(NamedTuple):
    """A map: `width` x `height` cells of `resolution` metres, row 0 at `origin`, each -1
    (unknown) or 0 (free) to 100 (occupied), as int8 bytes row by row."""

    width: int
    height: int
    resolution: float
    origin: Pose2D
    cells: bytes
    frame: str = "map"


IMAGE_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1, "mono16": 2}

_STORES = {
    RosDistro.HUMBLE: Stores.ROS2_HUMBLE,
    RosDistro.JAZZY: Stores.ROS2_JAZZY,
    RosDistro.ROLLING: Stores.ROS2_KILTED,  # the newest release rosbags has
}

# --- type definitions -----------------------------------------------------------------------

NAVIGATE_TO_POSE = "nav2_msgs/action/NavigateToPose"
CANCEL_GOAL = "action_msgs/srv/CancelGoal"
"""The service that cancels any action's goals."""
NAVIGATE_SEND_GOAL = f"{NAVIGATE_TO_POSE}_SendGoal"
NAVIGATE_GET_RESULT = f"{NAVIGATE_TO_POSE}_GetResult"
NAVIGATE_FEEDBACK = f"{NAVIGATE_TO_POSE}_FeedbackMessage"
"""The services and topic ROS 2 makes of Nav2's action, by their types."""

_NAV_GOAL = """
geometry_msgs/PoseStamped pose
string behavior_tree
"""

# Checked against docs.ros.org's nav2_msgs pages (Humble: "std_msgs/Empty result") and Jazzy-era
# copies of NavigateToPose.action; the constants do not change a byte on the wire. Rolling's
# result is Jazzy's (more constants); its feedback has two more fields (position and heading
# tracking error).
_NAV_RESULT = {
    RosDistro.HUMBLE: """
std_msgs/Empty result
""",
    RosDistro.JAZZY: """
uint16 NONE=0
uint16 UNKNOWN=9000
uint16 FAILED_TO_LOAD_BEHAVIOR_TREE=9001
uint16 TF_ERROR=9002
uint16 error_code
string error_msg
""",
}
_NAV_RESULT[RosDistro.ROLLING] = _NAV_RESULT[RosDistro.JAZZY]

_FEEDBACK = """
geometry_msgs/PoseStamped current_pose
builtin_interfaces/Duration navigation_time
builtin_interfaces/Duration estimated_time_remaining
int16 number_of_recoveries
float32 distance_remaining
"""
_NAV_FEEDBACK = {
    RosDistro.HUMBLE: _FEEDBACK,
    RosDistro.JAZZY: _FEEDBACK,
    RosDistro.ROLLING: _FEEDBACK
    + "float32 position_tracking_error\nfloat32 heading_tracking_error\n",
}

# The services and the feedback topic ROS 2 derives from any action (rosidl's action idl).
_ACTION_WRAPPERS = {
    "_SendGoal_Request": "unique_identifier_msgs/msg/UUID goal_id\n{action}_Goal goal",
    "_SendGoal_Response": "bool accepted\nbuiltin_interfaces/msg/Time stamp",
    "_GetResult_Request": "unique_identifier_msgs/msg/UUID goal_id",
    "_GetResult_Response": "int8 status\n{action}_Result result",
    "_FeedbackMessage": "unique_identifier_msgs/msg/UUID goal_id\n{action}_Feedback feedback",
}

_CANCEL_REQUEST = """
action_msgs/msg/GoalInfo goal_info
"""

SPEED_LIMIT = "nav2_msgs/msg/SpeedLimit"
"""What Nav2's controller server takes on its `speed_limit` topic: a top linear speed, in
m/s or in percent of its own (0: none), for whatever goal it follows."""
_SPEED_LIMIT = """
std_msgs/Header header
bool percentage
float64 speed_limit
"""

_CANCEL_RESPONSE = """
int8 ERROR_NONE=0
int8 ERROR_REJECTED=1
int8 ERROR_UNKNOWN_GOAL_ID=2
int8 ERROR_GOAL_TERMINATED=3
int8 return_code
action_msgs/msg/GoalInfo[] goals_canceling
"""


def _definitions(distro: RosDistro) -> dict[str, str]:
    """Message text of every type voicectl adds to the distribution's store."""
    texts = {
        f"{NAVIGATE_TO_POSE}_Goal": _NAV_GOAL,
        f"{NAVIGATE_TO_POSE}_Result": _NAV_RESULT[distro],
        f"{NAVIGATE_TO_POSE}_Feedback": _NAV_FEEDBACK[distro],
        f"{CANCEL_GOAL}_Request": _CANCEL_REQUEST,
        f"{CANCEL_GOAL}_Response": _CANCEL_RESPONSE,
        SPEED_LIMIT: _SPEED_LIMIT,
    }
    for suffix, text in _ACTION_WRAPPERS.items():
        texts[f"{NAVIGATE_TO_POSE}{suffix}"] = text.format(action=NAVIGATE_TO_POSE)
    return texts


@functools.cache
def typestore(distro: RosDistro) -> Typestore:
    """The distribution's rosbags store plus Nav2's action, built once per process."""
    # Building a store costs ~0.25 s, and a store is never changed after this function.
    store = get_typestore(_STORES[distro])
    for name, text in _definitions(distro).items():
        if name in store.fielddefs:  # a future rosbags may ship action_msgs' services
            continue
        # get_types_from_msg files a service type under '<pkg>/srv/msg/<name>': keep our name.
        (definition,) = get_types_from_msg(text, name).values()
        store.register({name: definition})
    return store


# --- names and hashes of types, as ROS 2's middlewares write them ----------------------------

NO_TYPE_HASH = "TypeHashNotSupported"
"""What rmw_zenoh writes where a type hash goes on Humble, which has none."""
SERVICES = (NAVIGATE_SEND_GOAL, NAVIGATE_GET_RESULT, CANCEL_GOAL)
"""The services voicectl calls or serves (an action's are services too)."""


def dds_type_name(ros_type: str) -> str:
    """A type as DDS and rmw_zenoh name it: 'geometry_msgs::msg::dds_::Twist_'."""
    package, kind, name = _split_type(ros_type)
    return f"{package}::{kind}::dds_::{name}_"


def ros_type_of(dds_name: str) -> str:
    """The inverse of `dds_type_name`; ValueError for a name not of that form."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise ValueError(f"{dds_name!r} is not a DDS type name ('pkg::msg::dds_::Name_')")
    return "/".join((parts[0], parts[1], parts[3][:-1]))


def _split_type(ros_type: str) -> tuple[str, str, str]:
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"{ros_type!r} is not a ROS type name ('pkg/msg/Name')")
    return parts[0], parts[1], parts[2]


def type_hash(distro: RosDistro, ros_type: str) -> str:
    """The RIHS01 hash of a message or service type, as rosidl computes it and rmw_zenoh
    writes it into keys ('RIHS01_<sha256>'); `NO_TYPE_HASH` on Humble."""
    if distro is RosDistro.HUMBLE:
        return NO_TYPE_HASH
    return hash_store(distro).hash_rihs01(ros_type)


@functools.cache
def hash_store(distro: RosDistro) -> Typestore:
    """A store whose descriptions hash as rosidl's: a service is a type of its own (request,
    response and event messages) and a message's `char` is rosidl's `uint8`. Apart from the
    codec's store: the hashes need types nothing encodes."""
    store = get_typestore(_STORES[distro])
    for name, text in _definitions(distro).items():
        if name not in store.fielddefs:
            (definition,) = get_types_from_msg(text, name).values()
            store.register({name: definition})
    for name, (constants, fields) in list(store.fielddefs.items()):
        store.fielddefs[name] = (constants, [(f, _char_as_uint8(d)) for f, d in fields])
    for service in SERVICES:
        describe_service(store, service)
    return store


def describe_service(store: Typestore, service: str) -> None:
    """Register the type rosidl hashes for `service`, whose `_Request` and `_Response` the
    store has: its request, response and introspection event messages."""
    event = f"{service}_Event"
    store.fielddefs[event] = (
        [],
        [
            ("info", (Nodetype.NAME, "service_msgs/msg/ServiceEventInfo")),
            ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{service}_Request"), 1))),
            ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, f"{service}_Response"), 1))),
        ],
    )
    store.fielddefs[service] = (
        [],
        [
            ("request_message", (Nodetype.NAME, f"{service}_Request")),
            ("response_message", (Nodetype.NAME, f"{service}_Response")),
            ("event_message", (Nodetype.NAME, event)),
        ],
    )


def _char_as_uint8(desc: Any) -> Any:
    """A field description with `char` read as rosidl reads it in a .msg: uint8."""
    kind, rest = desc
    if kind == Nodetype.BASE and rest[0] == "char":
        return (kind, ("uint8", rest[1]))
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        return (kind, (_char_as_uint8(rest[0]), rest[1]))
    return desc


# --- the codec ------------------------------------------------------------------------------

_E = TypeVar("_E", bound=IntEnum)


class Ros2Codec:
    """Encode and decode the ROS 2 messages voicectl needs, for one distribution."""

    def __init__(self, distro: RosDistro = RosDistro.JAZZY) -> None:
        self.distro = distro
        self._store = typestore(distro)
        self._types: dict[str, Any] = dict(self._store.types)

    # --- geometry_msgs/msg/Twist --------------------------------------------------------

    def twist(self, linear_x: float, angular_z: float) -> bytes:
        return self._encode(self._twist(linear_x, angular_z), "geometry_msgs/msg/Twist")

    def read_twist(self, raw: bytes) -> tuple[float, float]:
        """(linear x, angular z) of a Twist; a planar base ignores the other axes."""
        msg = self._decode(raw, "geometry_msgs/msg/Twist")
        return float(msg.linear.x), float(msg.angular.z)

    # --- geometry_msgs/msg/TwistStamped -------------------------------------------------

    def twist_stamped(
        self, linear_x: float, angular_z: float, stamp_s: float = 0.0, frame: str = "base_link"
    ) -> bytes:
        msg = self._types["geometry_msgs/msg/TwistStamped"](
            header=self._header(stamp_s, frame), twist=self._twist(linear_x, angular_z)
        )
        return self._encode(msg, "geometry_msgs/msg/TwistStamped")

    def read_twist_stamped(self, raw: bytes) -> tuple[float, float]:
        msg = self._decode(raw, "geometry_msgs/msg/TwistStamped")
        return float(msg.twist.linear.x), float(msg.twist.angular.z)

    def velocity(
        self, kind: CmdVelType, linear_x: float, angular_z: float, stamp_s: float = 0.0
    ) -> bytes:
        """A velocity command of the type the robot's cmd_vel takes."""
        if kind is CmdVelType.STAMPED:
            return self.twist_stamped(linear_x, angular_z, stamp_s)
        return self.twist(linear_x, angular_z)

    def read_velocity(self, kind: CmdVelType, raw: bytes) -> tuple[float, float]:
        if kind is CmdVelType.STAMPED:
            return self.read_twist_stamped(raw)
        return self.read_twist(raw)

    # --- nav2_msgs/msg/SpeedLimit ---------------------------------------------------------

    def speed_limit(self, limit: float, stamp_s: float = 0.0, percentage: bool = False) -> bytes:
        """Nav2's controller held to `limit` m/s (`percentage`: percent of its own top speed;
        0: no limit)."""
        msg = self._types[SPEED_LIMIT](
            header=self._header(stamp_s, ""), percentage=percentage, speed_limit=limit
        )
        return self._encode(msg, SPEED_LIMIT)

    def read_speed_limit(self, raw: bytes) -> tuple[float, bool]:
        """(the limit, whether it is in percent) of a SpeedLimit."""
        msg = self._decode(raw, SPEED_LIMIT)
        return float(msg.speed_limit), bool(msg.percentage)

    def velocity_axes(self, kind: CmdVelType, raw: bytes) -> tuple[float, ...]:
        """Every axis of a velocity command: linear x, y, z, then angular x, y, z (a
        holonomic base or a drone moves on those a planar base ignores)."""
        twist = self._twist_of(kind, raw)
        linear, angular = twist.linear, twist.angular
        axes = (linear.x, linear.y, linear.z, angular.x, angular.y, angular.z)
        return tuple(float(axis) for axis in axes)

    def stilled(self, kind: CmdVelType, raw: bytes) -> bytes:
        """The velocity command `raw` with every axis zero, its header (a TwistStamped's
        stamp and frame) kept."""
        if kind is CmdVelType.STAMPED:
            header = self._decode(raw, kind.ros_type).header
            msg = self._types[kind.ros_type](header=header, twist=self._twist(0.0, 0.0))
            return self._encode(msg, kind.ros_type)
        return self.twist(0.0, 0.0)

    def _twist_of(self, kind: CmdVelType, raw: bytes) -> Any:
        msg = self._decode(raw, kind.ros_type)
        return msg.twist if kind is CmdVelType.STAMPED else msg

    # --- nav_msgs/msg/Odometry ----------------------------------------------------------

    def odometry(self, pose: Pose2D, linear_x: float, angular_z: float, stamp_s: float) -> bytes:
        t = self._types
        msg = t["nav_msgs/msg/Odometry"](
            header=self._header(stamp_s, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=self._pose(pose), covariance=np.zeros(36, dtype=np.float64)
            ),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](
                twist=self._twist(linear_x, angular_z), covariance=np.zeros(36, dtype=np.float64)
            ),
        )
        return self._encode(msg, "nav_msgs/msg/Odometry")

    def transform(self, pose: Pose2D, stamp_s: float) -> bytes:
        """tf2_msgs/TFMessage with the odom -> base_link transform of `pose`, as a base's
        driver publishes it on /tf next to odometry."""
        t = self._types
        msg = t["tf2_msgs/msg/TFMessage"](
            transforms=[
                t["geometry_msgs/msg/TransformStamped"](
                    header=self._header(stamp_s, "odom"),
                    child_frame_id="base_link",
                    transform=t["geometry_msgs/msg/Transform"](
                        translation=t["geometry_msgs/msg/Vector3"](x=pose.x, y=pose.y, z=0.0),
                        rotation=self._pose(pose).orientation,
                    ),
                )
            ]
        )
        return self._encode(msg, "tf2_msgs/msg/TFMessage")

    def read_transform(self, raw: bytes) -> list[tuple[str, str, Pose2D]]:
        """(parent, child, planar pose) of each transform in a TFMessage. Only the tests
        read TF today; the reader lives beside its writer so that the simulator's bytes are
        checked by the codec that makes them, and fuzzed with every other reader."""
        msg = self._decode(raw, "tf2_msgs/msg/TFMessage")
        found = []
        for stamped in msg.transforms:
            v = stamped.transform.translation
            pose = Pose2D(x=float(v.x), y=float(v.y), yaw=_yaw(stamped.transform.rotation))
            found.append((str(stamped.header.frame_id), str(stamped.child_frame_id), pose))
        return found

    def read_odometry(self, raw: bytes) -> Odometry:
        """Pose, velocity and stamp of an Odometry message."""
        msg = self._decode(raw, "nav_msgs/msg/Odometry")
        return Odometry(
            pose=_pose2d(msg.pose.pose),
            linear_x=float(msg.twist.twist.linear.x),
            angular_z=float(msg.twist.twist.angular.z),
            stamp_s=_seconds(msg.header.stamp),
        )

    # --- navigate_to_pose: send_goal ----------------------------------------------------

    def send_goal_request(
        self, goal_id: bytes, frame: str, pose: Pose2D, stamp_s: float = 0.0
    ) -> bytes:
        t = self._types
        goal = t[f"{NAVIGATE_TO_POSE}_Goal"](
            pose=t["geometry_msgs/msg/PoseStamped"](
                header=self._header(stamp_s, frame), pose=self._pose(pose)
            ),
            behavior_tree="",
        )
        msg = t[f"{NAVIGATE_TO_POSE}_SendGoal_Request"](goal_id=self._uuid(goal_id), goal=goal)
        return self._encode(msg, f"{NAVIGATE_TO_POSE}_SendGoal_Request")

    def read_send_goal_request(self, raw: bytes) -> GoalRequest:
        msg = self._decode(raw, f"{NAVIGATE_TO_POSE}_SendGoal_Request")
        return GoalRequest(
            goal_id=_goal_id(msg.goal_id),
            frame=str(msg.goal.pose.header.frame_id),
            pose=_pose2d(msg.goal.pose.pose),
        )

    def send_goal_response(self, accepted: bool, stamp_s: float = 0.0) -> bytes:
        msg = self._types[f"{NAVIGATE_TO_POSE}_SendGoal_Response"](
            accepted=accepted, stamp=self._time(stamp_s)
        )
        return self._encode(msg, f"{NAVIGATE_TO_POSE}_SendGoal_Response")

    def read_send_goal_response(self, raw: bytes) -> bool:
        """Whether the goal was accepted."""
        return bool(self._decode(raw, f"{NAVIGATE_TO_POSE}_SendGoal_Response").accepted)

    # --- navigate_to_pose: get_result ---------------------------------------------------

    def get_result_request(self, goal_id: bytes) -> bytes:
        msg = self._types[f"{NAVIGATE_TO_POSE}_GetResult_Request"](goal_id=self._uuid(goal_id))
        return self._encode(msg, f"{NAVIGATE_TO_POSE}_GetResult_Request")

    def read_get_result_request(self, raw: bytes) -> bytes:
        """The goal id asked about."""
        return _goal_id(self._decode(raw, f"{NAVIGATE_TO_POSE}_GetResult_Request").goal_id)

    def get_result_response(self, status: int, error_code: int = 0, error_msg: str = "") -> bytes:
        """The final status; `error_code` and `error_msg` are dropped on Humble."""
        t = self._types
        if self.distro is RosDistro.HUMBLE:
            result = t[f"{NAVIGATE_TO_POSE}_Result"](result=t["std_msgs/msg/Empty"]())
        else:
            if not 0 <= error_code <= 0xFFFF:
                raise ValueError(f"error_code {error_code} must fit in uint16")
            result = t[f"{NAVIGATE_TO_POSE}_Result"](error_code=error_code, error_msg=error_msg)
        msg = t[f"{NAVIGATE_TO_POSE}_GetResult_Response"](
            status=int(GoalStatus(status)), result=result
        )
        return self._encode(msg, f"{NAVIGATE_TO_POSE}_GetResult_Response")

    def read_get_result_response(self, raw: bytes) -> NavigateResult:
        msg = self._decode(raw, f"{NAVIGATE_TO_POSE}_GetResult_Response")
        status = _enum(GoalStatus, msg.status, "goal status")
        if self.distro is RosDistro.HUMBLE:
            return NavigateResult(status=status)
        return NavigateResult(
            status=status,
            error_code=int(msg.result.error_code),
            error_msg=str(msg.result.error_msg),
        )

    # --- navigate_to_pose: feedback -----------------------------------------------------

    def feedback(
        self,
        goal_id: bytes,
        current: Pose2D,
        distance_remaining: float,
        navigation_time_s: float,
        frame: str = "map",
        stamp_s: float = 0.0,
    ) -> bytes:
        t = self._types
        rolling = (
            {"position_tracking_error": 0.0, "heading_tracking_error": 0.0}
            if self.distro is RosDistro.ROLLING
            else {}
        )
        feedback = t[f"{NAVIGATE_TO_POSE}_Feedback"](
            current_pose=t["geometry_msgs/msg/PoseStamped"](
                header=self._header(stamp_s, frame), pose=self._pose(current)
            ),
            navigation_time=self._duration(navigation_time_s),
            estimated_time_remaining=self._duration(0.0),
            number_of_recoveries=0,
            distance_remaining=distance_remaining,
            **rolling,
        )
        msg = t[f"{NAVIGATE_TO_POSE}_FeedbackMessage"](
            goal_id=self._uuid(goal_id), feedback=feedback
        )
        return self._encode(msg, f"{NAVIGATE_TO_POSE}_FeedbackMessage")

    def read_feedback(self, raw: bytes) -> NavigateFeedback:
        msg = self._decode(raw, f"{NAVIGATE_TO_POSE}_FeedbackMessage")
        return NavigateFeedback(
            goal_id=_goal_id(msg.goal_id),
            pose=_pose2d(msg.feedback.current_pose.pose),
            distance_remaining=float(msg.feedback.distance_remaining),
        )

    # --- navigate_to_pose: cancel_goal (action_msgs/srv/CancelGoal) -----------------------

    def cancel_goal_request(self, goal_id: bytes = CANCEL_ALL, stamp_s: float = 0.0) -> bytes:
        """Cancel `goal_id`; the default (all zeros, zero stamp) cancels every goal."""
        msg = self._types[f"{CANCEL_GOAL}_Request"](goal_info=self._goal_info(goal_id, stamp_s))
        return self._encode(msg, f"{CANCEL_GOAL}_Request")

    def read_cancel_goal_request(self, raw: bytes) -> CancelRequest:
        info = self._decode(raw, f"{CANCEL_GOAL}_Request").goal_info
        return CancelRequest(goal_id=_goal_id(info.goal_id), stamp_s=_seconds(info.stamp))

    def cancel_goal_response(self, return_code: int, goal_ids: tuple[bytes, ...] = ()) -> bytes:
        msg = self._types[f"{CANCEL_GOAL}_Response"](
            return_code=int(CancelCode(return_code)),
            goals_canceling=[self._goal_info(goal_id, 0.0) for goal_id in goal_ids],
        )
        return self._encode(msg, f"{CANCEL_GOAL}_Response")

    def read_cancel_goal_response(self, raw: bytes) -> CancelResponse:
        msg = self._decode(raw, f"{CANCEL_GOAL}_Response")
        return CancelResponse(
            return_code=_enum(CancelCode, msg.return_code, "cancel return code"),
            goal_ids=tuple(_goal_id(info.goal_id) for info in msg.goals_canceling),
        )

    # --- navigate_to_pose: status (action_msgs/msg/GoalStatusArray) ---------------------

    def goal_status_array(self, statuses: list[tuple[bytes, GoalStatus]]) -> bytes:
        """Every goal the server still remembers, with its status (stamps left at zero)."""
        t = self._types
        status_list = [
            t["action_msgs/msg/GoalStatus"](
                goal_info=self._goal_info(goal_id, 0.0), status=int(GoalStatus(status))
            )
            for goal_id, status in statuses
        ]
        msg = t["action_msgs/msg/GoalStatusArray"](status_list=status_list)
        return self._encode(msg, "action_msgs/msg/GoalStatusArray")

    def read_goal_status_array(self, raw: bytes) -> list[tuple[bytes, GoalStatus]]:
        """Read only by the tests, for the reason `read_transform` gives."""
        msg = self._decode(raw, "action_msgs/msg/GoalStatusArray")
        return [
            (_goal_id(entry.goal_info.goal_id), _enum(GoalStatus, entry.status, "goal status"))
            for entry in msg.status_list
        ]

    # --- sensor_msgs/msg/Image ----------------------------------------------------------

    def image(
        self,
        width: int,
        height: int,
        encoding: str,
        data: bytes,
        stamp_s: float = 0.0,
        frame: str = "camera",
    ) -> bytes:
        if encoding not in IMAGE_ENCODINGS:
            raise ValueError(
                f"image encoding {encoding!r} is not supported; use one of "
                + ", ".join(IMAGE_ENCODINGS)
            )
        step = width * IMAGE_ENCODINGS[encoding]
        if width < 0 or height < 0 or len(data) != step * height:
            raise ValueError(
                f"{len(data)} bytes of {encoding} do not make a {width}x{height} image "
                f"({step * height} expected)"
            )
        msg = self._types["sensor_msgs/msg/Image"](
            header=self._header(stamp_s, frame),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=0,
            step=step,
            data=np.frombuffer(data, dtype=np.uint8),
        )
        return self._encode(msg, "sensor_msgs/msg/Image")

    def read_image(self, raw: bytes) -> Image:
        msg = self._decode(raw, "sensor_msgs/msg/Image")
        width, height, step = int(msg.width), int(msg.height), int(msg.step)
        data = bytes(msg.data)
        row = width * IMAGE_ENCODINGS.get(str(msg.encoding), 0)
        if len(data) != step * height or (row and step < row):
            raise CdrError(
                f"image of {width}x{height} {msg.encoding!r} with step {step} "
                f"carries {len(data)} bytes"
            )
        if row and step != row:  # drop row padding so that callers see packed rows
            data = b"".join(data[i * step : i * step + row] for i in range(height))
        return Image(width=width, height=height, encoding=str(msg.encoding), data=data)

    # --- sensor_msgs/msg/CompressedImage --------------------------------------------------

    def compressed_image(
        self, image_format: str, data: bytes, stamp_s: float = 0.0, frame: str = "camera"
    ) -> bytes:
        msg = self._types["sensor_msgs/msg/CompressedImage"](
            header=self._header(stamp_s, frame),
            format=image_format,
            data=np.frombuffer(data, dtype=np.uint8),
        )
        return self._encode(msg, "sensor_msgs/msg/CompressedImage")

    def read_compressed_image(self, raw: bytes) -> CompressedImage:
        msg = self._decode(raw, "sensor_msgs/msg/CompressedImage")
        return CompressedImage(format=str(msg.format), data=bytes(msg.data))

    # --- nav_msgs/msg/OccupancyGrid -------------------------------------------------------

    def occupancy_grid(self, grid: OccupancyGrid, stamp_s: float = 0.0) -> bytes:
        t = self._types
        info = t["nav_msgs/msg/MapMetaData"](
            map_load_time=self._time(stamp_s),
            resolution=grid.resolution,
            width=grid.width,
            height=grid.height,
            origin=self._pose(grid.origin),
        )
        msg = t["nav_msgs/msg/OccupancyGrid"](
            header=self._header(stamp_s, grid.frame),
            info=info,
            data=np.frombuffer(grid.cells, dtype=np.int8),
        )
        return self._encode(msg, "nav_msgs/msg/OccupancyGrid")

    def read_occupancy_grid(self, raw: bytes) -> OccupancyGrid:
        msg = self._decode(raw, "nav_msgs/msg/OccupancyGrid")
        info = msg.info
        width, height = int(info.width), int(info.height)
        cells = bytes(np.asarray(msg.data, dtype=np.int8).tobytes())
        if len(cells) != width * height:
            raise CdrError(f"an occupancy grid of {width}x{height} cells carries {len(cells)}")
        return OccupancyGrid(
            width=width,
            height=height,
            resolution=float(info.resolution),
            origin=_pose2d(info.origin),
            cells=cells,
            frame=str(msg.header.frame_id),
        )

    # --- helpers ------------------------------------------------------------------------

    def _encode(self, msg: object, typename: str) -> bytes:
        return bytes(self._store.serialize_cdr(msg, typename, little_endian=True))

    def _decode(self, raw: bytes, typename: str) -> Any:
        try:
            return self._store.deserialize_cdr(raw, typename)
        except Exception as exc:  # every rosbags failure on foreign bytes is a malformed frame
            raise CdrError(f"{len(raw)} bytes are not a valid {typename}: {exc}") from exc

    def _time(self, seconds: float) -> Any:
        sec, nanosec = _split_seconds(seconds)
        return self._types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)

    def _duration(self, seconds: float) -> Any:
        sec, nanosec = _split_seconds(seconds)
        return self._types["builtin_interfaces/msg/Duration"](sec=sec, nanosec=nanosec)

    def _header(self, stamp_s: float, frame: str) -> Any:
        return self._types["std_msgs/msg/Header"](stamp=self._time(stamp_s), frame_id=frame)

    def _uuid(self, goal_id: bytes) -> Any:
        if len(goal_id) != GOAL_ID_SIZE:
            raise ValueError(f"a goal id is {GOAL_ID_SIZE} bytes, not {len(goal_id)}")
        return self._types["unique_identifier_msgs/msg/UUID"](
            uuid=np.frombuffer(goal_id, dtype=np.uint8)
        )

    def _goal_info(self, goal_id: bytes, stamp_s: float) -> Any:
        return self._types["action_msgs/msg/GoalInfo"](
            goal_id=self._uuid(goal_id), stamp=self._time(stamp_s)
        )

    def _twist(self, linear_x: float, angular_z: float) -> Any:
        vector = self._types["geometry_msgs/msg/Vector3"]
        return self._types["geometry_msgs/msg/Twist"](
            linear=vector(x=linear_x, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=angular_z)
        )

    def _pose(self, pose: Pose2D) -> Any:
        t = self._types
        return t["geometry_msgs/msg/Pose"](
            position=t["geometry_msgs/msg/Point"](x=pose.x, y=pose.y, z=0.0),
            orientation=t["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=math.sin(pose.yaw / 2), w=math.cos(pose.yaw / 2)
            ),
        )


SAME_RESULT = {RosDistro.ROLLING: RosDistro.JAZZY}
"""Distributions whose NavigateToPose result is another's: a get_result reply cannot tell
them apart (their feedback can: `distro_from_hash`)."""


def distro_of_result(raw: bytes) -> RosDistro:
    """Which distribution's NavigateToPose layout a get_result reply is in (Jazzy for
    Rolling's too, `SAME_RESULT`). Any reply tells, even the one an action server gives at
    once for a goal it does not know, so an executor can learn its robot's distribution
    before sending a goal."""
    fits = []
    for distro in RosDistro:
        if distro in SAME_RESULT:
            continue
        try:
            Ros2Codec(distro).read_get_result_response(raw)
        except CdrError:
            continue
        fits.append(distro)
    if len(fits) != 1:
        found = "every" if fits else "no"
        raise CdrError(f"{len(raw)} bytes fit {found} known NavigateToPose result layout")
    return fits[0]


@functools.cache
def distro_from_hash(ros_type: str, announced: str) -> RosDistro | None:
    """The distribution a type hash a robot announced for `ros_type` is of: Humble for
    its placeholder, else the one distribution whose hash it is; None when it is no
    distribution's, or several's (a Twist is the same in Jazzy and Rolling)."""
    if announced == NO_TYPE_HASH:
        return RosDistro.HUMBLE
    found = []
    for distro in RosDistro:
        if distro is RosDistro.HUMBLE:
            continue
        try:
            if type_hash(distro, ros_type) == announced:
                found.append(distro)
        except KeyError:  # a type voicectl has no definition of: it tells nothing
            return None
    return found[0] if len(found) == 1 else None


def _split_seconds(seconds: float) -> tuple[int, int]:
    """(sec, nanosec) of builtin_interfaces Time/Duration: nanosec is always in [0, 1e9)."""
    total = round(seconds * 1_000_000_000)
    sec, nanosec = divmod(total, 1_000_000_000)
    if not -(2**31) <= sec < 2**31:
        raise ValueError(f"{seconds} s does not fit a ROS time (int32 seconds)")
    return sec, nanosec


def _seconds(stamp: Any) -> float:
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def _goal_id(uuid_msg: Any) -> bytes:
    return bytes(uuid_msg.uuid)


def _yaw(q: Any) -> float:
    """The rotation about z of a quaternion (roll and pitch are zero on the ground)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _pose2d(pose: Any) -> Pose2D:
    return Pose2D(x=float(pose.position.x), y=float(pose.position.y), yaw=_yaw(pose.orientation))


def _enum(kind: type[_E], value: int, what: str) -> _E:
    try:
        return kind(int(value))
    except ValueError:
        allowed = ", ".join(f"{m.value} ({m.name})" for m in kind)
        raise CdrError(f"{what} {value} is unknown; known: {allowed}") from None
