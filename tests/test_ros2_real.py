"""shared/ros2.py against real ROS 2 (PyPI's Jazzy and Kilted, harness/ros2_env.py): every
type voicectl encodes or decodes, read and written by `rclpy.serialization`, and every
type hash voicectl computes against the ones rosidl wrote into the wheels' type
descriptions. Real messages: long strings, unicode frame ids, empty and long arrays.

For each message: real ROS reads voicectl's bytes as the values meant; real ROS's own
bytes for those values equal voicectl's except where ROS does not read them (alignment
padding, which it leaves uninitialised: found by flipping each byte and seeing whether
ROS reads anything different); and voicectl reads real ROS's bytes back."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from harness.ros2_env import ROLLING_NAV2_MSGS
from voicectl.shared.ros2 import (
    CANCEL_ALL,
    CANCEL_GOAL,
    NAVIGATE_FEEDBACK,
    NAVIGATE_GET_RESULT,
    NAVIGATE_SEND_GOAL,
    SERVICES,
    SPEED_LIMIT,
    CancelCode,
    CdrError,
    GoalStatus,
    OccupancyGrid,
    Pose2D,
    Ros2Codec,
    RosDistro,
    type_hash,
)

from .ros2_support import DISTROS, Oracle, env_of, oracle_of, type_hashes

pytestmark = pytest.mark.ros2

CODEC = Ros2Codec(RosDistro.JAZZY)
"""Kilted's messages are Jazzy's for every type voicectl speaks: one codec for both."""
GOAL_ID = bytes(range(1, 17))
STAMP = 1_764_000_000.5
"""Seconds that a float and ROS's (sec, nanosec) both hold exactly."""
POSE = Pose2D(x=1.5, y=-2.25, yaw=0.75)
FRAME = "карта/ロボット_🤖_" + "x" * 300
"""A frame id no robot would use, to try strings: unicode, odd lengths, long."""
LONG_TEXT = "ошибка: " + "no path to the kitchen; " * 60


@pytest.fixture(params=DISTROS, scope="module")
def oracle(request: pytest.FixtureRequest) -> Iterator[Oracle]:
    yield from oracle_of(request.param)


# --- what real ROS should read, in plain values --------------------------------------------


def time_of(seconds: float) -> dict[str, int]:
    sec, nanosec = divmod(round(seconds * 1_000_000_000), 1_000_000_000)
    return {"sec": sec, "nanosec": nanosec}


def header(stamp: float, frame: str) -> dict[str, Any]:
    return {"stamp": time_of(stamp), "frame_id": frame}


def vector(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> dict[str, float]:
    return {"x": x, "y": y, "z": z}


def pose(p: Pose2D) -> dict[str, Any]:
    quaternion = {"x": 0.0, "y": 0.0, "z": math.sin(p.yaw / 2), "w": math.cos(p.yaw / 2)}
    return {"position": vector(p.x, p.y), "orientation": quaternion}


def twist(linear: float, angular: float) -> dict[str, Any]:
    return {"linear": vector(linear), "angular": vector(z=angular)}


def uuid(goal_id: bytes) -> dict[str, list[int]]:
    return {"uuid": list(goal_id)}


def goal_info(goal_id: bytes, stamp: float = 0.0) -> dict[str, Any]:
    return {"goal_id": uuid(goal_id), "stamp": time_of(stamp)}


def ids(count: int) -> list[bytes]:
    return [bytes([i % 256] * 15 + [7]) for i in range(count)]


@dataclass(frozen=True)
class Case:
    """One message as voicectl writes it, what real ROS must read in it, and how voicectl
    reads what real ROS writes for it."""

    name: str
    ros_type: str
    ours: bytes
    values: dict[str, Any]
    read: Callable[[bytes], object] | None = None
    """voicectl's reader of the type; None where only voicectl writes it."""
    read_as: object = None
    """What `read` must return for real ROS's bytes of `values`."""


GRID = OccupancyGrid(
    width=173,
    height=61,
    resolution=0.05,
    origin=Pose2D(-4.0, -1.5, 0.25),
    cells=bytes((i * 37) % 101 for i in range(173 * 61)),
    frame=FRAME,
)
PIXELS = bytes(range(256)) * 36  # 64 x 48 rgb8
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(256)) * 400


def cases() -> list[Case]:
    c = CODEC
    status_ids = ids(120)
    return [
        Case(
            "twist",
            "geometry_msgs/msg/Twist",
            c.twist(0.25, -1.5),
            twist(0.25, -1.5),
            c.read_twist,
            (0.25, -1.5),
        ),
        Case(
            "twist stamped",
            "geometry_msgs/msg/TwistStamped",
            c.twist_stamped(0.5, 1.25, STAMP, FRAME),
            {"header": header(STAMP, FRAME), "twist": twist(0.5, 1.25)},
            c.read_twist_stamped,
            (0.5, 1.25),
        ),
        Case(
            "odometry",
            "nav_msgs/msg/Odometry",
            c.odometry(POSE, 0.4, -0.3, STAMP),
            {
                "header": header(STAMP, "odom"),
                "child_frame_id": "base_link",
                "pose": {"pose": pose(POSE), "covariance": [0.0] * 36},
                "twist": {"twist": twist(0.4, -0.3), "covariance": [0.0] * 36},
            },
            lambda raw: tuple(c.read_odometry(raw)),
            (c.read_odometry(c.odometry(POSE, 0.4, -0.3, STAMP))),
        ),
        Case(
            "tf",
            "tf2_msgs/msg/TFMessage",
            c.transform(POSE, STAMP),
            {
                "transforms": [
                    {
                        "header": header(STAMP, "odom"),
                        "child_frame_id": "base_link",
                        "transform": {
                            "translation": vector(POSE.x, POSE.y),
                            "rotation": pose(POSE)["orientation"],
                        },
                    }
                ]
            },
            c.read_transform,
            c.read_transform(c.transform(POSE, STAMP)),
        ),
        Case(
            "send goal request",
            f"{NAVIGATE_SEND_GOAL}_Request",
            c.send_goal_request(GOAL_ID, FRAME, POSE, STAMP),
            {
                "goal_id": uuid(GOAL_ID),
                "goal": {
                    "pose": {"header": header(STAMP, FRAME), "pose": pose(POSE)},
                    "behavior_tree": "",
                },
            },
            c.read_send_goal_request,
            c.read_send_goal_request(c.send_goal_request(GOAL_ID, FRAME, POSE, STAMP)),
        ),
        Case(
            "send goal response",
            f"{NAVIGATE_SEND_GOAL}_Response",
            c.send_goal_response(True, STAMP),
            {"accepted": True, "stamp": time_of(STAMP)},
            c.read_send_goal_response,
            True,
        ),
        Case(
            "get result request",
            f"{NAVIGATE_GET_RESULT}_Request",
            c.get_result_request(GOAL_ID),
            {"goal_id": uuid(GOAL_ID)},
            c.read_get_result_request,
            GOAL_ID,
        ),
        Case(
            "get result response",
            f"{NAVIGATE_GET_RESULT}_Response",
            c.get_result_response(GoalStatus.ABORTED, 208, LONG_TEXT),
            {"status": 6, "result": {"error_code": 208, "error_msg": LONG_TEXT}},
            lambda raw: tuple(c.read_get_result_response(raw)),
            (GoalStatus.ABORTED, 208, LONG_TEXT),
        ),
        Case(
            "feedback",
            f"{NAVIGATE_FEEDBACK}",
            c.feedback(GOAL_ID, POSE, 1.5, 3.25, FRAME, STAMP),
            {
                "goal_id": uuid(GOAL_ID),
                "feedback": {
                    "current_pose": {"header": header(STAMP, FRAME), "pose": pose(POSE)},
                    "navigation_time": time_of(3.25),
                    "estimated_time_remaining": time_of(0.0),
                    "number_of_recoveries": 0,
                    "distance_remaining": 1.5,
                },
            },
            lambda raw: tuple(c.read_feedback(raw)),
            tuple(c.read_feedback(c.feedback(GOAL_ID, POSE, 1.5, 3.25, FRAME, STAMP))),
        ),
        Case(
            "speed limit",
            SPEED_LIMIT,
            c.speed_limit(0.35, STAMP),
            {"header": header(STAMP, ""), "percentage": False, "speed_limit": 0.35},
            c.read_speed_limit,
            (0.35, False),
        ),
        Case(
            "cancel every goal",
            f"{CANCEL_GOAL}_Request",
            c.cancel_goal_request(),
            {"goal_info": goal_info(CANCEL_ALL)},
            lambda raw: tuple(c.read_cancel_goal_request(raw)),
            (CANCEL_ALL, 0.0),
        ),
        Case(
            "cancel one goal by stamp",
            f"{CANCEL_GOAL}_Request",
            c.cancel_goal_request(GOAL_ID, STAMP),
            {"goal_info": goal_info(GOAL_ID, STAMP)},
            lambda raw: tuple(c.read_cancel_goal_request(raw)),
            (GOAL_ID, STAMP),
        ),
        Case(
            "cancel response, none canceling",
            f"{CANCEL_GOAL}_Response",
            c.cancel_goal_response(CancelCode.UNKNOWN_GOAL_ID),
            {"return_code": 2, "goals_canceling": []},
            lambda raw: tuple(c.read_cancel_goal_response(raw)),
            (CancelCode.UNKNOWN_GOAL_ID, ()),
        ),
        Case(
            "cancel response, 120 canceling",
            f"{CANCEL_GOAL}_Response",
            c.cancel_goal_response(CancelCode.NONE, tuple(status_ids)),
            {"return_code": 0, "goals_canceling": [goal_info(i) for i in status_ids]},
            lambda raw: tuple(c.read_cancel_goal_response(raw)),
            (CancelCode.NONE, tuple(status_ids)),
        ),
        Case(
            "status, empty",
            "action_msgs/msg/GoalStatusArray",
            c.goal_status_array([]),
            {"status_list": []},
            c.read_goal_status_array,
            [],
        ),
        Case(
            "status, 120 goals",
            "action_msgs/msg/GoalStatusArray",
            c.goal_status_array([(i, GoalStatus(n % 7)) for n, i in enumerate(status_ids)]),
            {
                "status_list": [
                    {"goal_info": goal_info(i), "status": n % 7} for n, i in enumerate(status_ids)
                ]
            },
            c.read_goal_status_array,
            [(i, GoalStatus(n % 7)) for n, i in enumerate(status_ids)],
        ),
        Case(
            "image",
            "sensor_msgs/msg/Image",
            c.image(64, 48, "rgb8", PIXELS, STAMP, FRAME),
            {
                "header": header(STAMP, FRAME),
                "height": 48,
                "width": 64,
                "encoding": "rgb8",
                "is_bigendian": 0,
                "step": 192,
                "data": list(PIXELS),
            },
            lambda raw: tuple(c.read_image(raw)),
            (64, 48, "rgb8", PIXELS),
        ),
        Case(
            "image, empty",
            "sensor_msgs/msg/Image",
            c.image(0, 0, "mono8", b"", 0.0, ""),
            {
                "header": header(0.0, ""),
                "height": 0,
                "width": 0,
                "encoding": "mono8",
                "is_bigendian": 0,
                "step": 0,
                "data": [],
            },
            lambda raw: tuple(c.read_image(raw)),
            (0, 0, "mono8", b""),
        ),
        Case(
            "compressed image, 100 kB",
            "sensor_msgs/msg/CompressedImage",
            c.compressed_image("rgb8; jpeg compressed bgr8", JPEG, STAMP, FRAME),
            {
                "header": header(STAMP, FRAME),
                "format": "rgb8; jpeg compressed bgr8",
                "data": list(JPEG),
            },
            lambda raw: tuple(c.read_compressed_image(raw)),
            ("rgb8; jpeg compressed bgr8", JPEG),
        ),
        Case(
            "compressed image, empty",
            "sensor_msgs/msg/CompressedImage",
            c.compressed_image("", b""),
            {"header": header(0.0, "camera"), "format": "", "data": []},
            lambda raw: tuple(c.read_compressed_image(raw)),
            ("", b""),
        ),
        Case(
            "occupancy grid, 173 x 61",
            "nav_msgs/msg/OccupancyGrid",
            c.occupancy_grid(GRID, STAMP),
            {
                "header": header(STAMP, FRAME),
                "info": {
                    "map_load_time": time_of(STAMP),
                    "resolution": 0.05000000074505806,  # as float32 holds it
                    "width": 173,
                    "height": 61,
                    "origin": pose(GRID.origin),
                },
                "data": [b - 256 if b > 127 else b for b in GRID.cells],
            },
            lambda raw: c.read_occupancy_grid(raw)._replace(resolution=0.05),
            GRID,
        ),
        Case(
            "occupancy grid, empty",
            "nav_msgs/msg/OccupancyGrid",
            c.occupancy_grid(OccupancyGrid(0, 0, 1.0, Pose2D(), b"", "map")),
            {
                "header": header(0.0, "map"),
                "info": {
                    "map_load_time": time_of(0.0),
                    "resolution": 1.0,
                    "width": 0,
                    "height": 0,
                    "origin": pose(Pose2D()),
                },
                "data": [],
            },
            c.read_occupancy_grid,
            OccupancyGrid(0, 0, 1.0, Pose2D(), b"", "map"),
        ),
    ]


CASES = cases()


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_voicectl_and_real_ros_write_and_read_the_same_cdr(oracle: Oracle, case: Case) -> None:
    read, _ = oracle.decode(case.ros_type, case.ours)
    assert read == case.values
    theirs = oracle.encode(case.ros_type, case.values)
    assert len(theirs) == len(case.ours)
    differ = [i for i, (a, b) in enumerate(zip(case.ours, theirs, strict=True)) if a != b]
    # Where the bytes differ, real ROS reads neither: padding it left uninitialised.
    _, unread_ours = oracle.decode(case.ros_type, case.ours, differ)
    _, unread_theirs = oracle.decode(case.ros_type, theirs, differ)
    assert unread_ours == differ
    assert unread_theirs == differ
    if case.read is not None:
        assert case.read(theirs) == case.read_as


def test_the_byte_check_catches_a_wrong_byte(oracle: Oracle) -> None:
    """The comparison above would fail on a codec that wrote one value wrong."""
    ours = bytearray(CODEC.twist(0.25, -1.5))
    ours[-1] ^= 0x40  # angular z's sign and exponent
    read, _ = oracle.decode("geometry_msgs/msg/Twist", bytes(ours))
    assert read != twist(0.25, -1.5)


HASHED = sorted(
    {
        "geometry_msgs/msg/Twist",
        "geometry_msgs/msg/TwistStamped",
        "nav_msgs/msg/Odometry",
        "nav_msgs/msg/OccupancyGrid",
        "tf2_msgs/msg/TFMessage",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
        "action_msgs/msg/GoalStatusArray",
        NAVIGATE_FEEDBACK,
        SPEED_LIMIT,
        *SERVICES,
    }
)
"""Every type voicectl puts a hash of into an rmw_zenoh key: its topics, the action's
services, feedback and status, the cancel."""


@pytest.mark.parametrize("distro", DISTROS)
@pytest.mark.parametrize("ros_type", HASHED)
def test_every_type_hash_voicectl_computes_is_rosidls(distro: str, ros_type: str) -> None:
    share = env_of(distro).share
    assert type_hashes(share, ros_type) == {type_hash(RosDistro.JAZZY, ros_type)}


def test_type_hashes_are_found_where_rosidl_writes_them() -> None:
    """The hash check reads the right files: a type the wheels lack has none."""
    share = env_of("kilted").share
    assert len(type_hashes(share, "geometry_msgs/msg/Twist")) == 1
    assert type_hashes(share, "geometry_msgs/msg/NoSuchType") == set()


ROLLING_HASHED = [NAVIGATE_FEEDBACK, NAVIGATE_SEND_GOAL, NAVIGATE_GET_RESULT]
"""Rolling's NavigateToPose: its feedback has two more fields (and so another hash); its
services do not carry the feedback (the same hashes as Jazzy's)."""


@pytest.mark.parametrize("ros_type", ROLLING_HASHED)
def test_rolling_s_navigate_to_pose_hashes_are_rosidls(ros_type: str) -> None:
    """No wheels carry Rolling: harness/ros2_env.py has rosidl (Kilted's) describe Nav2's
    main-branch NavigateToPose, and voicectl's Rolling hashes must be those."""
    described = env_of("kilted").described("rolling")
    assert type_hashes(described, ros_type) == {type_hash(RosDistro.ROLLING, ros_type)}
    if ros_type == NAVIGATE_FEEDBACK:
        assert type_hash(RosDistro.ROLLING, ros_type) != type_hash(RosDistro.JAZZY, ros_type)


@pytest.fixture(scope="module")
def kilted() -> Iterator[Oracle]:
    yield from oracle_of("kilted")


def test_rolling_s_feedback_is_read_and_written_as_real_ros_does(kilted: Oracle) -> None:
    """No wheels carry Rolling: its NavigateToPose is built into Kilted's venv under a
    package name of its own (harness/ros2_env.py), the same fields in the same order,
    which is all CDR carries. Real ROS's bytes, with tracking errors that are not zero,
    read in Rolling's layout; Jazzy's layout refuses them; voicectl's Rolling bytes read
    in real ROS as meant."""
    ros_type = f"{ROLLING_NAV2_MSGS}/action/NavigateToPose_FeedbackMessage"
    rolling = Ros2Codec(RosDistro.ROLLING)
    values = {
        "goal_id": uuid(GOAL_ID),
        "feedback": {
            "current_pose": {"header": header(STAMP, FRAME), "pose": pose(POSE)},
            "navigation_time": time_of(3.25),
            "estimated_time_remaining": time_of(7.5),
            "number_of_recoveries": 3,
            "distance_remaining": 1.5,
            "position_tracking_error": 0.125,
            "heading_tracking_error": -0.5,
        },
    }
    theirs = kilted.encode(ros_type, values)
    read = rolling.read_feedback(theirs)
    assert (read.goal_id, read.distance_remaining) == (GOAL_ID, 1.5)
    assert (read.pose.x, read.pose.y, read.pose.yaw) == pytest.approx((POSE.x, POSE.y, POSE.yaw))
    with pytest.raises(CdrError):
        CODEC.read_feedback(theirs)

    ours = rolling.feedback(GOAL_ID, POSE, 1.5, 3.25, FRAME, STAMP)
    decoded, _ = kilted.decode(ros_type, ours)
    feedback = values["feedback"]
    assert decoded == {
        **values,
        "feedback": {
            **feedback,
            "estimated_time_remaining": time_of(0.0),
            "number_of_recoveries": 0,
            "position_tracking_error": 0.0,
            "heading_tracking_error": 0.0,
        },
    }
