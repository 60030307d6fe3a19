"""The walking skeleton, end to end: `voicectl up` as a real process tree on loopback,
commands typed through `voicectl say` and the HTTP API, the simulated robot moving."""

from __future__ import annotations

import collections
import io
import json
import signal
import sqlite3
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import msgspec
import pytest
import zenoh
from PIL import Image as PilImage

from harness.client import robot_key
from harness.speech_set import in_babble, in_pink_noise
from harness.wait import async_wait_until, wait_until
from voicectl.services.stt.audio import frames, read_wav
from voicectl.shared.bus import Bus, BusOptions, json_decoder
from voicectl.shared.client import VoicectlClient
from voicectl.shared.keys import RobotKeys
from voicectl.shared.kinds import ON_ZENOH
from voicectl.shared.messages import (
    AudioChunk,
    AudioStart,
    AudioStop,
    OrderStatus,
    Proposal,
    State,
    StateUpdate,
    SttStatus,
    Transcript,
)
from voicectl.shared.robot import TransportKind
from voicectl.shared.robot.keys import RobotNames
from voicectl.shared.ros2 import Pose2D, Ros2Codec, RosDistro

from .conftest import Speak, Stack
from .support import on_bus

pytestmark = pytest.mark.e2e


class RobotWatch:
    """The test's own eyes on the bus: odometry from the sim, state from the supervisor."""

    def __init__(self, router: str, transport: TransportKind = TransportKind.BRIDGE) -> None:
        self.codec = Ros2Codec(RosDistro.JAZZY)
        self.pose: Pose2D | None = None
        self._poses: collections.deque[tuple[float, Pose2D]] = collections.deque(maxlen=4000)
        """Recent odometry by its header stamp (wall-clock seconds, as the sim stamps it)."""
        self.pose_at_finish: dict[str, Pose2D] = {}
        """Where the robot was when each order ended, once odometry stamped after that end
        has come: on a loaded host the supervisor's state can overtake the odometry sent
        before it, and the last pose then is short of where the robot stopped."""
        self._ending: dict[str, float | None] = {}
        self._lock = threading.Lock()  # odometry and state come on Zenoh's threads
        self.state: State | None = None
        self._decoder = msgspec.json.Decoder(StateUpdate)
        options = BusOptions(connect=[router])
        self.session = zenoh.open(options.zenoh_config())
        odom = robot_key(transport, RobotNames().odom, "nav_msgs/msg/Odometry", any_hash=True)
        self.session.declare_subscriber(odom, self._on_odom)
        self.session.declare_subscriber(RobotKeys("robot").state, self._on_state)

    def _on_odom(self, sample: zenoh.Sample) -> None:
        odometry = self.codec.read_odometry(sample.payload.to_bytes())
        with self._lock:
            self.pose = odometry.pose
            self._poses.append((odometry.stamp_s, odometry.pose))
            self._settle()

    def _on_state(self, sample: zenoh.Sample) -> None:
        state = self._decoder.decode(sample.payload.to_bytes()).state
        with self._lock:
            self.state = state
            for record in state.history:
                if record.id not in self.pose_at_finish:
                    self._ending.setdefault(record.id, record.ended_at)
            self._settle()

    def _settle(self) -> None:
        """Move each ended order whose end the odometry has passed to `pose_at_finish`,
        with the last pose stamped at or before its end: the state update can come after
        the next order has set the robot moving (at ten times real speed, a loaded host's
        delay is a large part of a turn)."""
        if not self._poses:
            return
        newest = self._poses[-1][0]
        for order_id, ended in list(self._ending.items()):
            if ended is not None and newest <= ended:
                continue
            before = [pose for stamp, pose in self._poses if ended is None or stamp <= ended]
            self.pose_at_finish[order_id] = before[-1] if before else self._poses[0][1]
            del self._ending[order_id]

    def close(self) -> None:
        self.session.close()


@pytest.mark.parametrize("stack", list(ON_ZENOH), indirect=True, ids=str)
def test_spoken_sequence_moves_the_simulated_robot(stack: Stack) -> None:
    """The demo, on a robot behind zenoh-bridge-ros2dds and on one whose nodes speak
    rmw_zenoh (`voicectl up --transport rmw-zenoh`): the same orders, the same motion."""
    watch = RobotWatch(stack.router, stack.transport)
    try:
        wait_until(lambda: watch.pose is not None, 30.0, "odometry from the sim")
        said = stack.voicectl("say", "--connect", stack.router, "turn left then reach kitchen")
        assert said.returncode == 0, said.stderr
        reply = json.loads(said.stdout)
        assert [o["description"] for o in reply["orders"]] == ["turn left", "reach kitchen"]
        first, second = reply["order_ids"]

        wait_until(lambda: second in watch.pose_at_finish, 60.0, "both orders to finish")
        turned = watch.pose_at_finish[first]
        assert abs(turned.yaw - 1.57) < 0.05
        assert abs(turned.x) < 0.05
        assert abs(turned.y) < 0.05
        arrived = watch.pose_at_finish[second]
        assert abs(arrived.x - 3.0) < 0.1
        assert abs(arrived.y - 5.0) < 0.1
        assert abs(arrived.yaw - 1.0) < 0.05
    finally:
        watch.close()

    state = stack.voicectl("state", "--connect", stack.router)
    assert state.returncode == 0, state.stderr
    history = json.loads(state.stdout)["history"]
    assert [(h["id"], h["status"]) for h in history[:2]] == [
        (second, OrderStatus.SUCCEEDED),
        (first, OrderStatus.SUCCEEDED),
    ]
    assert history[0]["transcript"] == "turn left then reach kitchen"
    # a typo is not an idle robot: the known ones are named, as `say` does
    unknown = stack.voicectl("state", "--connect", stack.router, "--robot", "nobody")
    assert unknown.returncode == 1, unknown
    assert "no executor has served robot 'nobody' (known robots: robot)" in unknown.stderr


BABBLE = [
    ("the train leaves in ten minutes", "flite:awb"),
    ("did you see the game last night", "flite:rms"),
    ("we need more paper for the printer", "festival:kal_diphone"),
    ("two cats are in the garden", "flite:kal16"),
]
"""Four other people talking (one of them says "ten", another "two")."""


@pytest.mark.parametrize("room", ["clean", "pink-noise-5dB", "babble-10dB"])
def test_a_person_saying_go_forward_ten_meters_moves_the_robot_ten_meters(
    stack: Stack, people: dict[str, Path], speech: Speak, room: str
) -> None:
    """pocketsphinx's recording of a man, streamed to the stack's recogniser as the panel
    streams a microphone (in pink noise 5 dB below him, a loud room; or with four other
    people talking 10 dB below him, before, during and after), becomes the order to drive
    10 m, which the simulated robot drives. Among other voices it may also be refused or
    asked about, but never become another distance."""
    pcm = read_wav(people["real-goforward"])
    if room == "pink-noise-5dB":
        pcm = in_pink_noise(pcm, 5.0, tail=1.0)
    elif room == "babble-10dB":
        talkers = [read_wav(speech(text, voice)) for text, voice in BABBLE]
        padded = bytes(16000) + pcm + bytes(48000)  # 0.5 s before him, 1.5 s after
        pcm = in_babble(padded, talkers, 10.0)
    watch = RobotWatch(stack.router)
    try:
        wait_until(lambda: watch.pose is not None, 30.0, "odometry from the sim")

        async def speak(bus: Bus) -> list[str]:
            keys = RobotKeys("robot")
            heard: list[Proposal] = []
            bus.subscribe(keys.proposal, json_decoder(Proposal), lambda _k, p: heard.append(p))
            ready: list[SttStatus] = []
            bus.subscribe(
                keys.stt_status,
                json_decoder(SttStatus),
                lambda _k, s: ready.append(s),
                history=True,
            )
            await async_wait_until(lambda: any(s.ready for s in ready), 60.0, "a grammar in use")
            sender = bus.stream(keys.stt_audio("person"))
            assert await sender.matched(60.0), "the recogniser does not listen"
            sender.send(AudioStart())
            pieces = frames(pcm)
            for seq, first in enumerate(range(0, len(pieces), 5)):  # 100 ms a message
                sender.send(AudioChunk(seq=seq, pcm=b"".join(pieces[first : first + 5])))
            finals: list[Transcript] = []
            bus.subscribe(keys.transcript, json_decoder(Transcript), lambda _k, t: finals.append(t))
            seen = len(ready)
            sender.send(AudioStop())
            # Every utterance of the session decided: the recogniser closed it, and each of
            # its final transcripts has its proposal.
            await async_wait_until(
                lambda: any(s.sessions == 0 for s in ready[seen:]), 60.0, "the session's end"
            )
            await async_wait_until(
                lambda: (
                    any(p.session == "person" for p in heard)
                    and len([p for p in heard if p.session == "person"])
                    >= len([t for t in finals if t.session == "person"])
                ),
                60.0,
                "a proposal for every utterance",
            )
            proposals = [p for p in heard if p.session == "person"]
            taken = [p for p in proposals if p.orders]
            for proposal in taken:  # whatever the room, never another distance
                assert [o.description for o in proposal.orders] == ["move forward 10 m"], proposal
            if room == "babble-10dB" and not [p for p in taken if not p.doubts]:
                return []  # refused or asked, among other voices: nothing is sent
            [proposal] = proposals
            assert not proposal.rejected, proposal
            assert not proposal.doubts, proposal
            assert [h.ear for h in proposal.hearings][:2] == ["grammar", "moonshine"]
            client = VoicectlClient(bus)
            return await client.submit("robot", proposal.orders, proposal.transcript)

        sent = on_bus(stack.router, speak)
        if not sent:
            return
        [order_id] = sent
        wait_until(lambda: order_id in watch.pose_at_finish, 60.0, "the drive to finish")
        arrived = watch.pose_at_finish[order_id]
        assert abs(arrived.x - 10.0) < 0.2, arrived
        assert abs(arrived.y) < 0.2, arrived
    finally:
        watch.close()


def test_panel_api_needs_the_token_and_drives_the_robot(stack: Stack) -> None:
    base = f"http://127.0.0.1:{stack.port}"
    token = Path(stack.env["VOICECTL_DATA"], "token").read_text().strip()
    # Printed into a pipe (as into a log), the panel's address comes without the secret;
    # on a terminal it carries it (tests/test_up.py).
    assert not [line for line in stack.output if token in line]
    assert f"voicectl up: panel on http://127.0.0.1:{stack.port}/" in stack.output
    auth = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=base, timeout=30) as http:
        assert http.get("/api/health").json()["ok"] is True
        assert "voicectl" in http.get("/").text
        assert http.get("/api/state").status_code == 401
        assert http.get("/api/state", headers={"Authorization": "Bearer nope"}).status_code == 401

        parsed = http.post("/api/parse", json={"text": "multiply primes then fly"}, headers=auth)
        assert parsed.status_code == 200
        assert [o["order"] for o in parsed.json()["orders"]] == ["multiply"]
        assert parsed.json()["errors"][0]["text"] == "fly"

        bad = http.post("/api/submit", content=b"{not json", headers=auth)
        assert bad.status_code == 400
        assert "bad request body" in bad.json()["error"]

        submitted = http.post(
            "/api/submit",
            json={"orders": parsed.json()["orders"], "transcript": "multiply primes"},
            headers=auth,
        )
        assert submitted.status_code == 200, submitted.text
        (order_id,) = submitted.json()["order_ids"]

        record = finished_record(http, auth, order_id, "the multiply order to finish")
        assert record["status"] == "succeeded"
        assert record["message"] == "7 x 5 = 35"

        unknown = http.post("/api/cancel", json={"order_id": "nope"}, headers=auth)
        assert unknown.status_code == 409
        assert "neither queued nor running" in unknown.json()["error"]

        said = http.post(
            "/api/say",
            json={"text": "reach bathroom then reach kitchen then reach base"},
            headers=auth,
        )
        _, kitchen, base = said.json()["order_ids"]
        moved = http.post("/api/reorder", json={"order_id": base, "position": 0}, headers=auth)
        assert moved.status_code == 200, moved.text
        queued = [r["id"] for r in http.get("/api/state", headers=auth).json()["queue"]]
        assert queued[0] == base  # next, ahead of kitchen (bathroom may still be queued too)
        assert kitchen in queued
        assert http.post("/api/cancel_all", headers=auth).status_code == 200
        page = http.get("/api/history", params={"limit": 2}, headers=auth).json()
        assert page["type"] == "historypage"
        assert len(page["records"]) == 2
        assert http.get("/api/history", params={"limit": "x"}, headers=auth).status_code == 400


def test_up_stops_every_child_on_sigint(stack: Stack) -> None:
    trips = " then ".join(["reach bathroom then reach base"] * 2)
    said = stack.voicectl("say", "--connect", stack.router, trips)
    ids = json.loads(said.stdout)["order_ids"]
    assert len(ids) == 4, said
    wait_until(
        lambda: '"progress": {' in stack.voicectl("state", "--connect", stack.router).stdout,
        30.0,
        "the first order to be under way",
    )
    stack.process.send_signal(signal.SIGINT)
    assert stack.process.wait(timeout=30) == 0
    time.sleep(0.5)
    assert any("voicectl up: stopped" in line for line in stack.output)
    leftovers = subprocess.run(
        ["pgrep", "-f", "--", f"--connect {stack.router}"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert leftovers.stdout.strip() == "", leftovers.stdout
    # The executor stopped before the robot: the running order was interrupted, not lost,
    # and the rest of its utterance was dropped, so that the next start moves nothing. On
    # a loaded machine orders can end (at 10x) before the signal lands: the one running
    # then is the one interrupted (none, if it landed between two).
    database = Path(stack.env["VOICECTL_DATA"]) / "supervisor.sqlite3"
    with sqlite3.connect(database) as db:
        status = dict(db.execute("SELECT id, status FROM orders").fetchall())
    ended = [status[order_id] for order_id in ids]
    done = ended.count("succeeded")
    rest = ended[done:]
    assert ended[:done] == ["succeeded"] * done, status
    assert rest, f"every order ended before the signal: {status}"
    interrupted = ["interrupted"] + ["cancelled"] * (len(rest) - 1)
    assert rest in (interrupted, ["cancelled"] * len(rest)), status


def test_say_submits_only_what_was_wholly_understood(stack: Stack) -> None:
    half = stack.voicectl("say", "--connect", stack.router, "multiply primes then dance")
    assert half.returncode == 1
    assert json.loads(half.stdout)["order_ids"] == []
    assert half.stderr.splitlines() == [
        "voicectl say: nothing submitted (--partial submits what was understood): "
        "'dance': no order matches",
    ]
    partial = stack.voicectl(
        "say", "--connect", stack.router, "--partial", "multiply primes then dance"
    )
    assert partial.returncode == 0, partial.stderr  # it submitted what was understood
    assert len(json.loads(partial.stdout)["order_ids"]) == 1


def test_supervisor_commands_from_the_cli(stack: Stack) -> None:
    said = stack.voicectl("say", "--connect", stack.router, "multiply primes then turn back")
    assert said.returncode == 0, said.stderr
    first, second = json.loads(said.stdout)["order_ids"]
    moved = stack.voicectl("reorder", "--connect", stack.router, second, "0")
    # the first order may already have run; either way the answer is one clear line
    assert moved.returncode in (0, 1), moved.stderr
    unknown = stack.voicectl("cancel", "--connect", stack.router, "nope")
    assert unknown.returncode == 1
    assert unknown.stderr == "voicectl cancel: order 'nope' is neither queued nor running\n"
    stopped = stack.voicectl("stop", "--connect", stack.router)
    assert stopped.returncode == 0, stopped.stderr
    assert json.loads(stopped.stdout)["type"] == "stopped"
    assert json.loads(stopped.stdout)["confirmed"] is True

    def both_finished() -> bool:
        page = json.loads(stack.voicectl("history", "--connect", stack.router).stdout)
        return {first, second} <= {r["id"] for r in page["records"]}

    wait_until(both_finished, 30.0, "both orders in the history")
    page = json.loads(stack.voicectl("history", "--connect", stack.router, "--limit", "1").stdout)
    assert page["total"] >= 2
    assert len(page["records"]) == 1


def test_a_photo_an_order_took_is_served_to_the_panel(stack: Stack) -> None:
    """A photo is a file on the robot: the panel gets it through the executor, by order."""
    token = Path(stack.env["VOICECTL_DATA"], "token").read_text().strip()
    auth = {"Authorization": f"Bearer {token}"}
    with httpx.Client(base_url=f"http://127.0.0.1:{stack.port}", timeout=30) as http:
        said = http.post("/api/say", json={"text": "take a picture"}, headers=auth)
        assert said.status_code == 200, said.text
        (order_id,) = said.json()["order_ids"]

        record = finished_record(http, auth, order_id, "the photo to be taken")
        assert record["status"] == "succeeded"
        photo = http.get("/api/photo", params={"order": order_id}, headers=auth)
        assert photo.status_code == 200, photo.text
        assert photo.headers["content-type"] == "image/png"
        with PilImage.open(io.BytesIO(photo.content)) as picture:
            assert picture.size == (64, 48)
        assert http.get("/api/photo", params={"order": order_id}).status_code == 401
        missing = http.get("/api/photo", params={"order": "0123abcd"}, headers=auth)
        assert (missing.status_code, missing.json()) == (
            404,
            {"error": "order 0123abcd took no photo kept on this robot"},
        )
        odd = http.get("/api/photo", params={"order": "../../etc/*"}, headers=auth)
        assert odd.status_code == 404
        assert "an order id is letters and digits" in odd.json()["error"]
        assert http.get("/api/photo", headers=auth).status_code == 400


def finished_record(
    http: httpx.Client, auth: dict[str, str], order_id: str, what: str
) -> dict[str, Any]:
    """The history record of `order_id` from the panel's API, once it has ended."""

    def finished() -> dict[str, Any] | None:
        history = http.get("/api/state", headers=auth).json()["history"]
        return next((h for h in history if h["id"] == order_id), None)

    wait_until(finished, 30.0, what)
    record = finished()
    assert record is not None
    return record
