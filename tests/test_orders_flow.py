"""Supervisor and executor as real processes on loopback: dispatch, results, failure
policy, cancel, emergency stop, an executor that dies, user executors."""

from __future__ import annotations

import asyncio
import contextlib
import signal
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from harness.client import Client, client_wait_ready
from voicectl.shared.messages import (
    Cancel,
    Done,
    EmergencyStop,
    Failed,
    OrderStatus,
    Stopped,
)

from .conftest import Processes
from .support import ROBOT_GIVEN, joined, order

USER_EXECUTORS = [
    "--executor",
    "harness.executors:Boom",
    "--executor",
    "harness.executors:Refuse",
    "--executor",
    "harness.executors:Slow=slow,slow2",
    "--executor",
    "harness.executors:Stubborn",
    "--executor",
    "harness.executors:Strict",
]
EXECUTORS_FILE = """\
# One class, two setups: an integrator's executor configured without code changes.
executors:
  - class: harness.executors:Greeter
    args: {greeting: hello, times: 2}
  - class: harness.executors:Greeter
    labels: [welcome]
    args: {greeting: welcome aboard}
"""


@dataclass
class Robot:
    router: str
    processes: Processes
    executors_file: Path
    name: str = "r1"

    def start_executor(self) -> Any:
        return self.processes.start(
            "voicectl.services.executor",
            "--connect",
            self.router,
            "--robot",
            self.name,
            "--cancel-deadline",
            "0.5",
            *USER_EXECUTORS,
            "--executors",
            str(self.executors_file),
            *ROBOT_GIVEN,
        )


@pytest.fixture
def robot(router: str, processes: Processes, tmp_path: Path) -> Robot:
    processes.start("voicectl.services.supervisor", "--connect", router, "--robot", "r1")
    executors_file = tmp_path / "executors.yaml"
    executors_file.write_text(EXECUTORS_FILE)
    bot = Robot(router, processes, executors_file)
    bot.start_executor()
    return bot


@contextlib.asynccontextmanager
async def scenario(robot: Robot) -> AsyncIterator[Client]:
    """A client of the robot's supervisor, once the supervisor and its executor are up."""
    with joined(robot.router) as bus:
        client = Client(bus, robot.name)
        await client_wait_ready(client)
        yield client


async def test_results_of_builtin_and_user_executors(robot: Robot) -> None:
    async with scenario(robot) as client:
        ids = await client.submit(order("mul", first=6, second=7))
        ok = await client.finished(ids[0])
        assert (ok.status, ok.message) == (OrderStatus.SUCCEEDED, "6 x 7 = 42")

        (boom,) = await client.submit(order("boom"))
        record = await client.finished(boom)
        assert (record.status, record.message) == (OrderStatus.FAILED, "RuntimeError: kaboom")

        (nobody,) = await client.submit(order("dance"))
        record = await client.finished(nobody)
        assert record.status == OrderStatus.REJECTED
        assert record.message == (
            "unknown label 'dance'; bound labels: boom, drive, greet, mbgoal, mul, pic, "
            "refuse, rotate, slow, slow2, strict, stubborn, wait, welcome"
        )

        greetings = await client.submit(order("greet"), order("welcome"))
        records = [await client.finished(order_id) for order_id in greetings]
        assert [r.message for r in records] == ["hello hello", "welcome aboard"]

        # the executor survived all of that
        (again,) = await client.submit(order("mul", first=2, second=3))
        assert (await client.finished(again)).status == OrderStatus.SUCCEEDED


async def test_a_failure_cancels_the_rest_of_the_utterance(robot: Robot) -> None:
    async with scenario(robot) as client:
        refused, after = await client.submit(order("refuse"), order("mul", first=1, second=1))
        first = await client.finished(refused)
        assert (first.status, first.message) == (OrderStatus.FAILED, "door is closed")
        rest = await client.finished(after)
        assert rest.status == OrderStatus.CANCELLED
        assert rest.message == "cancelled because “do refuse” before it failed"


async def test_duplicate_submit_is_a_no_op(robot: Robot) -> None:
    async with scenario(robot) as client:
        first = await client.submit(order("slow", seconds=0.5), request_id="same")
        again = await client.submit(order("slow", seconds=0.5), request_id="same")
        assert first == again
        await client.finished(first[0])
        state = await client.state()
        assert [r.id for r in state.history].count(first[0]) == 1
        assert not state.queue


async def test_cancel_running_and_queued_orders(robot: Robot) -> None:
    async with scenario(robot) as client:
        running, queued = await client.submit(order("slow"), order("slow2"))
        await client.wait_state(
            lambda s: s.current is not None and s.current.progress is not None,
            "progress of the running order",
        )
        assert isinstance(await client.ask(Cancel(order_id=queued)), Done)
        assert isinstance(await client.ask(Cancel(order_id=running)), Done)
        for order_id in (running, queued):
            assert (await client.finished(order_id)).status == OrderStatus.CANCELLED
        unknown = await client.ask(Cancel(order_id="nope"))
        assert isinstance(unknown, Failed)
        assert "'nope' is neither queued nor running" in unknown.reason


async def test_an_executor_that_ignores_cancel_is_cut_off_and_runs_alone(robot: Robot) -> None:
    async with scenario(robot) as client:
        (stubborn,) = await client.submit(order("stubborn", seconds=4))
        await client.wait_state(
            lambda s: s.current is not None and s.current.progress is not None,
            "the order to be running",
        )
        await client.ask(Cancel(order_id=stubborn))
        record = await client.finished(stubborn, timeout=10.0)
        assert record.status == OrderStatus.CANCELLED
        assert "did not stop in time" in record.message
        # Its code still runs for a few seconds: nothing runs beside it.
        (refused,) = await client.submit(order("mul", first=1, second=2))
        rejected = await client.finished(refused)
        assert rejected.status == OrderStatus.REJECTED
        assert f"order '{stubborn}' ignored its cancel and still runs" in rejected.message
        for _ in range(40):  # then orders run again
            (after,) = await client.submit(order("mul", first=1, second=2))
            if (await client.finished(after)).status == OrderStatus.SUCCEEDED:
                break
            await asyncio.sleep(0.25)
        else:
            raise AssertionError("orders stayed refused after the stubborn executor ended")


async def test_orders_are_checked_against_the_executors_parameter_types(robot: Robot) -> None:
    async with scenario(robot) as client:
        (fits,) = await client.submit(order("strict", metres_per_second=1))
        assert (await client.finished(fits)).message == "1 m/s for cruise"
        for params, why in (
            (
                {"metres_per_second": True},
                "parameter 'metres_per_second': Expected `float`, got `bool`",
            ),
            ({"metres_per_second": 3}, "parameter 'metres_per_second': Expected `float` <= 2.0"),
            ({}, "missing parameter `metres_per_second`"),
            ({"metres_per_second": 1, "mode": 5}, "parameter 'mode': Expected `str`, got `int`"),
        ):
            (bad,) = await client.submit(order("strict", **params))
            record = await client.finished(bad)
            assert (record.status, record.message) == (
                OrderStatus.REJECTED,
                f"'do strict' (strict): {why}",
            )
        # the seed's tutorial: mul reads first and second, and True is not a number
        (wrong,) = await client.submit(order("mul", first=True, second=2))
        assert (await client.finished(wrong)).status == OrderStatus.REJECTED


async def test_emergency_stop_clears_everything(robot: Robot) -> None:
    async with scenario(robot) as client:
        ids = await client.submit(
            order("slow"), order("mul", first=1, second=1), order("mul", first=2, second=2)
        )
        await client.wait_state(lambda s: s.current is not None, "the order to start")
        reply = await client.ask(EmergencyStop())
        assert isinstance(reply, Stopped), reply
        assert reply.confirmed, reply
        records = [await client.finished(i) for i in ids]
        assert [r.status for r in records] == [OrderStatus.CANCELLED] * 3
        assert records[0].message == "emergency stop"


async def test_executor_lost_mid_order_pauses_the_queue(robot: Robot) -> None:
    async with scenario(robot) as client:
        running, waiting = await client.submit(
            order("slow"), order("mul", first=3, second=3), request_id="a"
        )
        (other,) = await client.submit(order("mul", first=4, second=4), request_id="b")
        await client.wait_state(
            lambda s: s.current is not None and s.current.progress is not None,
            "the executor to be running the order",
        )
        executor = robot.processes.started[-1][1]
        executor.send_signal(signal.SIGKILL)
        executor.wait()
        lost = await client.finished(running)
        assert (lost.status, lost.message) == (
            OrderStatus.FAILED,
            "executor lost; halting the robot",
        )
        state = await client.wait_state(lambda s: not s.executor_online, "executor offline")
        # the failed order's sibling is cancelled; the other utterance waits, not lost
        assert [r.id for r in state.queue] == [other]
        assert (await client.finished(waiting)).status == OrderStatus.CANCELLED
        robot.start_executor()
        record = await client.finished(other)
        assert (record.status, record.message) == (OrderStatus.SUCCEEDED, "4 x 4 = 16")
