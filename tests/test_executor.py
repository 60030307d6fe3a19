"""The executor against the simulator through real Zenoh, the test in the supervisor's
seat: every built-in executor, cancel and halt, label tokens."""

from __future__ import annotations

import asyncio
import math
import uuid
from pathlib import Path

import pytest
from PIL import Image as PilImage

from shared.bus import Bus, BusOptions, json_decoder
from shared.keys import BridgeKeys, RobotKeys
from shared.messages import (
    Accepted,
    CancelOrder,
    Done,
    Execute,
    ExecutorEvent,
    ExecutorReply,
    Halt,
    Order,
    OrderFinished,
    OrderProgress,
    OrderStatus,
    TargetPose,
)
from shared.ros2 import Odometry, Ros2Codec, RosDistro

from .conftest import Processes, async_wait_until


class Harness:
    """Sends orders straight to the executor and keeps what it reports."""

    def __init__(self, bus: Bus, robot: str = "r1") -> None:
        self.bus = bus
        self.keys = RobotKeys(robot)
        self.events: dict[str, list[ExecutorEvent]] = {}
        self.odometry: list[tuple[float, Odometry]] = []
        self._decode = json_decoder(ExecutorReply)
        codec = Ros2Codec(RosDistro.JAZZY)
        loop = asyncio.get_running_loop()
        bus.subscribe(self.keys.executor_events, json_decoder(ExecutorEvent), self._on_event)
        bus.subscribe(
            BridgeKeys().odom,
            codec.read_odometry,
            lambda _key, odom: self.odometry.append((loop.time(), odom)),
        )

    def _on_event(self, _key: str, event: ExecutorEvent) -> None:
        self.events.setdefault(event.order_id, []).append(event)

    async def ready(self) -> None:
        async def answered() -> bool:
            replies = self.bus.session.liveliness().get(self.keys.alive("executor"), timeout=1)
            return any(r.ok is not None for r in replies)

        for _ in range(200):
            if await answered() and self.odometry:
                return
            await asyncio.sleep(0.05)
        raise AssertionError("executor or sim never came up")

    async def execute(self, order: Order) -> str:
        order_id = uuid.uuid4().hex[:12]
        reply = await self.bus.request(
            self.keys.executor_execute, Execute(order_id=order_id, order=order), self._decode
        )
        assert isinstance(reply, Accepted), reply
        return order_id

    async def control(self, request: CancelOrder | Halt) -> object:
        return await self.bus.request(self.keys.executor_control, request, self._decode)

    async def finished(self, order_id: str, timeout: float = 30.0) -> OrderFinished:
        def done() -> OrderFinished | None:
            return next(
                (e for e in self.events.get(order_id, []) if isinstance(e, OrderFinished)), None
            )

        await async_wait_until(done, timeout, f"order {order_id} to finish")
        result = done()
        assert result is not None
        return result

    def pose(self) -> Odometry:
        return self.odometry[-1][1]


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> tuple[str, Path]:
    processes.start("services.sim", "--connect", router)
    photos = tmp_path / "photos"
    processes.start(
        "services.executor",
        "--connect",
        router,
        "--robot",
        "r1",
        "--photo-dir",
        str(photos),
    )
    return router, photos


def run(router: str, body: object) -> None:
    async def main() -> None:
        with Bus.open(BusOptions(connect=[router]), asyncio.get_running_loop()) as bus:
            harness = Harness(bus)
            await harness.ready()
            assert callable(body)
            await body(harness)

    asyncio.run(main())


def order(label: str, **params: float) -> Order:
    return Order(order=label, label=label, description=f"{label} test", params=params)


def test_drive_and_rotate_close_the_loop_on_odometry(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        start = harness.pose().pose
        result = await harness.finished(await harness.execute(order("drive", distance=0.6)))
        assert (result.status, result.message) == (OrderStatus.SUCCEEDED, "drove 0.6 m")
        await asyncio.sleep(0.2)
        moved = harness.pose().pose
        assert math.hypot(moved.x - start.x, moved.y - start.y) == pytest.approx(0.6, abs=0.05)
        assert harness.pose().linear_x == 0.0

        turn = Order(
            order="rotation",
            label="rotate",
            description="turn left",
            target_pose=TargetPose(frame="base_link", yaw=1.57),
        )
        result = await harness.finished(await harness.execute(turn))
        assert result.status == OrderStatus.SUCCEEDED
        await asyncio.sleep(0.2)
        turned = harness.pose().pose.yaw - moved.yaw
        assert math.atan2(math.sin(turned), math.cos(turned)) == pytest.approx(1.57, abs=0.05)
        progress = [e for e in harness.events[result.order_id] if isinstance(e, OrderProgress)]
        assert progress
        assert progress[0].progress.distance_angular == pytest.approx(1.57, abs=0.1)

        bad = await harness.finished(await harness.execute(order("drive")))
        assert bad.status == OrderStatus.FAILED
        assert "needs a 'distance' parameter or a base_link target pose" in bad.message

    run(robot[0], body)


def test_pic_saves_the_next_camera_frame_as_png(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        result = await harness.finished(await harness.execute(order("pic", wait=1)))
        assert result.status == OrderStatus.SUCCEEDED, result.message
        (photo,) = robot[1].glob("*.png")
        assert str(photo) in result.message
        with PilImage.open(photo) as picture:
            assert picture.size == (64, 48)
            assert picture.mode == "RGB"
        progress = [e for e in harness.events[result.order_id] if isinstance(e, OrderProgress)]
        assert progress[0].progress.text == "photo in 1 s"

    run(robot[0], body)


def test_mbgoal_reports_remaining_distance_and_cancel_stops_the_robot_fast(
    robot: tuple[str, Path],
) -> None:
    async def body(harness: Harness) -> None:
        far = Order(
            order="goal",
            label="mbgoal",
            description="reach far",
            target_pose=TargetPose(frame="map", x=6.0, y=0.0),
        )
        order_id = await harness.execute(far)

        def driving() -> bool:
            distances = [
                e.progress.distance_linear
                for e in harness.events.get(order_id, [])
                if isinstance(e, OrderProgress) and e.progress.distance_linear
            ]
            return bool(distances) and harness.pose().linear_x > 0.3

        await async_wait_until(driving, 20.0, "navigation to drive and report progress")
        loop = asyncio.get_running_loop()
        cancelled_at = loop.time()
        assert isinstance(await harness.control(CancelOrder(order_id=order_id)), Done)
        await async_wait_until(
            lambda: harness.odometry[-1][0] > cancelled_at and harness.pose().linear_x == 0.0,
            5.0,
            "the robot to stop",
        )
        stopped_at = next(
            t for t, odom in harness.odometry if t > cancelled_at and odom.linear_x == 0.0
        )
        assert stopped_at - cancelled_at < 0.2  # time scale 1: wall time is sim time
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "cancelled")

    run(robot[0], body)


def test_halt_stops_a_driving_robot_outside_any_order(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        order_id = await harness.execute(order("drive", distance=5.0))
        await async_wait_until(lambda: harness.pose().linear_x > 0.2, 10.0, "driving")
        assert isinstance(await harness.control(Halt()), Done)
        result = await harness.finished(order_id)
        assert (result.status, result.message) == (OrderStatus.CANCELLED, "emergency stop")
        halted_at = asyncio.get_running_loop().time()
        await asyncio.sleep(0.3)
        assert all(odom.linear_x == 0.0 for t, odom in harness.odometry if t > halted_at + 0.1)

    run(robot[0], body)


def test_executor_announces_its_labels(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        replies = harness.bus.session.liveliness().get("voice/r1/labels/*", timeout=2)
        labels = sorted(str(r.ok.key_expr).rsplit("/", 1)[1] for r in replies if r.ok)
        assert labels == ["drive", "mbgoal", "mul", "pic", "rotate", "wait"]
        simulator = harness.bus.session.liveliness().get(BridgeKeys().simulator, timeout=2)
        assert [str(r.ok.key_expr) for r in simulator if r.ok] == ["voicectl_sim/alive"]

    run(robot[0], body)


def test_sim_publishes_tf_that_agrees_with_odometry(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        codec = Ros2Codec(RosDistro.JAZZY)
        transforms: list[list[tuple[str, str, object]]] = []
        harness.bus.subscribe(
            BridgeKeys().tf, codec.read_transform, lambda _key, tf: transforms.append(tf)
        )
        await harness.finished(await harness.execute(order("drive", distance=0.3)))
        await async_wait_until(lambda: len(transforms) > 2, 5.0, "tf messages")
        ((parent, child, pose),) = transforms[-1]
        assert (parent, child) == ("odom", "base_link")
        odom = harness.pose().pose
        assert pose == odom  # the robot stands still: the latest of each agree exactly

    run(robot[0], body)


def test_wait_pauses_for_the_spoken_seconds(robot: tuple[str, Path]) -> None:
    async def body(harness: Harness) -> None:
        loop = asyncio.get_running_loop()
        started = loop.time()
        result = await harness.finished(await harness.execute(order("wait", seconds=1.5)))
        assert (result.status, result.message) == (OrderStatus.SUCCEEDED, "waited 1.5 s")
        assert loop.time() - started >= 1.5
        bad = await harness.finished(await harness.execute(order("wait", seconds=-1)))
        assert bad.status == OrderStatus.FAILED

    run(robot[0], body)
