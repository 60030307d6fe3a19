"""The panel's HTTP API and microphone socket, in process with Starlette's TestClient on a
real Zenoh router: every refusal, and the audio bridge's messages on the bus."""

from __future__ import annotations

import functools
import json
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from harness.ports import free_port
from harness.processes import Process
from harness.wait import async_wait_until, wait_until
from voicectl.services.web.app import MAX_BODY, Access, Panel, create_app
from voicectl.shared.bus import BusOptions
from voicectl.shared.keys import MAX_ROBOTS, RobotKeys, robot_of
from voicectl.shared.messages import AudioChunk, AudioMessage, AudioStart, AudioStop

from .conftest import Processes
from .support import ROBOT_GIVEN, on_bus, until_heard

TOKEN = "test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture
def client(router: str) -> Iterator[TestClient]:
    app = create_app(BusOptions(connect=[router]), Panel("robot", Access(TOKEN)))
    with TestClient(app) as test_client:  # runs the lifespan: the app opens its bus
        yield test_client


class AudioListener:
    """A real subscriber on one robot's audio keys, as the recogniser would have."""

    def __init__(self, router: str, robot: str = "robot") -> None:
        self.received: list[tuple[str, AudioMessage]] = []
        self._decoder = msgspec.json.Decoder(AudioMessage)
        self._session = zenoh.open(BusOptions(connect=[router]).zenoh_config())
        self._subscriber = self._session.declare_subscriber(
            RobotKeys(robot).stt_audio_any, self._on_sample
        )
        self._lock = threading.Lock()
        # Listening once the router knows it: the socket waits for a listener, not this test.
        on_bus(router, lambda bus: until_heard(bus, RobotKeys(robot).stt_audio("probe")))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.received.append(
                (str(sample.key_expr), self._decoder.decode(sample.payload.to_bytes()))
            )

    def close(self) -> None:
        self._subscriber.undeclare()
        self._session.close()


@pytest.mark.parametrize(
    ("method", "path"),
    [
        ("GET", "/api/state"),
        ("GET", "/api/history"),
        ("GET", "/api/events"),
        ("GET", "/api/robots"),
        ("POST", "/api/parse"),
        ("POST", "/api/submit"),
        ("POST", "/api/say"),
        ("POST", "/api/cancel"),
        ("POST", "/api/cancel_all"),
        ("POST", "/api/stop"),
        ("POST", "/api/release"),
        ("POST", "/api/resume"),
        ("POST", "/api/reorder"),
        ("POST", "/api/speech"),
    ],
)
def test_every_api_route_needs_the_token(client: TestClient, method: str, path: str) -> None:
    for headers in ({}, {"Authorization": "Bearer wrong"}, {"Authorization": TOKEN}):
        response = client.request(method, path, headers=headers, json={})
        assert response.status_code == 401, (headers, response.text)
        assert "token" in response.json()["error"]


def test_the_page_and_health_need_no_token_and_hold_no_data(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200
    assert TOKEN not in page.text
    assert client.get("/static/panel.js").status_code == 200
    assert client.get("/static/capture.js").status_code == 200
    assert client.get("/api/health").json() == {"ok": True, "robot": "robot"}


def test_no_other_site_may_frame_the_panel_or_run_scripts_in_it(client: TestClient) -> None:
    """Issue 32: the panel sent no Content-Security-Policy or anti-framing header; a page
    elsewhere could frame it and trick a click on Release."""
    for response in (
        client.get("/"),
        client.get("/static/panel.js"),
        client.get("/static/missing.js"),
        client.get("/api/health"),
        client.get("/api/state"),  # refused (no token): a 401 carries them too
    ):
        headers = response.headers
        policy = headers["content-security-policy"]
        assert "frame-ancestors 'none'" in policy
        assert "script-src 'self';" in policy
        assert "default-src 'self';" in policy
        assert headers["x-frame-options"] == "DENY"
        assert headers["x-content-type-options"] == "nosniff"


@pytest.mark.parametrize("name", [".env", "x" * 256, "..%2fapp.py", "missing.js"])
def test_static_paths_outside_the_panel_are_404(client: TestClient, name: str) -> None:
    assert client.get(f"/static/{name}").status_code == 404


def test_bad_bodies_and_parameters_are_4xx_and_change_nothing(client: TestClient) -> None:
    cases = [
        ("/api/parse", b"\xff\xfe not utf-8", 400),
        ("/api/parse", b"[" * 100_000 + b"]" * 100_000, 413),
        ("/api/parse", b'{"text": "x", "extra": 1}', 400),
        ("/api/submit", b'{"orders": []}', 400),
        ("/api/reorder", b'{"order_id": "a"}', 400),
        ("/api/reorder", b'{"order_id": "a", "position": -5}', 400),
        ("/api/parse", b"[" * 20_000, 400),  # deeply nested, under the size limit
        ("/api/parse", b"x" * (MAX_BODY + 1), 413),
    ]
    for path, body, status in cases:
        response = client.post(path, content=body, headers=AUTH)
        assert response.status_code == status, (path, body[:20], response.text)
        assert response.json()["error"]
    assert client.get("/api/state?robot=no/such", headers=AUTH).status_code == 400
    assert client.get("/api/history?offset=1e23", headers=AUTH).status_code == 400
    assert client.get("/api/history?limit=0", headers=AUTH).status_code == 400


def test_without_services_requests_say_what_is_missing(client: TestClient) -> None:
    response = client.post("/api/parse", json={"text": "turn left"}, headers=AUTH)
    assert response.status_code == 503
    assert response.json()["error"].startswith("converter unavailable")
    response = client.get("/api/state", headers=AUTH)
    assert response.status_code == 503
    assert response.json()["error"].startswith("supervisor unavailable")


def test_robots_lists_the_default_robot(client: TestClient) -> None:
    assert client.get("/api/robots", headers=AUTH).json() == {
        "robots": ["robot"],
        "default": "robot",
    }


def test_the_event_stream_starts_with_what_is_known(router: str) -> None:
    app = create_app(BusOptions(connect=[router]), Panel("robot", Access(TOKEN)))
    with (
        TestClient(app) as client,
        client.stream("GET", "/api/events?robot=robot", headers=AUTH) as response,
    ):
        assert response.status_code == 200
        frames = []
        for line in response.iter_lines():
            if line.startswith("data: "):
                frames.append(json.loads(line[6:]))
            if len(frames) == 2:
                break
    assert frames[0] == {
        "type": "parts",
        "robot": "robot",
        "parts": dict.fromkeys(
            ["converter", "stt", "supervisor", "executor", "robot", "navigation"], False
        ),
    }
    assert frames[1] == {"type": "robots", "robots": ["robot"]}


# --- the microphone socket ------------------------------------------------------------------


def test_the_audio_socket_refuses_a_foreign_origin(client: TestClient) -> None:
    with (
        pytest.raises(WebSocketDisconnect) as closed,
        client.websocket_connect(
            "/api/audio", headers={"origin": "https://evil.example"}
        ) as socket,
    ):
        socket.receive_text()
    assert closed.value.code == 4403


def test_the_audio_socket_needs_the_token_first(client: TestClient) -> None:
    for hello, code in (
        ({"token": "wrong", "robot": "robot"}, 4401),
        ({"robot": "robot"}, 1003),
        ({"token": TOKEN, "robot": "../x"}, 1003),
    ):
        with client.websocket_connect(
            "/api/audio", headers={"origin": "http://testserver"}
        ) as socket:
            socket.send_text(json.dumps(hello))
            assert socket.receive_json()["type"] == "error"
            with pytest.raises(WebSocketDisconnect) as closed:
                socket.receive_text()
            assert closed.value.code == code


def test_a_greeting_sent_as_bytes_is_refused_in_words(client: TestClient) -> None:
    with client.websocket_connect("/api/audio", headers={"origin": "http://testserver"}) as socket:
        socket.send_bytes(json.dumps({"token": TOKEN, "robot": "robot"}).encode())
        assert socket.receive_json() == {
            "type": "error",
            "error": "first message must be text: {token, robot}",
        }
        with pytest.raises(WebSocketDisconnect) as closed:
            socket.receive_text()
        assert closed.value.code == 1003


def test_the_audio_socket_says_when_no_recogniser_listens(client: TestClient) -> None:
    with client.websocket_connect("/api/audio") as socket:  # no Origin: not a browser
        socket.send_text(json.dumps({"token": TOKEN, "robot": "robot"}))
        message = socket.receive_json()
        assert message == {"type": "error", "error": "speech recognition is not running"}


def test_audio_frames_become_one_session_on_the_bus(client: TestClient, router: str) -> None:
    listener = AudioListener(router)
    try:
        frames = [bytes([n]) * 640 for n in range(3)]
        with client.websocket_connect(
            "/api/audio", headers={"origin": "http://testserver"}
        ) as socket:
            socket.send_text(json.dumps({"token": TOKEN, "robot": "robot"}))
            hello = socket.receive_json()
            assert hello["type"] == "session"
            socket.send_bytes(frames[0])
            socket.send_bytes(frames[1] + frames[2])
            socket.send_text(json.dumps({"type": "stop"}))
        session = hello["session"]
        wait_until(lambda: len(listener.received) >= 4, 10.0, "the session on the bus")
        key = RobotKeys("robot").stt_audio(session)
        assert listener.received == [
            (key, AudioStart()),
            (key, AudioChunk(seq=0, pcm=frames[0])),
            (key, AudioChunk(seq=1, pcm=frames[1] + frames[2])),
            (key, AudioStop()),
        ]
    finally:
        listener.close()


@pytest.mark.parametrize(
    ("payload", "code", "says"),
    [
        (b"\x00" * 700, 1003, "whole 640-byte frames"),
        (b"\x00" * (640 * 51), 1009, "at most 32000 bytes"),
    ],
)
def test_bad_audio_ends_the_session_with_a_reason(
    client: TestClient, router: str, payload: bytes, code: int, says: str
) -> None:
    listener = AudioListener(router)
    try:
        with client.websocket_connect("/api/audio") as socket:
            socket.send_text(json.dumps({"token": TOKEN, "robot": "robot"}))
            assert socket.receive_json()["type"] == "session"
            socket.send_bytes(payload)
            error = socket.receive_json()
            assert error["type"] == "error"
            assert says in error["error"]
            with pytest.raises(WebSocketDisconnect) as closed:
                socket.receive_text()
            assert closed.value.code == code
        wait_until(
            lambda: any(isinstance(m, AudioStop) for _, m in listener.received), 10.0, "a stop"
        )
        assert not any(isinstance(m, AudioChunk) for _, m in listener.received)
    finally:
        listener.close()


def test_the_api_drives_the_converter_and_supervisor(
    client: TestClient, router: str, processes: Processes
) -> None:
    processes.start("voicectl.services.converter", "--connect", router)
    processes.start("voicectl.services.supervisor", "--robot", "robot", "--connect", router)
    wait_until(
        lambda: client.post("/api/parse", json={"text": "x"}, headers=AUTH).status_code == 200,
        30.0,
        "the converter",
    )
    parsed = client.post(
        "/api/parse", json={"text": "please reach the kitchen then dance"}, headers=AUTH
    ).json()
    assert [o["description"] for o in parsed["orders"]] == ["reach kitchen"]
    assert parsed["errors"][0]["text"] == "dance"
    # /api/say submits nothing when a part of the text was not understood
    said = client.post("/api/say", json={"text": "turn left then dance"}, headers=AUTH).json()
    assert said["order_ids"] == []
    wait_until(
        lambda: client.get("/api/state", headers=AUTH).status_code == 200, 30.0, "the supervisor"
    )
    submitted = client.post(
        "/api/submit?robot=robot", json={"orders": parsed["orders"]}, headers=AUTH
    ).json()
    [order_id] = submitted["order_ids"]
    state = client.get("/api/state", headers=AUTH).json()
    assert [r["id"] for r in state["queue"]] == [order_id]  # no executor: it waits
    assert client.post("/api/cancel", json={"order_id": order_id}, headers=AUTH).status_code == 200
    unknown = client.post("/api/cancel", json={"order_id": "nope"}, headers=AUTH)
    assert unknown.status_code == 409
    history = client.get("/api/history?limit=5", headers=AUTH).json()
    assert history["records"][0]["id"] == order_id
    assert history["records"][0]["status"] == "cancelled"


def test_robots_follow_the_services_on_the_bus(
    client: TestClient, router: str, processes: Processes
) -> None:
    # An open panel hears of the new robot on its event stream, without asking.
    with client.stream("GET", "/api/events?robot=robot", headers=AUTH) as response:
        processes.start("voicectl.services.supervisor", "--robot", "r2", "--connect", router)
        deadline = time.monotonic() + 30.0
        heard: list[object] = []
        for line in response.iter_lines():
            if line.startswith("data: "):
                heard.append(json.loads(line[6:]))
            if {"type": "robots", "robots": ["r2", "robot"]} in heard:
                break
            assert time.monotonic() < deadline, f"no robots frame naming r2 in {heard}"
    assert "r2" in client.get("/api/robots", headers=AUTH).json()["robots"]
    assert client.get("/api/robots", headers=AUTH).json()["default"] == "robot"
    wait_until(
        lambda: client.get("/api/state?robot=r2", headers=AUTH).status_code == 200,
        30.0,
        "r2's supervisor",
    )
    assert client.get("/api/state?robot=r2", headers=AUTH).json()["robot"] == "r2"
    with client.stream("GET", "/api/events?robot=r2", headers=AUTH) as response:
        for line in response.iter_lines():
            if line.startswith("data: ") and '"parts"' in line:
                parts = json.loads(line[6:])
                break
    assert parts["robot"] == "r2"
    assert parts["parts"]["supervisor"] is True
    assert parts["parts"]["executor"] is False


BODY_ROUTES = ("/api/parse", "/api/say", "/api/cancel", "/api/submit", "/api/reorder")


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    route=st.sampled_from(BODY_ROUTES),
    field=st.sampled_from(["text", "order_id", "request_id"]),
    junk=st.one_of(st.binary(min_size=1, max_size=12), st.sampled_from([b"\xc3", b"\xff"])),
    cut=st.integers(min_value=0, max_value=30),
)
def test_undecodable_bodies_are_a_400_never_a_500(
    client: TestClient, route: str, field: str, junk: bytes, cut: int
) -> None:
    """Invalid or truncated UTF-8 inside a JSON string, on every route that reads a body:
    one line saying what is wrong, and the server goes on answering."""
    body = b'{"' + field.encode() + b'":"turn left' + junk + b'"}'
    for sent in (body, body[: len(body) - cut]):
        response = client.post(
            route, content=sent, headers={**AUTH, "Content-Type": "application/json"}
        )
        assert response.status_code != 500, (sent, response.text)  # 503: no service here
        try:
            sent.decode()
        except UnicodeDecodeError:
            assert response.status_code == 400, (sent, response.text)
            assert "\n" not in response.json()["error"]
    assert client.get("/api/robots", headers=AUTH).status_code == 200


def test_a_request_id_reused_for_other_orders_is_a_conflict(
    client: TestClient, router: str, processes: Processes
) -> None:
    processes.start("voicectl.services.supervisor", "--robot", "robot", "--connect", router)
    wait_until(
        lambda: client.get("/api/state", headers=AUTH).status_code == 200, 30.0, "the supervisor"
    )
    wait = {"order": "wait", "label": "wait", "description": "wait 1 s", "params": {"s": 1}}
    other = {**wait, "description": "wait 2 s", "params": {"s": 2}}
    first = client.post("/api/submit", json={"orders": [wait], "request_id": "a1"}, headers=AUTH)
    assert first.status_code == 200, first.text
    again = client.post("/api/submit", json={"orders": [wait], "request_id": "a1"}, headers=AUTH)
    assert again.json() == first.json()  # a retry: the same ids, nothing queued twice
    clash = client.post("/api/submit", json={"orders": [other], "request_id": "a1"}, headers=AUTH)
    assert clash.status_code == 409, clash.text
    assert "request id 'a1' was used for other orders" in clash.json()["error"]
    empty = client.post("/api/submit", json={"orders": [wait], "request_id": ""}, headers=AUTH)
    assert empty.status_code == 400, empty.text
    assert client.get("/api/state", headers=AUTH).json()["queue_length"] == 1


def test_a_robot_name_has_a_length_limit(client: TestClient) -> None:
    response = client.get(f"/api/state?robot={'r' * 60_000}", headers=AUTH)
    assert response.status_code == 400
    assert "longer than 64 characters" in response.json()["error"]


def test_a_session_the_recogniser_cannot_serve_is_refused_in_words(
    client: TestClient, router: str, processes: Processes
) -> None:
    """Past --max-sessions the browser is told, instead of streaming into the void; the
    recogniser says so once, not once per chunk."""
    stt = processes.start(
        "voicectl.services.stt", "--robot", "robot", "--max-sessions", "1", "--connect", router
    )
    hello = json.dumps({"token": TOKEN, "robot": "robot"})
    origin = {"origin": "http://testserver"}

    def first_message(socket: Any) -> dict[str, Any]:
        socket.send_text(hello)
        message: dict[str, Any] = socket.receive_json()
        return message

    wait_until(lambda: "stt ready" in processes.log(stt), 60.0, "the recogniser")
    with client.websocket_connect("/api/audio", headers=origin) as first:
        opened = first_message(first)
        assert opened["type"] == "session", opened
        first.send_bytes(bytes(640))
        with client.websocket_connect("/api/audio", headers=origin) as second:
            assert first_message(second)["type"] == "session"
            for _ in range(20):
                second.send_bytes(bytes(640))
            refused = second.receive_json()
            assert refused["type"] == "error", refused
            assert refused["error"].startswith("speech recognition is busy (1 microphones open)")
            with pytest.raises(WebSocketDisconnect) as closed:
                second.receive_text()
            assert closed.value.code == 4503
    log = processes.log(stt)
    assert log.count("refused: 1 sessions open already") == 1, log
    assert "not started: dropped" not in log, log


def test_open_panels_learn_the_labels_the_executors_serve(
    client: TestClient, router: str, processes: Processes
) -> None:
    """What the executors announce reaches the panel, which flags a staged order no
    executor would take before it is sent."""
    with client.stream("GET", "/api/events?robot=robot", headers=AUTH) as response:
        executor = processes.start(
            "voicectl.services.executor", "--robot", "robot", "--connect", router, *ROBOT_GIVEN
        )
        deadline = time.monotonic() + 30.0
        labels: list[str] = []
        for line in response.iter_lines():
            if line.startswith("data: "):
                frame = json.loads(line[6:])
                if frame["type"] == "labels":
                    assert frame["robot"] == "robot"
                    labels = frame["labels"]
            if "wait" in labels:
                break
            assert time.monotonic() < deadline, f"no labels frame with 'wait': {labels}"
    assert {"drive", "mbgoal", "rotate", "wait"} <= set(labels)
    # Its labels go out before it is up: let it finish starting, so that it stops cleanly.
    wait_until(lambda: "executor ready" in processes.log(executor), 30.0, "the executor")


def test_an_idle_session_ends_and_the_browser_is_told(
    client: TestClient, router: str, processes: Processes
) -> None:
    """A microphone that goes quiet is ended by the recogniser, and the panel hears why;
    the recogniser's status counts the sessions as they open and close."""
    stt = processes.start(
        "voicectl.services.stt", "--robot", "robot", "--idle", "1", "--connect", router
    )
    wait_until(lambda: "stt ready" in processes.log(stt), 60.0, "the recogniser")
    counts: list[int] = []

    def on_status(sample: zenoh.Sample) -> None:
        counts.append(json.loads(sample.payload.to_bytes())["sessions"])

    options = BusOptions(connect=[router]).zenoh_config()
    with zenoh.open(options) as session:
        session.declare_subscriber(RobotKeys("robot").stt_status, on_status)
        with client.websocket_connect(
            "/api/audio", headers={"origin": "http://testserver"}
        ) as socket:
            socket.send_text(json.dumps({"token": TOKEN, "robot": "robot"}))
            assert socket.receive_json()["type"] == "session"
            socket.send_bytes(bytes(640))
            ended = socket.receive_json()  # after a second of silence on the socket
            assert ended == {
                "type": "error",
                "error": "no audio for 1 s: the microphone closed",
            }
            with pytest.raises(WebSocketDisconnect) as closed:
                socket.receive_text()
            assert closed.value.code == 1000
        wait_until(lambda: counts[-1:] == [0], 10.0, "the status to count no session")
    assert 1 in counts, counts


def _panel(router: str, processes: Processes, tmp_path: Path) -> tuple[Process, int]:
    """`voicectl web` as a process of its own, once it serves: its process and port."""
    port = free_port()
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN)
    web = processes.start(
        "voicectl.services.web",
        "--connect",
        router,
        "--port",
        str(port),
        "--token-file",
        str(token_file),
    )
    wait_until(lambda: "panel on" in processes.log(web), 30.0, "the panel")
    return web, port


def test_a_client_gone_mid_body_leaves_no_traceback(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    web, port = _panel(router, processes, tmp_path)
    for route in ("/api/parse", "/api/say", "/api/submit", "/api/cancel"):
        with socket.create_connection(("127.0.0.1", port)) as raw:
            raw.sendall(
                f"POST {route} HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n"
                "Content-Type: application/json\r\nContent-Length: 1000\r\n\r\n"
                '{"text": "turn'.encode()
            )
    # the panel goes on answering, and said nothing alarming
    with socket.create_connection(("127.0.0.1", port)) as raw:
        raw.sendall(b"GET /api/health HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n")
        assert raw.recv(100).startswith(b"HTTP/1.1 200")
    time.sleep(0.5)  # the server's side of the dropped connections has been handled
    log = processes.log(web)
    assert "Traceback" not in log, log
    assert "ClientDisconnect" not in log, log


def test_an_open_event_stream_does_not_hold_up_the_stop(
    router: str, processes: Processes, tmp_path: Path
) -> None:
    """A panel left open in a browser: SIGTERM still stops the service, at once and
    cleanly, and the stream ends instead of breaking off."""
    web, port = _panel(router, processes, tmp_path)
    with socket.create_connection(("127.0.0.1", port), timeout=10.0) as raw:
        raw.sendall(
            f"GET /api/events HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer {TOKEN}\r\n\r\n".encode()
        )
        received = raw.recv(4096)
        assert received.startswith(b"HTTP/1.1 200"), received
        while b"data: " not in received:
            received += raw.recv(4096)
        # Exits by itself (0) within the stop's bound; one that waited for the stream would
        # be killed at the end of it.
        assert processes.stop(web, timeout=10.0) == 0, processes.log(web)
        while chunk := raw.recv(4096):  # the stream's last chunk, then the end
            received += chunk
    assert received.endswith(b"0\r\n\r\n"), received[-200:]
    assert "Traceback" not in processes.log(web), processes.log(web)


class StuckStream:
    """A fake of the bus's audio stream whose puts block, as a put under congestion
    control BLOCK does when the link is congested: congestion cannot be made on loopback."""

    def __init__(self) -> None:
        self.flowing = threading.Event()
        self.sent: list[object] = []
        self.closed = threading.Event()

    def send(self, message: object) -> None:
        self.flowing.wait()
        self.sent.append(message)

    def close(self) -> None:
        self.closed.set()


def test_audio_never_blocks_the_loop_the_stop_is_served_on() -> None:
    from voicectl.services.web.audio import QUEUED, _Sender

    stream = StuckStream()
    sender = _Sender(stream, "s1")  # type: ignore[arg-type]

    def session() -> None:
        sender.send(AudioStart())
        for seq in range(QUEUED * 3):
            sender.send(AudioChunk(seq=seq, pcm=bytes(640)))
        sender.send(AudioStop())
        sender.close()

    sent = threading.Thread(target=session, daemon=True)
    sent.start()
    sent.join(timeout=30.0)
    # Every send returned while the bus was still stuck: nothing waited for it.
    assert not sent.is_alive()
    assert stream.sent == []
    stream.flowing.set()
    assert stream.closed.wait(5.0)
    assert isinstance(stream.sent[0], AudioStart)
    assert isinstance(stream.sent[-1], AudioStop)  # the ends are never dropped
    assert len(stream.sent) <= QUEUED + 2  # new chunks were dropped, not queued for ever


def test_made_up_robots_are_not_listed_and_the_panel_stays_quick(
    client: TestClient, router: str, processes: Processes
) -> None:
    """Issue 32, item 2: 5,000 made-up executors' tokens made /api/robots list 5,001
    robots (and every token cost the panel a sort of them all). Robots are listed when a
    supervisor serves them; others are followed up to a bound, and ignored past it."""
    flood = processes.start("harness.flood", "--connect", router, "--robots", "2000")
    wait_until(lambda: "flooding: 2000" in processes.log(flood), 60.0, "the flood")
    processes.start("voicectl.services.supervisor", "--robot", "r2", "--connect", router)

    def listed() -> list[str]:
        robots: list[str] = client.get("/api/robots", headers=AUTH).json()["robots"]
        return robots

    wait_until(lambda: "r2" in listed(), 30.0, "r2, which a supervisor serves, to be listed")
    # The supervisor takes on made-up robots too, as their executors' tokens reach it, up
    # to its bound (`--max-robots`): the panel lists those it serves, never the flood.
    robots = listed()
    assert {"r2", "robot"} <= set(robots), robots
    assert len(robots) <= 2 + MAX_ROBOTS, len(robots)
    with zenoh.open(BusOptions(connect=[router]).zenoh_config()) as session:
        key = RobotKeys("fake0").alive("supervisor").replace("fake0", "fake$*")
        replies = session.liveliness().get(key, timeout=10.0)
        served = {robot_of(str(reply.ok.key_expr)) for reply in replies if reply.ok}
    assert set(robots) - {"r2", "robot"} <= served, "a robot no supervisor serves is listed"
    assert client.get("/api/health").status_code == 200


async def test_a_flood_of_made_up_robots_is_forgotten_past_the_cap(router: str) -> None:
    """Issue 43: every made-up robot name grew the hub's last frames and labels without
    bound. Now it follows at most `max_robots` besides the default one, as the supervisor
    does (`--max-robots`): the one heard from longest ago that no page shows makes room."""
    from voicectl.services.web.hub import Hub
    from voicectl.shared.messages import RobotPose, SttStatus
    from voicectl.shared.process import running

    from .support import joined

    cap, flood = 20, 300
    encode = msgspec.json.encode
    with joined(router) as bus, zenoh.open(BusOptions(connect=[router]).zenoh_config()) as other:
        hub = Hub(bus, "robot", max_robots=cap)
        async with running(hub):
            with hub.listen("shown"):  # a page shows this robot: it stays, flood or not

                def said(robot: str) -> bool:
                    """Said again until the hub knows it: a sample put before its
                    subscription reached the router is lost."""
                    other.put(RobotKeys(robot).stt_status, encode(SttStatus(engine="real")))
                    return hub.knows(robot, "SttStatus")

                for robot in ("robot", "shown"):
                    status = functools.partial(said, robot)
                    await async_wait_until(status, 30.0, f"{robot}'s status")
                # The hub's watch on the labels reached the router: tokens are heard now.
                tokens = [other.liveliness().declare_token(RobotKeys("shown").label("wave"))]
                await async_wait_until(
                    lambda: hub.labels("shown").labels == ["wave"], 30.0, "the hub's watch"
                )
                # Samples, then tokens: each path keeps its own order, not the other's, so
                # each ends with a robot of its own that the test waits for.
                for i in range(flood):
                    keys = RobotKeys(f"fake{i}")
                    other.put(keys.pose, encode(RobotPose(x=1.0, y=2.0, yaw=0.0)))
                    other.put(keys.stt_status, encode(SttStatus(engine="made-up")))
                other.put(RobotKeys("last").stt_status, encode(SttStatus(engine="made-up")))
                await async_wait_until(lambda: hub.knows("last", "SttStatus"), 30.0, "samples")
                for i in range(flood):
                    tokens.append(
                        other.liveliness().declare_token(RobotKeys(f"tok{i}").label("go"))
                    )
                tokens.append(other.liveliness().declare_token(RobotKeys("last").label("go")))
                await async_wait_until(lambda: hub.labels("last").labels == ["go"], 30.0, "tokens")
                held = hub.held
                assert len(held - {"robot", "shown"}) <= cap, len(held)
                assert {"robot", "shown", "last"} <= held
                # What a page opened now is primed with is still there for those kept.
                with hub.listen("robot") as queue:
                    frames = [queue.get_nowait() for _ in range(queue.qsize())]
                assert any(b'"engine":"real"' in frame for frame in frames)
                assert hub.labels("tok0").labels == []
                assert not hub.knows("fake0", "SttStatus")
                assert hub.knows("shown", "SttStatus")
                for token in tokens:
                    token.undeclare()
