"""User executors, some of them faulty on purpose, that the tests and the STOP
benchmarks bind with `--executor harness.executors:...`, the way an integrator binds their
own module."""

from __future__ import annotations

import asyncio
import math
import time
from typing import Annotated

import msgspec

from voicectl.executor import ExecutionContext, Executor, Order, OrderFailed, TargetPose


class Speed(msgspec.Struct):
    metres_per_second: Annotated[float, msgspec.Meta(gt=0, le=2)]
    mode: str = "cruise"


class Boom(Executor):
    """Raises like buggy user code does."""

    labels = ("boom",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        raise RuntimeError("kaboom")


class Refuse(Executor):
    labels = ("refuse",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        raise OrderFailed("door is closed")


class Slow(Executor):
    """Reports progress for `seconds` (default 30), honouring cancellation."""

    labels = ("slow",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        seconds = float(order.params.get("seconds", 30))
        steps = int(seconds / 0.1)
        for step in range(steps):
            ctx.progress(f"step {step}", percent=100.0 * step / steps)
            await asyncio.sleep(0.1)
        return "slept"


class Stubborn(Executor):
    """Ignores cancellation for `seconds` (default 3), as a badly written executor might."""

    labels = ("stubborn",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        ctx.progress("running, deaf to cancel")
        loop = asyncio.get_running_loop()
        end = loop.time() + float(order.params.get("seconds", 3))
        while loop.time() < end:
            try:
                await asyncio.sleep(0.1)
            except asyncio.CancelledError:
                continue
        return "finally"


class Runaway(Executor):
    """Drives forward and goes on driving whatever happens: cancels and errors are
    swallowed. Only a revoked robot handle keeps it from moving the robot."""

    labels = ("runaway",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        while True:
            try:
                ctx.robot.drive(0.3, 0.0)
                ctx.progress("driving")
            except Exception as exc:
                ctx.progress(f"swallowed: {exc}")
            try:
                await asyncio.sleep(0.05)
            except asyncio.CancelledError:
                continue


class Strict(Executor):
    """Declares typed parameters: the runner rejects orders that do not fit."""

    labels = ("strict",)
    params_type = Speed

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        speed: Speed = ctx.params
        return f"{speed.metres_per_second:g} m/s for {speed.mode}"


class Greeter(Executor):
    """Takes constructor arguments, as bound from an executors file."""

    labels = ("greet",)

    def __init__(self, greeting: str, times: int = 1) -> None:
        self.greeting = greeting
        self.times = times

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        return " ".join([self.greeting] * self.times)


class BlockingNavigator(Executor):
    """Starts a navigation goal, then blocks its event loop (`time.sleep` where an
    `await` belonged) for `seconds` (default 6): nothing on the loop runs meanwhile."""

    labels = ("blocknav",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        target = TargetPose(frame="map", x=float(order.params.get("x", 8.0)), y=0.0)
        going = asyncio.ensure_future(ctx.robot.navigate(target, lambda _pose, _left: None))
        start = await ctx.robot.next_pose()
        while abs((await ctx.robot.next_pose()).x - start.x) < 0.3:
            pass
        ctx.progress("navigating; blocking the loop")
        time.sleep(float(order.params.get("seconds", 6)))  # noqa: ASYNC251 (the fault)
        await going
        return "arrived"


class BlockedDriver(Executor):
    """Commands velocity from a blocked loop: drive, `time.sleep(0.1)`, drive... for
    `seconds` (default 6), swallowing whatever the robot handle raises."""

    labels = ("blockdrive",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        ctx.progress("driving from a blocked loop")
        end = time.monotonic() + float(order.params.get("seconds", 6))
        refused = 0
        while time.monotonic() < end:
            try:
                ctx.robot.drive(0.3, 0.0)
            except Exception:
                refused += 1
            time.sleep(0.1)  # noqa: ASYNC251 (the fault under test)
        return f"drove; {refused} commands refused"


class RawVelocity(Executor):
    """Publishes its own Twist bytes on cmd_vel, as fast as `speed` asks (default 1000
    m/s), once per odometry message for `seconds` (default 1), then a stop: a user
    executor that bypasses `drive`."""

    labels = ("rawvel",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        robot = ctx.robot
        twist = robot.codec.twist(float(order.params.get("speed", 1000.0)), 0.0)
        end = time.monotonic() + float(order.params.get("seconds", 1.0))
        try:
            while time.monotonic() < end:
                await robot.next_pose()
                robot.publish(robot.names.cmd_vel, "geometry_msgs/msg/Twist", twist)
        finally:
            robot.drive(0.0, 0.0)
        return "published"


class Wild(Executor):
    """An executor whose arithmetic went wrong: drives at 0.3 m/s until the robot moves,
    then asks for `value` ('nan', 'inf', '-inf': a number no robot may be sent) the way
    `how` says: 'drive' (the linear speed of `drive`), 'turn' (its angular speed), 'raw'
    (its own Twist bytes on cmd_vel), 'other' (a Twist on the topic `topic`), 'goal' (a
    navigation goal whose x it is, forced into the frozen TargetPose). Then it carries on
    driving at 0.3 m/s, swallowing whatever the robot handle raises, as careless code
    would: only the handle keeps it from moving the robot."""

    labels = ("wild",)

    async def execute(self, order: Order, ctx: ExecutionContext) -> str | None:
        robot = ctx.robot
        value = float(str(order.params.get("value", "nan")))
        how = str(order.params.get("how", "drive"))
        start = await robot.next_pose()
        while math.hypot((pose := await robot.next_pose()).x - start.x, pose.y - start.y) < 0.1:
            robot.drive(0.3, 0.0)
        try:
            match how:
                case "drive":
                    robot.drive(value, 0.0)
                case "turn":
                    robot.drive(0.3, value)
                case "raw":
                    twist = robot.codec.twist(value, 0.0)
                    robot.publish(robot.names.cmd_vel, "geometry_msgs/msg/Twist", twist)
                case "other":
                    topic = robot.names.topic(str(order.params.get("topic", "cmd_vel_nav")))
                    twist = robot.codec.twist(0.2, value)
                    robot.publish(topic, "geometry_msgs/msg/Twist", twist)
                case "goal":
                    target = TargetPose(frame="map", x=1.0)
                    msgspec.structs.force_setattr(target, "x", value)
                    await robot.navigate(target, lambda _pose, _left: None)
        except Exception as exc:
            ctx.progress(f"swallowed: {exc}")
        while True:
            try:
                robot.drive(0.3, 0.0)
            except Exception as exc:
                ctx.progress(f"swallowed: {exc}")
            await asyncio.sleep(0.05)
