"""rmw_zenoh's wire layout, and voicectl speaking it on a real router.

Pinned byte for byte: keys, tokens, type hashes, GIDs and the attachment's encoding (at a
fixed time). On a router: a publication's exact key, payload and attachment (sequence
numbers, the GID of its publisher's token); a service call's key (the exact one, as
rmw_zenoh's clients ask, and only of complete queryables), payload and attachment (its
sequence number, the GID of its client's token; the time is the call's own); an action's
status kept for a late client; a reply's echo of the request's sequence number and
GID; the seam's action client (shared/robot/action.py) against an action server.

The expected values were worked out from ros2/rmw_zenoh's docs/design.md and its
rmw_zenoh_cpp sources as released for Jazzy (0.2.10), Kilted (0.6.7) and Humble (0.1.9):
liveliness_utils.cpp (keys, tokens, GIDs), attachment_helpers.cpp (the attachment, written
with zenoh-cpp's serializer), rmw_service_data.cpp (replies). Where the design document
itself gives a key or a token, it is quoted as it stands there. The GIDs were computed with
rmw_zenoh's own XXH3 code (simplified_xxhash3.cpp) from the tokens below.
No ROS 2 runs here: what these values are checked against is that source, not a robot.
"""

from __future__ import annotations

import asyncio

import pytest
import zenoh
from zenoh.ext import Int64, z_serialize

from harness.wait import async_wait_until
from voicectl.shared.errors import BusError
from voicectl.shared.messages import ExecutorInfo
from voicectl.shared.robot import Interface, Role, TransportKind, open_transport
from voicectl.shared.robot.action import ActionClient, Cancelled
from voicectl.shared.robot.keys import RMW_QOS_DEFAULT, RmwKind, RmwToken, RmwZenohKeys
from voicectl.shared.robot.rmw_zenoh import Attachment, RmwZenohTransport, gid_of
from voicectl.shared.robot.stop import RobotStop
from voicectl.shared.ros2 import (
    CANCEL_GOAL,
    NAVIGATE_FEEDBACK,
    NAVIGATE_GET_RESULT,
    NAVIGATE_SEND_GOAL,
    CancelCode,
    GoalStatus,
    Pose2D,
    Ros2Codec,
    RosDistro,
    dds_type_name,
    describe_service,
    hash_store,
    ros_type_of,
    type_hash,
)

from .support import joined

ZID = "1f2e3d4c5b6a79880123456789abcdef"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
SEND_GOAL_HASH = "RIHS01_a4fcb3bee1bf32e21a0e541a943b221aa0826996e2c98f079b47022b256f48b5"


# --- types ---------------------------------------------------------------------------------


def test_types_are_named_as_dds_names_them() -> None:
    assert dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"
    assert dds_type_name(NAVIGATE_SEND_GOAL) == "nav2_msgs::action::dds_::NavigateToPose_SendGoal_"
    assert ros_type_of("action_msgs::srv::dds_::CancelGoal_") == CANCEL_GOAL


def test_type_hashes_are_rosidl_s() -> None:
    jazzy = RosDistro.JAZZY
    # Messages: what rosbags computes, the values rmw_zenoh-based tools publish.
    assert type_hash(jazzy, "geometry_msgs/msg/Twist") == TWIST_HASH
    assert type_hash(jazzy, "nav_msgs/msg/Odometry") == (
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    )
    assert type_hash(jazzy, "action_msgs/msg/GoalStatusArray") == (
        "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e"
    )
    # A service is hashed as rosidl describes it (request, response, event) with .msg's
    # char read as uint8: rosbags alone gets every service wrong. CancelGoal's hash is the
    # one `ros2 action info -v` prints on Jazzy.
    assert type_hash(jazzy, CANCEL_GOAL) == (
        "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a"
    )
    # Nav2's action parts, by the same computation (no published value was found: check
    # one with `ros2 action info -v /navigate_to_pose` on a robot, docs/deploy.md).
    assert type_hash(jazzy, NAVIGATE_SEND_GOAL) == SEND_GOAL_HASH
    assert type_hash(RosDistro.HUMBLE, "geometry_msgs/msg/Twist") == "TypeHashNotSupported"


def test_the_service_hash_matches_the_one_in_rmw_zenoh_s_design_document() -> None:
    """The design document's example key carries example_interfaces' AddTwoInts hash."""
    store = hash_store(RosDistro.JAZZY)
    store.register(
        {
            "example_interfaces/srv/AddTwoInts_Request": (
                [],
                [("a", (1, ("int64", 0))), ("b", (1, ("int64", 0)))],
            ),
            "example_interfaces/srv/AddTwoInts_Response": ([], [("sum", (1, ("int64", 0)))]),
        }
    )
    describe_service(store, "example_interfaces/srv/AddTwoInts")
    key = RmwZenohKeys(2).data(
        "/add_two_ints",
        dds_type_name("example_interfaces/srv/AddTwoInts"),
        store.hash_rihs01("example_interfaces/srv/AddTwoInts"),
    )
    assert key == (
        "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/"
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
    )


# --- keys, tokens, attachments -------------------------------------------------------------


def test_data_keys() -> None:
    keys = RmwZenohKeys(0)
    twist = dds_type_name("geometry_msgs/msg/Twist")
    assert keys.data("cmd_vel", twist, TWIST_HASH) == (
        f"0/cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}"
    )
    assert keys.data("/bot1/cmd_vel/", twist, TWIST_HASH).startswith("0/bot1/cmd_vel/geometry")
    assert (
        keys.data_any_hash("bot1/cmd_vel", twist)
        == "0/bot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/*"
    )


def test_tokens_as_rmw_zenoh_s_design_document_shows_them() -> None:
    keys = RmwZenohKeys(0)
    zid = "aac3178e146ba6f1fc6e6a4085e77f21"
    node = RmwToken(zid, 0, 0, RmwKind.NODE, "", "listener")
    assert keys.token(node) == f"@ros2_lv/0/{zid}/0/0/NN/%/%/listener"
    subscriber = RmwToken(
        zid,
        0,
        10,
        RmwKind.SUBSCRIBER,
        "",
        "listener",
        "chatter",
        "std_msgs::msg::dds_::String_",
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    )
    text = (
        f"@ros2_lv/0/{zid}/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/"
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
    )
    assert keys.token(subscriber) == text
    assert keys.parse_token(text) == subscriber
    assert keys.parse_token(keys.token(node)) == node
    # A namespace and a name with slashes are one chunk each, '/' written '%'.
    remapped = RmwToken(
        ZID,
        8,
        9,
        RmwKind.PUBLISHER,
        "bot1",
        "voicectl_executor",
        "bot1/a/cmd_vel",
        "geometry_msgs::msg::dds_::Twist_",
        TWIST_HASH,
        RMW_QOS_DEFAULT,
    )
    assert keys.token(remapped) == (
        f"@ros2_lv/0/{ZID}/8/9/MP/%/%bot1/voicectl_executor/%bot1%a%cmd_vel/"
        f"geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}/::,10:,:,:,,"
    )
    assert keys.parse_token(keys.token(remapped)) == remapped
    assert keys.parse_token("@ros2_lv/1/x/0/0/NN/%/%/n") is None  # another domain


def test_the_attachment_and_the_gid() -> None:
    token = (
        f"@ros2_lv/0/{ZID}/0/1/MP/%/%/voicectl_executor/%cmd_vel/"
        f"geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}/::,10:,:,:,,"
    )
    gid = gid_of(token)
    assert gid.hex() == "ad643850b4422c290924d802ea94c8e0"
    raw = Attachment(1, 1_700_000_000_123_456_789, gid).encode()
    assert raw.hex() == (
        "0100000000000000"  # sequence number, int64 little-endian
        "15cd853dfe9c9717"  # source timestamp, ns since the epoch
        "10"  # the GID's length, as zenoh's serializer writes a sequence
        "ad643850b4422c290924d802ea94c8e0"
    )
    # What zenoh-cpp's serializer (rmw_zenoh's) writes is zenoh's one format.
    assert raw == z_serialize((Int64(1), Int64(1_700_000_000_123_456_789), gid)).to_bytes()
    assert Attachment.decode(raw) == Attachment(1, 1_700_000_000_123_456_789, gid)


# --- on a real router ------------------------------------------------------------------------


async def test_a_publication_and_a_service_call_carry_what_rmw_zenoh_needs(router: str) -> None:
    with joined(router) as bus:
        session = bus.session
        seen: list[zenoh.Sample] = []
        asked: list[tuple[str, bytes, bytes]] = []
        twist_key = RmwZenohKeys(0).data(
            "bot1/cmd_vel", dds_type_name("geometry_msgs/msg/Twist"), TWIST_HASH
        )
        goal_key = RmwZenohKeys(0).data(
            "bot1/navigate_to_pose/_action/send_goal",
            dds_type_name(NAVIGATE_SEND_GOAL),
            SEND_GOAL_HASH,
        )
        codec = Ros2Codec()

        def on_goal(query: zenoh.Query) -> None:  # a robot's rmw_zenoh action server
            attachment = query.attachment.to_bytes() if query.attachment else b""
            payload = query.payload.to_bytes() if query.payload else b""
            asked.append((str(query.key_expr), payload, attachment))
            reply = Attachment(Attachment.decode(attachment).sequence, 1, bytes(16)).encode()
            query.reply(query.key_expr, codec.send_goal_response(True, 1.0), attachment=reply)

        subscriber = session.declare_subscriber(twist_key, seen.append)
        queryable = session.declare_queryable(goal_key, on_goal, complete=True)
        try:
            transport = open_transport(
                bus, TransportKind.RMW_ZENOH, "voicectl_executor", "bot1", 0, RosDistro.JAZZY
            )
            assert isinstance(transport, RmwZenohTransport)
            await async_wait_until(
                lambda: session.liveliness().get(f"@ros2_lv/0/{session.zid()}/**", timeout=1),
                5.0,
                "the node's token",
            )
            for _ in range(2):
                transport.publish("bot1/cmd_vel", "geometry_msgs/msg/Twist", codec.twist(0.5, 0.0))
            await async_wait_until(lambda: len(seen) == 2, 5.0, "two samples on the exact key")
            first, second = (Attachment.decode(s.attachment.to_bytes()) for s in seen)
            assert (first.sequence, second.sequence) == (1, 2)
            assert first.gid == second.gid
            assert seen[0].payload.to_bytes() == codec.twist(0.5, 0.0)

            request = codec.send_goal_request(bytes(range(16)), "map", Pose2D(1.0, 2.0, 0.0))
            reply = await transport.call(
                "bot1/navigate_to_pose/_action/send_goal", NAVIGATE_SEND_GOAL, request, 5.0
            )
            assert codec.read_send_goal_response(reply)
            ((key, payload, attachment),) = asked
            # A call asks the exact key, as rmw_zenoh's own clients do. The payload is the
            # request as it was given.
            assert key == goal_key
            assert payload == request
            assert len(attachment) == 33
            assert attachment[16] == 0x10  # the GID's length, before the GID
            client = Attachment.decode(attachment)
            assert client.sequence == 1
            # The tokens say who sent them: the node, its publisher and its client.
            tokens = {
                str(r.ok.key_expr)
                for r in session.liveliness().get(f"@ros2_lv/0/{session.zid()}/**", timeout=2)
                if r.ok is not None
            }
            node = f"@ros2_lv/0/{session.zid()}/0/0/NN/%/%bot1/voicectl_executor"
            assert node in tokens
            [publisher] = [t for t in tokens if "/MP/" in t]
            assert publisher.endswith(
                f"%bot1%cmd_vel/geometry_msgs::msg::dds_::Twist_/{TWIST_HASH}/::,10:,:,:,,"
            )
            assert gid_of(publisher) == first.gid
            [client_token] = [t for t in tokens if "/SC/" in t]
            assert gid_of(client_token) == client.gid
        finally:
            subscriber.undeclare()
            queryable.undeclare()


async def test_a_served_service_echoes_the_client_in_its_reply_and_discovery_sees_both(
    router: str,
) -> None:
    with joined(router) as bus, joined(router) as robot_bus:
        robot = open_transport(robot_bus, TransportKind.RMW_ZENOH, "voicectl_sim", "")
        codec = Ros2Codec()

        async def cancel(_raw: bytes) -> bytes:
            return codec.cancel_goal_response(0)

        robot.serve("navigate_to_pose/_action/cancel_goal", CANCEL_GOAL, cancel)
        robot.offer(Interface(Role.SUBSCRIBER, "cmd_vel", "geometry_msgs/msg/TwistStamped"))
        executor = open_transport(bus, TransportKind.RMW_ZENOH, "voicectl_executor", "")
        found: list[Interface] = []
        executor.discover(lambda interface, present: found.append(interface))
        await async_wait_until(
            lambda: any(i.role is Role.SUBSCRIBER for i in found), 5.0, "the robot's tokens"
        )
        assert (
            Interface(
                Role.SUBSCRIBER,
                "cmd_vel",
                "geometry_msgs/msg/TwistStamped",
                type_hash(RosDistro.JAZZY, "geometry_msgs/msg/TwistStamped"),
            )
            in found
        )
        assert any(i.role is Role.SERVICE_SERVER and i.ros_type == CANCEL_GOAL for i in found)
        replies: list[zenoh.Reply] = []
        bus.session.get(
            RmwZenohKeys(0).data_any_hash(
                "navigate_to_pose/_action/cancel_goal", dds_type_name(CANCEL_GOAL)
            ),
            replies.append,
            payload=codec.cancel_goal_request(),
            attachment=Attachment(7, 5, bytes(range(16))).encode(),
        )
        await async_wait_until(lambda: replies, 5.0, "the reply")
        answer = replies[0].ok
        assert answer is not None
        assert answer.attachment is not None
        echoed = Attachment.decode(answer.attachment.to_bytes())
        assert (echoed.sequence, echoed.gid) == (7, bytes(range(16)))
        assert echoed.timestamp_ns > 5


async def test_a_stop_goes_where_the_executor_saw_the_robot_listen_until_it_sees_for_itself(
    router: str,
) -> None:
    """A stop's first zero velocity goes out at once, on the key the executor passed on
    (ExecutorInfo.cmd_vel_hash); its transport follows the robot's tokens from then on,
    and what the robot itself announces wins."""
    told = "RIHS01_" + "ab" * 32  # the executor's word: a robot since restarted, say
    twist = dds_type_name("geometry_msgs/msg/Twist")
    with joined(router) as bus, joined(router) as robot_bus:
        robot = open_transport(
            robot_bus, TransportKind.RMW_ZENOH, "voicectl_sim", "", 0, RosDistro.HUMBLE
        )
        heard: set[str] = set()

        def hear(key: str) -> None:  # as the robot's rmw_zenoh subscription: this key only
            robot_bus.subscribe(key, bytes, lambda sample_key, _raw: heard.add(sample_key))

        told_key = RmwZenohKeys(0).data("cmd_vel", twist, told)
        announced = RmwZenohKeys(0).data("cmd_vel", twist, "TypeHashNotSupported")
        hear(told_key)
        hear(announced)
        info = ExecutorInfo(transport=TransportKind.RMW_ZENOH, cmd_vel_hash=told)
        stop = RobotStop.of(info, bus, "voicectl_test_stop")

        def stopped_on(key: str) -> bool:
            # Sent again until heard: the robot's subscription may not have reached the
            # router yet. The robot's token is not there: the told key it is.
            stop.zero_velocity()
            return key in heard

        await async_wait_until(lambda: stopped_on(told_key), 5.0, "the stop on the told key")
        assert heard == {told_key}

        robot.offer(Interface(Role.SUBSCRIBER, "cmd_vel", "geometry_msgs/msg/Twist"))
        await async_wait_until(
            lambda: stop.transport.subscriber_types("cmd_vel"), 5.0, "the robot's token"
        )
        stop = RobotStop.of(info, bus, "voicectl_test_stop")
        await async_wait_until(lambda: stopped_on(announced), 5.0, "the stop on the robot's key")


async def test_the_action_client_sends_follows_and_cancels_a_goal(router: str) -> None:
    """The seam's one action client against an action server on rmw_zenoh: a goal sent
    and accepted, its feedback and status followed, cancelled, its result had."""
    action = "bot1/navigate_to_pose"
    goal_id = bytes(range(16))
    codec = Ros2Codec()
    with joined(router) as bus, joined(router) as robot_bus:
        robot = open_transport(robot_bus, TransportKind.RMW_ZENOH, "voicectl_sim", "bot1")
        ended = asyncio.Event()
        asked: list[bytes] = []

        async def send_goal(raw: bytes) -> bytes:
            asked.append(codec.read_send_goal_request(raw).goal_id)
            return codec.send_goal_response(True, 1.0)

        async def get_result(raw: bytes) -> bytes:
            assert codec.read_get_result_request(raw) == goal_id
            await ended.wait()
            return codec.get_result_response(GoalStatus.CANCELED)

        async def cancel(raw: bytes) -> bytes:
            ended.set()
            cancelled = codec.read_cancel_goal_request(raw).goal_id
            return codec.cancel_goal_response(CancelCode.NONE, (cancelled,))

        robot.serve(f"{action}/_action/send_goal", NAVIGATE_SEND_GOAL, send_goal)
        robot.serve(f"{action}/_action/get_result", NAVIGATE_GET_RESULT, get_result)
        robot.serve(f"{action}/_action/cancel_goal", CANCEL_GOAL, cancel)
        executor = open_transport(bus, TransportKind.RMW_ZENOH, "voicectl_executor", "bot1")
        servers: set[str] = set()
        executor.discover(
            lambda i, present: servers.add(i.name) if i.role is Role.SERVICE_SERVER else None
        )
        await async_wait_until(lambda: len(servers) == 3, 5.0, "the action server's tokens")

        client = ActionClient(executor, action, codec)
        client.follow()
        heard: list[float] = []
        try:
            with client.following(goal_id, lambda f: heard.append(f.distance_remaining)):
                assert await client.send_goal(goal_id, "map", Pose2D(2.0, 0.0, 0.0), 5.0)
                assert asked == [goal_id]

                def followed() -> bool:
                    # Published again until heard: the subscriptions may not have reached
                    # the router yet. The status of a goal not followed is no one's.
                    robot.publish(
                        f"{action}/_action/feedback",
                        NAVIGATE_FEEDBACK,
                        codec.feedback(goal_id, Pose2D(0.5, 0.0, 0.0), 1.5, 1.0),
                    )
                    robot.publish(
                        f"{action}/_action/status",
                        "action_msgs/msg/GoalStatusArray",
                        codec.goal_status_array(
                            [(bytes(16), GoalStatus.ABORTED), (goal_id, GoalStatus.EXECUTING)]
                        ),
                    )
                    return bool(heard) and client.status(goal_id) is GoalStatus.EXECUTING

                await async_wait_until(followed, 5.0, "the goal's feedback and status")
                assert heard[0] == 1.5
                assert await client.cancel(goal_id) == Cancelled(
                    True, True, f"navigation cancelled goal {goal_id.hex()[:8]}"
                )
                result = await client.get_result(goal_id, 5.0)
                assert result.status is GoalStatus.CANCELED
            assert client.status(goal_id) is None  # followed no longer
        finally:
            client.close()


async def test_a_call_asks_only_the_exact_key_of_a_complete_server(router: str) -> None:
    """rmw_zenoh's clients ask their own type hash, of complete queryables, one reply per
    key: a server of another hash, or one not declared complete, is not asked."""
    codec = Ros2Codec()
    name = "navigate_to_pose/_action/cancel_goal"
    dds = dds_type_name(CANCEL_GOAL)
    keys = RmwZenohKeys(0)
    asked: list[str] = []

    def answer(query: zenoh.Query) -> None:
        asked.append(str(query.key_expr))
        query.reply(query.key_expr, codec.cancel_goal_response(0), attachment=bytes(33))

    with joined(router) as bus, joined(router) as robot:
        other_hash = robot.session.declare_queryable(
            keys.data(name, dds, "RIHS01_" + "0" * 64), answer, complete=True
        )
        incomplete = robot.session.declare_queryable(
            keys.data(name, dds, type_hash(RosDistro.JAZZY, CANCEL_GOAL)), answer
        )
        transport = open_transport(bus, TransportKind.RMW_ZENOH, "voicectl_stop", "", 0)
        with pytest.raises(BusError):
            await transport.call(name, CANCEL_GOAL, codec.cancel_goal_request(), 1.0)
        assert asked == []
        exact = robot.session.declare_queryable(
            keys.data(name, dds, type_hash(RosDistro.JAZZY, CANCEL_GOAL)), answer, complete=True
        )
        try:
            reply = await transport.call(name, CANCEL_GOAL, codec.cancel_goal_request(), 5.0)
            assert codec.read_cancel_goal_response(reply).return_code == 0
            assert asked == [keys.data(name, dds, type_hash(RosDistro.JAZZY, CANCEL_GOAL))]
        finally:
            for queryable in (other_hash, incomplete, exact):
                queryable.undeclare()


async def test_an_action_status_is_kept_for_a_client_that_comes_later(router: str) -> None:
    """An action's status is transient local: published before a client subscribes, the
    client still gets the last one, as from rmw_zenoh's cached publisher."""
    codec = Ros2Codec()
    status = "navigate_to_pose/_action/status"
    goal = bytes(range(16))
    with joined(router) as robot_bus, joined(router) as bus:
        robot = open_transport(robot_bus, TransportKind.RMW_ZENOH, "voicectl_sim", "")
        robot.publish(
            status,
            "action_msgs/msg/GoalStatusArray",
            codec.goal_status_array([(goal, GoalStatus.EXECUTING)]),
        )
        client = open_transport(bus, TransportKind.RMW_ZENOH, "voicectl_executor", "")
        heard: list[list[tuple[bytes, GoalStatus]]] = []
        client.subscribe(
            status,
            "action_msgs/msg/GoalStatusArray",
            codec.read_goal_status_array,
            heard.append,
            latched=True,
        )
        await async_wait_until(lambda: heard, 5.0, "the kept status")
        assert heard[0] == [(goal, GoalStatus.EXECUTING)]
