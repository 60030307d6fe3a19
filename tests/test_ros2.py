"""CDR encoding of the ROS 2 messages voicectl exchanges, on Humble and Jazzy."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voicectl.shared.errors import VoicectlError
from voicectl.shared.ros2 import (
    CANCEL_ALL,
    SAME_RESULT,
    CameraType,
    CancelCode,
    CdrError,
    CmdVelType,
    CompressedImage,
    GoalStatus,
    Pose2D,
    Ros2Codec,
    RosDistro,
    distro_from_hash,
    distro_of_result,
    type_hash,
    typestore,
)

NAV = "nav2_msgs/action/NavigateToPose"
GOAL_ID = bytes(range(1, 17))
OTHER_ID = bytes(range(101, 117))
HEADER = b"\x00\x01\x00\x00"


@pytest.fixture(params=list(RosDistro), ids=str)
def codec(request: pytest.FixtureRequest) -> Ros2Codec:
    distro: RosDistro = request.param
    return Ros2Codec(distro)


def same_pose(a: Pose2D, b: Pose2D) -> bool:
    yaw_error = math.remainder(a.yaw - b.yaw, 2 * math.pi)
    return (
        math.isclose(a.x, b.x, abs_tol=1e-9)
        and math.isclose(a.y, b.y, abs_tol=1e-9)
        and abs(yaw_error) < 1e-9
    )


# --- round trips ----------------------------------------------------------------------------


def test_twist(codec: Ros2Codec) -> None:
    assert codec.read_twist(codec.twist(0.25, -1.5)) == (0.25, -1.5)


@pytest.mark.parametrize("yaw", [0.0, 0.5, -2.0, math.pi - 1e-6, -math.pi + 1e-6])
def test_odometry(codec: Ros2Codec, yaw: float) -> None:
    pose = Pose2D(x=1.5, y=-2.25, yaw=yaw)
    odometry = codec.read_odometry(codec.odometry(pose, 0.5, -0.25, 1700000000.125))
    assert same_pose(odometry.pose, pose)
    assert (odometry.linear_x, odometry.angular_z) == (0.5, -0.25)
    assert odometry.stamp_s == pytest.approx(1700000000.125, abs=1e-6)


@pytest.mark.parametrize("frame", ["map", "odom", "base_link"])
def test_send_goal(codec: Ros2Codec, frame: str) -> None:
    pose = Pose2D(x=2.0, y=1.0, yaw=1.25)
    goal_id, got_frame, got_pose = codec.read_send_goal_request(
        codec.send_goal_request(GOAL_ID, frame, pose)
    )
    assert (goal_id, got_frame) == (GOAL_ID, frame)
    assert same_pose(got_pose, pose)
    assert codec.read_send_goal_response(codec.send_goal_response(True, 12.5)) is True
    assert codec.read_send_goal_response(codec.send_goal_response(False)) is False


def test_get_result(codec: Ros2Codec) -> None:
    assert codec.read_get_result_request(codec.get_result_request(GOAL_ID)) == GOAL_ID
    for status in GoalStatus:
        assert codec.read_get_result_response(codec.get_result_response(status)).status is status


def test_get_result_error_details_exist_on_jazzy_only() -> None:
    failed = (GoalStatus.ABORTED, 202, "no transform map -> base_link")
    jazzy = Ros2Codec(RosDistro.JAZZY)
    humble = Ros2Codec(RosDistro.HUMBLE)
    assert jazzy.read_get_result_response(jazzy.get_result_response(*failed)) == failed
    # Humble's Result is std_msgs/Empty: the details cannot travel, the status does.
    assert humble.read_get_result_response(humble.get_result_response(*failed)) == (
        GoalStatus.ABORTED,
        0,
        "",
    )


def test_feedback(codec: Ros2Codec) -> None:
    pose = Pose2D(x=0.5, y=0.25, yaw=-0.75)
    goal_id, got_pose, remaining = codec.read_feedback(
        codec.feedback(GOAL_ID, pose, distance_remaining=1.75, navigation_time_s=3.5)
    )
    assert goal_id == GOAL_ID
    assert same_pose(got_pose, pose)
    assert remaining == 1.75  # exact in float32


def test_cancel_goal(codec: Ros2Codec) -> None:
    assert codec.read_cancel_goal_request(codec.cancel_goal_request()) == (CANCEL_ALL, 0.0)
    request = codec.read_cancel_goal_request(codec.cancel_goal_request(GOAL_ID, 5.25))
    assert request == (GOAL_ID, 5.25)
    response = codec.cancel_goal_response(CancelCode.NONE, (GOAL_ID, OTHER_ID))
    assert codec.read_cancel_goal_response(response) == (CancelCode.NONE, (GOAL_ID, OTHER_ID))
    rejected = codec.read_cancel_goal_response(codec.cancel_goal_response(CancelCode.REJECTED))
    assert rejected == (CancelCode.REJECTED, ())


def test_goal_status_array(codec: Ros2Codec) -> None:
    statuses = [(GOAL_ID, GoalStatus.SUCCEEDED), (OTHER_ID, GoalStatus.EXECUTING)]
    assert codec.read_goal_status_array(codec.goal_status_array(statuses)) == statuses
    assert codec.read_goal_status_array(codec.goal_status_array([])) == []


def test_image(codec: Ros2Codec) -> None:
    data = bytes(range(256)) * 36  # 64 x 48 x 3
    assert codec.read_image(codec.image(64, 48, "rgb8", data)) == (64, 48, "rgb8", data)


def test_twist_stamped_and_the_velocity_of_either_type(codec: Ros2Codec) -> None:
    assert codec.read_twist_stamped(codec.twist_stamped(0.25, -1.5, 12.5)) == (0.25, -1.5)
    for kind in CmdVelType:
        payload = codec.velocity(kind, 0.3, 0.2, 5.0)
        assert codec.read_velocity(kind, payload) == (0.3, 0.2)
    assert codec.velocity(CmdVelType.TWIST, 0.3, 0.2) == codec.twist(0.3, 0.2)
    with pytest.raises(CdrError):  # a robot that takes one cannot read the other
        codec.read_twist_stamped(codec.twist(0.3, 0.2))


def test_compressed_image(codec: Ros2Codec) -> None:
    jpeg = b"\xff\xd8\xff\xe0" + bytes(range(40))
    frame = codec.read_compressed_image(codec.compressed_image("rgb8; jpeg compressed bgr8", jpeg))
    assert frame == CompressedImage(format="rgb8; jpeg compressed bgr8", data=jpeg)


def test_message_types_are_known_by_the_names_bridge_tokens_give() -> None:
    assert CmdVelType.of("geometry_msgs/msg/TwistStamped") is CmdVelType.STAMPED
    assert CmdVelType.of("geometry_msgs/msg/Twist") is CmdVelType.TWIST
    assert CmdVelType.of("std_msgs/msg/String") is None
    assert CameraType.of("sensor_msgs/msg/CompressedImage") is CameraType.COMPRESSED
    assert CameraType.of("sensor_msgs/msg/Image") is CameraType.RAW


@pytest.mark.parametrize("status", [GoalStatus.UNKNOWN, GoalStatus.SUCCEEDED, GoalStatus.ABORTED])
def test_any_get_result_reply_tells_its_distro(codec: Ros2Codec, status: GoalStatus) -> None:
    """Even the reply for a goal the server does not know, which is how the executor
    finds out before its first goal."""
    told = distro_of_result(codec.get_result_response(status))
    assert told is SAME_RESULT.get(codec.distro, codec.distro)


def test_a_get_result_reply_in_no_known_layout_says_so() -> None:
    with pytest.raises(CdrError, match="3 bytes fit no known NavigateToPose result layout"):
        distro_of_result(b"\x00\x01\x00")


# --- the bytes on the wire ------------------------------------------------------------------


def every_message(codec: Ros2Codec) -> dict[str, bytes]:
    pose = Pose2D(x=1.0, y=2.0, yaw=0.5)
    return {
        "twist": codec.twist(0.5, 0.1),
        "odometry": codec.odometry(pose, 0.5, 0.1, 10.0),
        "send_goal_request": codec.send_goal_request(GOAL_ID, "map", pose),
        "send_goal_response": codec.send_goal_response(True, 10.0),
        "get_result_request": codec.get_result_request(GOAL_ID),
        "get_result_response": codec.get_result_response(GoalStatus.SUCCEEDED),
        "feedback": codec.feedback(GOAL_ID, pose, 1.0, 2.0),
        "cancel_goal_request": codec.cancel_goal_request(GOAL_ID),
        "cancel_goal_response": codec.cancel_goal_response(CancelCode.NONE, (GOAL_ID,)),
        "goal_status_array": codec.goal_status_array([(GOAL_ID, GoalStatus.EXECUTING)]),
        "image": codec.image(2, 1, "rgb8", b"\x01\x02\x03\x04\x05\x06"),
        "twist_stamped": codec.twist_stamped(0.5, 0.1, 10.0),
        "compressed_image": codec.compressed_image("rgb8; jpeg compressed bgr8", b"\xff\xd8"),
    }


def test_every_payload_starts_with_the_little_endian_cdr_header(codec: Ros2Codec) -> None:
    for name, payload in every_message(codec).items():
        assert payload[:4] == HEADER, name


def expected_messages(distro: RosDistro) -> dict[str, tuple[Any, str]]:
    """The messages of `every_message`, built field by field with rosbags' own classes."""
    t = typestore(distro).types

    def time(sec: int) -> Any:
        return t["builtin_interfaces/msg/Time"](sec=sec, nanosec=0)

    def duration(sec: int) -> Any:
        return t["builtin_interfaces/msg/Duration"](sec=sec, nanosec=0)

    def uuid(raw: bytes) -> Any:
        return t["unique_identifier_msgs/msg/UUID"](uuid=np.frombuffer(raw, dtype=np.uint8))

    def info(raw: bytes) -> Any:
        return t["action_msgs/msg/GoalInfo"](goal_id=uuid(raw), stamp=time(0))

    def header(sec: int, frame: str) -> Any:
        return t["std_msgs/msg/Header"](stamp=time(sec), frame_id=frame)

    def vector(x: float, y: float, z: float) -> Any:
        return t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)

    twist = t["geometry_msgs/msg/Twist"](linear=vector(0.5, 0, 0), angular=vector(0, 0, 0.1))
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](
            x=0.0, y=0.0, z=math.sin(0.25), w=math.cos(0.25)
        ),
    )
    zeros = np.zeros(36, dtype=np.float64)
    rolling: dict[str, float] = {}
    if distro is RosDistro.ROLLING:
        rolling = {"position_tracking_error": 0.0, "heading_tracking_error": 0.0}
    if distro is RosDistro.HUMBLE:
        result = t[f"{NAV}_Result"](result=t["std_msgs/msg/Empty"]())
    else:
        result = t[f"{NAV}_Result"](error_code=0, error_msg="")
    return {
        "twist": (twist, "geometry_msgs/msg/Twist"),
        "odometry": (
            t["nav_msgs/msg/Odometry"](
                header=header(10, "odom"),
                child_frame_id="base_link",
                pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zeros),
                twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zeros),
            ),
            "nav_msgs/msg/Odometry",
        ),
        "send_goal_request": (
            t[f"{NAV}_SendGoal_Request"](
                goal_id=uuid(GOAL_ID),
                goal=t[f"{NAV}_Goal"](
                    pose=t["geometry_msgs/msg/PoseStamped"](header=header(0, "map"), pose=pose),
                    behavior_tree="",
                ),
            ),
            f"{NAV}_SendGoal_Request",
        ),
        "send_goal_response": (
            t[f"{NAV}_SendGoal_Response"](accepted=True, stamp=time(10)),
            f"{NAV}_SendGoal_Response",
        ),
        "get_result_request": (
            t[f"{NAV}_GetResult_Request"](goal_id=uuid(GOAL_ID)),
            f"{NAV}_GetResult_Request",
        ),
        "get_result_response": (
            t[f"{NAV}_GetResult_Response"](status=4, result=result),
            f"{NAV}_GetResult_Response",
        ),
        "feedback": (
            t[f"{NAV}_FeedbackMessage"](
                goal_id=uuid(GOAL_ID),
                feedback=t[f"{NAV}_Feedback"](
                    current_pose=t["geometry_msgs/msg/PoseStamped"](
                        header=header(0, "map"), pose=pose
                    ),
                    navigation_time=duration(2),
                    estimated_time_remaining=duration(0),
                    number_of_recoveries=0,
                    distance_remaining=1.0,
                    **rolling,
                ),
            ),
            f"{NAV}_FeedbackMessage",
        ),
        "cancel_goal_request": (
            t["action_msgs/srv/CancelGoal_Request"](goal_info=info(GOAL_ID)),
            "action_msgs/srv/CancelGoal_Request",
        ),
        "cancel_goal_response": (
            t["action_msgs/srv/CancelGoal_Response"](
                return_code=0, goals_canceling=[info(GOAL_ID)]
            ),
            "action_msgs/srv/CancelGoal_Response",
        ),
        "goal_status_array": (
            t["action_msgs/msg/GoalStatusArray"](
                status_list=[t["action_msgs/msg/GoalStatus"](goal_info=info(GOAL_ID), status=2)]
            ),
            "action_msgs/msg/GoalStatusArray",
        ),
        "image": (
            t["sensor_msgs/msg/Image"](
                header=header(0, "camera"),
                height=1,
                width=2,
                encoding="rgb8",
                is_bigendian=0,
                step=6,
                data=np.arange(1, 7, dtype=np.uint8),
            ),
            "sensor_msgs/msg/Image",
        ),
        "twist_stamped": (
            t["geometry_msgs/msg/TwistStamped"](header=header(10, "base_link"), twist=twist),
            "geometry_msgs/msg/TwistStamped",
        ),
        "compressed_image": (
            t["sensor_msgs/msg/CompressedImage"](
                header=header(0, "camera"),
                format="rgb8; jpeg compressed bgr8",
                data=np.array([0xFF, 0xD8], dtype=np.uint8),
            ),
            "sensor_msgs/msg/CompressedImage",
        ),
    }


def test_bytes_equal_rosbags_serialization_of_the_same_message(codec: Ros2Codec) -> None:
    store = typestore(codec.distro)
    expected = expected_messages(codec.distro)
    got = every_message(codec)
    assert got.keys() == expected.keys()
    for name, (message, typename) in expected.items():
        assert got[name] == bytes(store.serialize_cdr(message, typename, little_endian=True)), name


def test_humble_and_jazzy_results_differ_on_the_wire() -> None:
    humble = Ros2Codec(RosDistro.HUMBLE).get_result_response(GoalStatus.SUCCEEDED)
    jazzy = Ros2Codec(RosDistro.JAZZY).get_result_response(GoalStatus.SUCCEEDED)
    assert humble != jazzy
    # Humble: int8 status, then std_msgs/Empty's one placeholder byte.
    assert humble == HEADER + b"\x04\x00"
    # Jazzy: int8 status, pad to 2, uint16 error_code, string error_msg (length 1: the NUL).
    assert jazzy == HEADER + b"\x04\x00" + b"\x00\x00" + b"\x01\x00\x00\x00" + b"\x00"
    tf_error = Ros2Codec(RosDistro.JAZZY).get_result_response(GoalStatus.ABORTED, 202, "tf")
    assert (
        tf_error == HEADER + b"\x06\x00" + (202).to_bytes(2, "little") + b"\x03\x00\x00\x00tf\x00"
    )


def test_twist_layout_is_six_little_endian_doubles() -> None:
    payload = Ros2Codec().twist(0.5, -1.0)
    values = np.frombuffer(payload[4:], dtype="<f8")
    assert values.tolist() == [0.5, 0.0, 0.0, 0.0, 0.0, -1.0]


def test_a_humble_result_does_not_decode_as_jazzy() -> None:
    humble = Ros2Codec(RosDistro.HUMBLE).get_result_response(GoalStatus.SUCCEEDED)
    with pytest.raises(CdrError):
        Ros2Codec(RosDistro.JAZZY).read_get_result_response(humble)


# --- bad input ------------------------------------------------------------------------------


def test_encoding_rejects_bad_arguments_with_clear_errors() -> None:
    codec = Ros2Codec()
    with pytest.raises(ValueError, match="16 bytes, not 4"):
        codec.get_result_request(b"abcd")
    with pytest.raises(ValueError, match="expected"):
        codec.image(2, 2, "rgb8", b"\x00" * 5)
    with pytest.raises(ValueError, match="not supported"):
        codec.image(1, 1, "yuv422", b"\x00\x00")
    with pytest.raises(ValueError, match="7"):
        codec.get_result_response(7)
    with pytest.raises(ValueError, match="uint16"):
        codec.get_result_response(GoalStatus.ABORTED, error_code=70000)


def test_cdr_error_is_a_voicectl_error_that_names_the_type() -> None:
    with pytest.raises(VoicectlError, match="nav_msgs/msg/Odometry"):
        Ros2Codec().read_odometry(HEADER + b"\x01\x02")


def test_unknown_status_value_is_a_cdr_error() -> None:
    payload = bytearray(Ros2Codec().goal_status_array([(GOAL_ID, GoalStatus.EXECUTING)]))
    payload[-1] = 42  # the int8 status is the last byte
    with pytest.raises(CdrError, match="goal status 42"):
        Ros2Codec().read_goal_status_array(bytes(payload))


READERS = [
    "read_twist",
    "read_odometry",
    "read_send_goal_request",
    "read_send_goal_response",
    "read_get_result_request",
    "read_get_result_response",
    "read_feedback",
    "read_cancel_goal_request",
    "read_cancel_goal_response",
    "read_goal_status_array",
    "read_image",
    "read_twist_stamped",
    "read_compressed_image",
]
CODECS = {distro: Ros2Codec(distro) for distro in RosDistro}
SAMPLES = [payload for codec in CODECS.values() for payload in every_message(codec).values()]


@st.composite
def damaged_message(draw: st.DrawFn) -> bytes:
    """A real message cut short or with one byte changed."""
    sample = draw(st.sampled_from(SAMPLES))
    at = draw(st.integers(0, len(sample) - 1))
    if draw(st.booleans()):
        return sample[:at]
    return sample[:at] + bytes([draw(st.integers(0, 255))]) + sample[at + 1 :]


@settings(max_examples=400, deadline=None)
@given(
    distro=st.sampled_from(list(RosDistro)),
    reader=st.sampled_from(READERS),
    payload=st.one_of(
        st.binary(max_size=64), st.binary(max_size=256).map(HEADER.__add__), damaged_message()
    ),
)
def test_readers_raise_only_cdr_error_on_arbitrary_bytes(
    distro: RosDistro, reader: str, payload: bytes
) -> None:
    read: Callable[[bytes], object] = getattr(CODECS[distro], reader)
    with contextlib.suppress(CdrError):  # anything else fails the test
        read(payload)


@pytest.mark.parametrize("distro", list(RosDistro))
def test_transform_carries_the_pose_as_rosbags_would_encode_it(distro: RosDistro) -> None:
    codec = Ros2Codec(distro)
    pose = Pose2D(x=1.5, y=-2.0, yaw=2.5)
    raw = codec.transform(pose, 12.25)
    ((parent, child, read),) = codec.read_transform(raw)
    assert (parent, child) == ("odom", "base_link")
    assert (read.x, read.y) == (1.5, -2.0)
    assert read.yaw == pytest.approx(2.5)

    store = typestore(distro)
    t = store.types
    message = t["tf2_msgs/msg/TFMessage"](
        transforms=[
            t["geometry_msgs/msg/TransformStamped"](
                header=t["std_msgs/msg/Header"](
                    stamp=t["builtin_interfaces/msg/Time"](sec=12, nanosec=250_000_000),
                    frame_id="odom",
                ),
                child_frame_id="base_link",
                transform=t["geometry_msgs/msg/Transform"](
                    translation=t["geometry_msgs/msg/Vector3"](x=1.5, y=-2.0, z=0.0),
                    rotation=t["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(1.25), w=math.cos(1.25)
                    ),
                ),
            )
        ]
    )
    expected = bytes(store.serialize_cdr(message, "tf2_msgs/msg/TFMessage", little_endian=True))
    assert raw == expected


def test_rolling_feedback_has_two_more_fields_and_a_hash_of_its_own() -> None:
    """Rolling's NavigateToPose feedback is Jazzy's plus two float32: neither reads the
    other's, and the hash a robot announces for it names the distribution."""
    jazzy, rolling = Ros2Codec(RosDistro.JAZZY), Ros2Codec(RosDistro.ROLLING)
    pose = Pose2D(1.0, 2.0, 0.5)
    ours = rolling.feedback(GOAL_ID, pose, 1.5, 2.0)
    assert len(ours) == len(jazzy.feedback(GOAL_ID, pose, 1.5, 2.0)) + 8
    assert rolling.read_feedback(ours).distance_remaining == 1.5
    with pytest.raises(CdrError):
        jazzy.read_feedback(ours)
    with pytest.raises(CdrError):
        rolling.read_feedback(jazzy.feedback(GOAL_ID, pose, 1.5, 2.0))
    feedback = "nav2_msgs/action/NavigateToPose_FeedbackMessage"
    assert type_hash(RosDistro.ROLLING, feedback) != type_hash(RosDistro.JAZZY, feedback)
    for distro in (RosDistro.JAZZY, RosDistro.ROLLING):
        assert distro_from_hash(feedback, type_hash(distro, feedback)) is distro
    # A Twist is the same in both: its hash tells only that it is not Humble's.
    twist = "geometry_msgs/msg/Twist"
    assert distro_from_hash(twist, type_hash(RosDistro.JAZZY, twist)) is None
    assert distro_from_hash(twist, "TypeHashNotSupported") is RosDistro.HUMBLE
    assert distro_from_hash(twist, "RIHS01_" + "0" * 64) is None
    # Its result is Jazzy's: a get_result reply names Jazzy.
    assert distro_of_result(rolling.get_result_response(GoalStatus.SUCCEEDED)) is RosDistro.JAZZY
