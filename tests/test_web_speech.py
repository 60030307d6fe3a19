"""The panel's spoken answers on the HTTP API (POST /api/speech in services/web/app.py), in
process with Starlette's TestClient on a real Zenoh router and real espeak-ng; and
`voicectl web --voice` refusing an engine that is not installed."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from starlette.testclient import TestClient

from voicectl.services.web.app import Access, Panel, create_app
from voicectl.shared.bus import BusOptions
from voicectl.shared.tts import MAX_TEXT, CommandVoice, Voice, from_wav, load_voice

from .conftest import REPO

TOKEN = "test-token-0123456789"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@contextmanager
def serving(router: str, voice: Voice | None) -> Iterator[TestClient]:
    """The panel's app with `voice` (None: `--voice none`), its lifespan running."""
    app = create_app(BusOptions(connect=[router]), Panel("robot", Access(TOKEN), voice))
    with TestClient(app) as client:
        yield client


def test_speech_is_a_wav_of_the_text(router: str) -> None:
    with serving(router, load_voice("espeak-ng")) as client:
        answer = client.post("/api/speech", json={"text": "reached kitchen"}, headers=AUTH)
        assert answer.status_code == 200, answer.text
        assert answer.headers["content-type"] == "audio/wav"
        assert answer.content[:4] == b"RIFF"
        assert answer.content[8:12] == b"WAVE"
        assert 0.5 < from_wav(answer.content).seconds < 3.0


def test_speech_needs_the_token(router: str) -> None:
    with serving(router, load_voice("espeak-ng")) as client:
        for headers in ({}, {"Authorization": "Bearer wrong"}):
            refused = client.post("/api/speech", json={"text": "stopped"}, headers=headers)
            assert refused.status_code == 401
            assert "token" in refused.json()["error"]


def test_bad_requests_are_4xx_in_one_line(router: str) -> None:
    cases = [
        (b"not json", 400),
        (b'{"text": ""}', 400),
        (b'{"text": "   "}', 400),  # nothing to say once the spaces go
        (b'{"words": "stopped"}', 400),
        (b'{"text": "stopped", "voice": "x"}', 400),
        (b'{"text": 7}', 400),
        (b'{"text": "%s"}' % (b"a" * (MAX_TEXT + 1)), 400),
        (b"x" * 100_000, 413),
    ]
    with serving(router, load_voice("espeak-ng")) as client:
        for body, status in cases:
            answer = client.post("/api/speech", content=body, headers=AUTH)
            assert answer.status_code == status, (body[:30], answer.text)
            error = answer.json()["error"]
            assert error
            assert "\n" not in error
        assert client.get("/api/speech", headers=AUTH).status_code == 405


def test_with_spoken_answers_off_the_route_says_so(router: str) -> None:
    with serving(router, None) as client:
        answer = client.post("/api/speech", json={"text": "stopped"}, headers=AUTH)
        assert answer.status_code == 404
        assert answer.json() == {"error": "spoken answers are off (voicectl web --voice none)"}


def test_an_engine_gone_from_the_machine_is_unavailable_not_a_crash(router: str) -> None:
    gone = CommandVoice("flite", lambda text: (["/nonexistent/flite", text], b""), "apt-get x")
    with serving(router, gone) as client:
        answer = client.post("/api/speech", json={"text": "stopped"}, headers=AUTH)
        assert answer.status_code == 503
        assert answer.json()["error"] == "speech engine 'flite' is not installed (apt-get x)"


def test_the_service_refuses_to_start_with_an_engine_that_is_not_installed(
    tmp_path: Path,
) -> None:
    env = {"PATH": str(tmp_path), "VOICECTL_DATA": str(tmp_path / "data")}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "voicectl",
            "web",
            "--voice",
            "flite",
            "--connect",
            "tcp/127.0.0.1:9",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "voicectl web: speech engine 'flite' is not installed (apt-get install flite); "
        "or --voice none"
    )
