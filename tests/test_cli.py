"""The command line's contracts: `voicectl parse` output and exit codes, services that
refuse a bad configuration in one line, junk on the bus answered and survived."""

from __future__ import annotations

import asyncio
import datetime
import json
import os
import socket
from pathlib import Path
from typing import Any

import pytest

from harness.client import Client, client_wait_ready
from harness.ports import free_port
from harness.wait import async_wait_until, wait_until
from voicectl.shared.bus import json_decoder
from voicectl.shared.keys import RobotKeys
from voicectl.shared.messages import Failed, GetState, StateReply, SupervisorReply
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Pose2D, Ros2Codec, RosDistro, new_goal_id

from .conftest import REPO, Processes, voicectl
from .support import joined
from .test_hints import BARE_PATH, run_as_written


def test_parse_prints_one_json_object() -> None:
    done = voicectl("parse", "--orders", "orders/demo.yaml", "turn left then dance")
    assert done.returncode == 1  # "dance" made no order
    assert voicectl("parse", "--orders", "orders/demo.yaml", "turn left").returncode == 0
    assert json.loads(done.stdout) == {
        "orders": [
            {
                "order": "rotation",
                "case": "left",
                "label": "mbgoal",
                "description": "turn left",
                "params": {},
                "target_pose": {"frame": "base_link", "x": 0.0, "y": 0.0, "yaw": 1.57},
                "confirm": False,
            }
        ],
        "errors": [{"text": "dance", "reason": "no order matches"}],
    }


def test_parse_without_frame_has_null_pose_and_params() -> None:
    done = voicectl("parse", "--orders", "orders/tutorial.yaml", "take a picture")
    (order,) = json.loads(done.stdout)["orders"]
    assert order["target_pose"] is None
    assert order["params"] == {"wait": 5}


def test_an_order_that_asks_for_a_spoken_yes_says_so() -> None:
    done = voicectl("parse", "--orders", "orders/demo.yaml", "go to the dumpster")
    (order,) = json.loads(done.stdout)["orders"]
    assert order["confirm"] is True


def test_parse_with_a_bad_file_exits_2_in_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("orders:\n  spin: {voice_alias: spin}\n")
    done = voicectl("parse", "--orders", str(bad), "spin")
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr == f"voicectl parse: {bad}: order 'spin': missing mandatory key 'label'\n"


def test_converter_refuses_to_start_with_half_a_config(tmp_path: Path, router: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("orders:\n  ok: {voice_alias: go, label: x}\n  broken: {label: x}\n")
    done = voicectl("converter", "--orders", str(bad), "--connect", router, timeout=60)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert lines[-1].endswith(f"{bad}: order 'broken': missing mandatory key 'voice_alias'")


def test_executor_refuses_a_bad_binding() -> None:
    done = voicectl("executor", "--executor", "no_such_module:X", timeout=60)
    assert done.returncode == 2
    assert "cannot import no_such_module" in done.stderr


async def test_supervisor_answers_junk_and_keeps_serving(router: str, processes: Processes) -> None:
    supervisor = processes.start(
        "voicectl.services.supervisor", "--connect", router, "--robot", "r1"
    )
    key = RobotKeys("r1").supervisor

    with joined(router) as bus:
        decode = json_decoder(SupervisorReply)
        await client_wait_ready(Client(bus, "r1"), executor=False)
        for junk in (b"", b"\x00\xff", b'{"type": "submit"}', b'{"type": "launch"}'):
            reply = decode(await bus.request_bytes(key, junk, 5.0))
            assert isinstance(reply, Failed)
            assert reply.reason.startswith("undecodable request")
        bus.session.put(RobotKeys("r1").executor_events, b"garbage")
        state = await bus.request(key, GetState(), decode, timeout=5.0)
        assert isinstance(state, StateReply)
    assert supervisor.poll() is None
    await async_wait_until(
        lambda: (
            "dropped undecodable message on voice/r1/executor/events" in processes.log(supervisor)
        ),
        10.0,
        "the supervisor to log the junk event",
    )


def test_web_on_a_busy_port_says_so_in_one_line(router: str, tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = voicectl(
            "web",
            "--port",
            str(port),
            "--connect",
            router,
            "--token-file",
            str(tmp_path / "token"),
            timeout=60.0,
        )
    assert result.returncode == 2, result
    assert result.stderr.strip().splitlines()[-1] == (
        f"voicectl web: cannot serve on 127.0.0.1:{port}: Address already in use"
    )
    assert "panel on" not in result.stderr + result.stdout
    assert "Traceback" not in result.stderr


async def test_a_stop_navigation_refuses_is_said_to_be_unconfirmed(
    router: str, processes: Processes
) -> None:
    """`voicectl stop` never reports a stop nothing confirmed as done: exit status 4 and
    one line saying what is in doubt."""
    processes.start("voicectl.services.sim", "--connect", router, "--fault", "cancel-rejected")
    processes.start("voicectl.services.supervisor", "--connect", router, "--robot", "r1")
    processes.start("voicectl.services.executor", "--connect", router, "--robot", "r1")

    def executor_online() -> bool:
        state = voicectl("state", "--robot", "r1", "--connect", router, timeout=30.0)
        return state.returncode == 0 and json.loads(state.stdout)["executor_online"]

    await asyncio.to_thread(wait_until, executor_online, 60.0, "the executor")

    with joined(router) as bus:
        codec = Ros2Codec(RosDistro.JAZZY)
        reply = await bus.request_bytes(
            RobotNames().navigate("send_goal"),
            codec.send_goal_request(new_goal_id(), "map", Pose2D(x=8.0, y=0.0, yaw=0.0)),
            timeout=10.0,
        )
        assert codec.read_send_goal_response(reply)
    stopped = await asyncio.to_thread(voicectl, "stop", "--robot", "r1", "--connect", router)
    assert stopped.returncode == 4, stopped
    answer = json.loads(stopped.stdout)
    assert answer["type"] == "stopped"
    assert answer["confirmed"] is False
    assert "navigation refused to cancel every goal" in answer["detail"]
    assert stopped.stderr.startswith("voicectl stop: sent, but not confirmed: sent zero velocity")


async def test_say_tells_a_person_what_was_sent_and_when(router: str, processes: Processes) -> None:
    """`voicectl say` says in one stderr line what it did not understand, suggesting
    once; what it did not submit is not printed as sent; `state` and `history` give
    every time as an epoch and in ISO 8601."""
    processes.start("voicectl.services.sim", "--connect", router, "--time-scale", "10")
    processes.start("voicectl.services.converter", "--connect", router)
    processes.start("voicectl.services.supervisor", "--connect", router, "--robot", "r1")
    processes.start("voicectl.services.executor", "--connect", router, "--robot", "r1")
    bus = ("--robot", "r1", "--connect", router)

    def executor_online() -> bool:
        state = voicectl("state", *bus, timeout=30.0)
        return state.returncode == 0 and json.loads(state.stdout)["executor_online"]

    await asyncio.to_thread(wait_until, executor_online, 60.0, "the executor")

    def say(*args: str) -> tuple[int, dict[str, Any], str]:
        done = voicectl("say", *bus, *args, timeout=30.0)
        return done.returncode, json.loads(done.stdout), done.stderr

    # The converter's reason already suggests a phrase: the hint is said once.
    code, said, stderr = await asyncio.to_thread(say, "move forwad 2 meters")
    assert code == 1
    assert said["submitted"] is False
    assert said["orders"] == said["not_sent"] == []
    assert stderr.count("did you mean: move forward 2 meters?") == 1, stderr
    (line,) = stderr.splitlines()
    assert line.startswith("voicectl say: nothing submitted: 'move forwad 2 meters': "), line

    # A misspelling with no reason of its own gets the suggestion from the candidates.
    code, said, stderr = await asyncio.to_thread(say, "trun left")
    assert code == 1
    assert stderr == (
        "voicectl say: nothing submitted: 'trun left': no order matches, did you mean: turn left?\n"
    )

    # Understood in part: what was understood is held back, and not printed as sent.
    code, said, stderr = await asyncio.to_thread(say, "turn left then dance")
    assert code == 1
    assert said["submitted"] is False
    assert said["orders"] == []
    assert said["order_ids"] == []
    assert [order["description"] for order in said["not_sent"]] == ["turn left"]
    assert stderr == (
        "voicectl say: nothing submitted (--partial submits what was understood): "
        "'dance': no order matches\n"
    )

    code, said, stderr = await asyncio.to_thread(say, "turn left")
    assert code == 0, stderr
    assert said["submitted"] is True
    assert len(said["order_ids"]) == 1
    assert stderr == ""

    def finished() -> bool:
        page = json.loads(voicectl("history", *bus, timeout=30.0).stdout)
        return bool(page["records"])

    await asyncio.to_thread(wait_until, finished, 60.0, "the turn to finish")
    history = json.loads((await asyncio.to_thread(voicectl, "history", *bus)).stdout)
    state = json.loads((await asyncio.to_thread(voicectl, "state", *bus)).stdout)
    for record in (history["records"][0], state["history"][0]):
        for key in ("submitted_at", "started_at", "ended_at"):
            epoch = record[key]
            readable = datetime.datetime.fromisoformat(record[f"{key}_iso"])
            assert readable.tzinfo is not None, record  # a time a person can place
            assert abs(readable.timestamp() - epoch) < 1.0, (key, record)


def test_confirm_must_be_true_or_false(tmp_path: Path) -> None:
    orders = tmp_path / "orders.yaml"
    orders.write_text('orders:\n  x:\n    voice_alias: "x"\n    label: "l"\n    confirm: "yes"\n')
    done = voicectl("parse", "--orders", str(orders), "x")
    assert done.returncode == 2
    assert done.stderr.strip() == (
        f"voicectl parse: {orders}: order 'x': 'confirm' must be true or false"
    )


def test_transcribe_of_a_missing_file_says_which_in_one_line(tmp_path: Path) -> None:
    there = tmp_path / "there.wav"
    there.write_text("not audio, but present")
    gone = tmp_path / "missing.wav"
    done = voicectl("transcribe", str(there), str(gone))
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr == f"voicectl transcribe: no such file: {gone}\n"


def test_a_negative_reorder_position_is_refused_in_one_line() -> None:
    """...and the help it points to is a command that runs as written, from the clone."""
    done = voicectl(
        "reorder",
        "some-id",
        "-1",
        "--connect",
        "tcp/127.0.0.1:1",
        env={**os.environ, "PATH": BARE_PATH},
    )
    assert done.returncode == 2
    assert done.stdout == ""
    said, _, helps = done.stderr.partition(" (see ")
    assert said == "voicectl reorder: argument position: position must be 0 or more, not -1"
    assert helps.endswith(" reorder --help)\n"), helps
    shown = run_as_written(helps.removesuffix(")\n"), REPO, BARE_PATH)
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith("usage: voicectl reorder"), shown.stdout


@pytest.mark.parametrize(
    ("flag", "value", "allowed"),
    [
        ("--limit", "0", "1 to 500"),
        ("--limit", "1000", "1 to 500"),
        ("--offset", "-1", f"0 to {2**53}"),
        ("--limit", "ten", "1 to 500"),
    ],
)
def test_a_history_page_out_of_range_is_a_usage_error_naming_the_range(
    flag: str, value: str, allowed: str
) -> None:
    """Said by the command itself, before the bus: no router is there to ask."""
    done = voicectl("history", flag, value, "--connect", f"tcp/127.0.0.1:{free_port()}")
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""
    assert done.stderr.count("\n") == 1, done.stderr
    assert done.stderr.startswith(
        f"voicectl history: argument {flag}: must be a whole number from {allowed}, not '{value}'"
    ), done.stderr


async def test_cancel_all_says_what_it_cancelled_and_partial_say_exits_0(
    router: str, processes: Processes
) -> None:
    """`cancel-all` names what there was to cancel (nothing, the queue, the running
    order); `say --partial` that submitted something exits 0."""
    processes.start("voicectl.services.sim", "--connect", router)
    processes.start("voicectl.services.converter", "--connect", router)
    processes.start("voicectl.services.supervisor", "--connect", router, "--robot", "r1")
    processes.start("voicectl.services.executor", "--connect", router, "--robot", "r1")
    bus = ("--robot", "r1", "--connect", router)

    def state() -> dict[str, Any]:
        done = voicectl("state", *bus, timeout=30.0)
        return json.loads(done.stdout) if done.returncode == 0 else {}

    await asyncio.to_thread(wait_until, lambda: state().get("executor_online"), 60.0, "executor")

    def cancel_all() -> str:
        done = voicectl("cancel-all", *bus, timeout=30.0)
        assert done.returncode == 0, done.stderr
        detail: str = json.loads(done.stdout)["detail"]
        return detail

    nothing = await asyncio.to_thread(cancel_all)
    assert nothing == "nothing to cancel: the queue was empty and no order was running"

    partial = await asyncio.to_thread(
        voicectl, "say", *bus, "--partial", "move forward 10 meters then dance", timeout=30.0
    )
    assert partial.returncode == 0, partial.stderr
    assert json.loads(partial.stdout)["submitted"] is True
    assert partial.stderr == (
        "voicectl say: submitted the rest; not understood: 'dance': no order matches\n"
    )
    await asyncio.to_thread(wait_until, lambda: state().get("current"), 30.0, "the drive to run")
    queued = await asyncio.to_thread(voicectl, "say", *bus, "turn left", timeout=30.0)
    assert queued.returncode == 0, queued.stderr

    both = await asyncio.to_thread(cancel_all)
    # The longest drive the orders allow: under two suites at once (load 15 to 19), a 5 m
    # one ended before the three commands since it began had run.
    assert both == "cancelled 1 queued order and the running order (move forward 10 m)"


def test_a_wake_phrase_longer_than_a_few_words_is_refused_in_one_line() -> None:
    done = voicectl("listen", "-", "--wake", "hey robot " * 5)
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()[-1:]
    assert "argument --wake: a phrase is at most 8 words and 64 characters" in line, done.stderr
