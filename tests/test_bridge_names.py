"""How voicectl names a robot's ROS interfaces the way zenoh-bridge-ros2dds does: keys
under a namespace, names ROS accepts, and the liveliness tokens the bridge announces."""

from __future__ import annotations

import pytest

from voicectl.shared.robot.keys import BridgeKind, BridgeToken, RobotNames, check_ros_name


def test_remapped_names_become_keys_under_the_namespace() -> None:
    keys = RobotNames(
        "/bot1",
        cmd_vel_name="/diff_drive_controller/cmd_vel",
        camera_name="front/image_raw/compressed",
        navigate_name="nav/navigate_to_pose",
    )
    assert keys.namespace == "bot1"
    assert keys.cmd_vel == "bot1/diff_drive_controller/cmd_vel"
    assert keys.odom == "bot1/odom"
    assert keys.camera_image == "bot1/front/image_raw/compressed"
    assert keys.navigate("send_goal") == "bot1/nav/navigate_to_pose/_action/send_goal"
    assert RobotNames().navigate("get_result") == "navigate_to_pose/_action/get_result"


@pytest.mark.parametrize("name", ["bot1", "/a/b_c", "_hidden", "a1/b2/", ""])
def test_ros_names_are_accepted_without_their_slashes(name: str) -> None:
    assert check_ros_name(name, "topic") == name.strip("/")


@pytest.mark.parametrize(
    ("name", "part"),
    [("bot-1", "bot-1"), ("a/1b", "1b"), ("a//b", ""), ("a.b", "a.b"), ("x/a__b", "a__b")],
)
def test_names_ros_refuses_are_refused_naming_the_part(name: str, part: str) -> None:
    expected = (
        f"ROS namespace {name!r}: {part!r} is not a ROS 2 name; use letters, digits and "
        "single '_', not starting with a digit ('-' and '.' are not allowed)"
    )
    with pytest.raises(ValueError, match="is not a ROS 2 name") as refused:
        check_ros_name(name, "ROS namespace")
    assert str(refused.value) == expected


def test_an_empty_topic_name_is_refused() -> None:
    with pytest.raises(ValueError, match="cmd_vel name must not be empty"):
        RobotNames(cmd_vel_name="/")


def test_bridge_tokens_read_back_as_written() -> None:
    token = BridgeToken(
        BridgeKind.SUBSCRIBER,
        "bot1/diff_drive_controller/cmd_vel",
        "geometry_msgs/msg/TwistStamped",
    )
    key = token.token_key("ab12")
    assert key == (
        "@/ab12/@ros2_lv/MS/bot1§diff_drive_controller§cmd_vel/"
        "geometry_msgs§msg§TwistStamped/:1:0:0,10"
    )
    assert BridgeToken.parse(key) == token
    action = BridgeToken(BridgeKind.ACTION_SERVER, "nav", "nav2_msgs/action/NavigateToPose")
    assert action.token_key("ab12") == "@/ab12/@ros2_lv/AS/nav/nav2_msgs§action§NavigateToPose"
    assert BridgeToken.parse(action.token_key("ab12")) == action


def test_a_jazzy_bridge_token_with_a_type_hash_still_reads() -> None:
    key = (
        "@/ab12/@ros2_lv/MP/odom/nav_msgs§msg§Odometry/"
        ":1:0:0,10:typehash=RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    )
    assert BridgeToken.parse(key) == BridgeToken(
        BridgeKind.PUBLISHER, "odom", "nav_msgs/msg/Odometry"
    )


@pytest.mark.parametrize(
    "key",
    ["@/ab12/@ros2_lv", "voice/r1/alive/executor", "@/ab12/@ros2_lv/ZZ/odom/nav_msgs§msg§Odometry"],
)
def test_other_keys_are_not_bridge_tokens(key: str) -> None:
    assert BridgeToken.parse(key) is None
