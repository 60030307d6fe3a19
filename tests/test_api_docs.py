"""docs/api.md against the panel: every route of the app is described, and every example
runs against a real stack and answers as shown."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from voicectl.services.web.app import Access, Panel

from .conftest import REPO, Stack

DOC = REPO / "docs" / "api.md"
FENCE = re.compile(r"```(\w*)\n(.*?)```", re.DOTALL)


def sections() -> dict[str, str]:
    """Each route's section of the doc, by its heading ("GET /api/state")."""
    text = DOC.read_text()
    parts = re.split(r"^### (.+)$", text, flags=re.MULTILINE)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def app_routes() -> set[str]:
    """Every route the app serves, as "METHOD PATH" (WebSocket for sockets)."""
    found = set()
    for route in Panel("robot", Access("token")).routes():
        methods = getattr(route, "methods", None)
        if methods is None:
            found.add(f"WebSocket {route.path}")
        else:
            found |= {f"{method} {route.path}" for method in methods - {"HEAD"}}
    return found


def test_every_route_of_the_app_is_documented_and_no_other() -> None:
    assert set(sections()) == app_routes()


def same_shape(shown: object, got: object, where: str) -> None:
    """`got` has the keys `shown` has, recursively ("...": the rest is not shown); an
    error's words are the ones shown."""
    if isinstance(shown, dict):
        assert isinstance(got, dict), (where, got)
        if "..." not in shown:
            assert set(got) == set(shown), (where, got)
        for key, value in shown.items():
            if key != "...":
                same_shape(value, got[key], f"{where}.{key}")
        if "error" in shown:
            assert got["error"] == shown["error"], where
    elif isinstance(shown, list) and shown:
        assert isinstance(got, list), (where, got)
        assert got, (where, "empty")
        same_shape(shown[0], got[0], f"{where}[0]")
    else:
        assert type(got) is type(shown) or got is None or shown is None, (where, shown, got)


def test_the_examples_answer_as_shown(stack: Stack, tmp_path: Path) -> None:
    text = DOC.read_text()
    variables = FENCE.search(text, text.index("The examples use two shell variables"))
    assert variables is not None, "no block of shell variables in docs/api.md"
    setup = (
        variables.group(2)
        .replace(":8000", f":{stack.port}")
        .replace(".venv/bin/voicectl", f"{sys.executable} -m voicectl")
    )
    env = {**stack.env, "PYTHONPATH": str(REPO)}
    ran = 0
    for heading, body in sections().items():
        blocks = FENCE.findall(body)
        for index, (language, code) in enumerate(blocks):
            shown = blocks[index + 1] if index + 1 < len(blocks) else ("", "")
            if language == "sh":
                done = _bash(f"set -e\n{setup}\n{code}", tmp_path, env)
            elif language == "python":
                script = tmp_path / "example.py"
                script.write_text(code)
                run = f"{setup}\nexport PANEL TOKEN\n{sys.executable} {script}"
                done = _bash(run, tmp_path, env)
            else:
                continue
            ran += 1
            where = f"{heading}: {code.strip()[:60]}"
            if "--max-time" in code:  # a stream, cut off by curl
                assert done.returncode == 28, (where, done.stderr)
                events = [line for line in done.stdout.splitlines() if line.startswith("data: ")]
                kinds = {json.loads(line.removeprefix("data: "))["type"] for line in events}
                expected = set(re.findall(r'"type":"(\w+)"', shown[1]))
                assert expected <= kinds, (where, kinds)
                continue
            assert done.returncode == 0, (where, done.stderr)
            written = re.search(r" -o (\S+)", code)
            if written:
                assert (tmp_path / written.group(1)).read_bytes()[:4] == b"RIFF", where
            elif language == "python":
                assert json.loads(done.stdout.splitlines()[0])["type"] == "session", where
            else:
                assert shown[0] == "json", where
                same_shape(json.loads(shown[1]), json.loads(done.stdout), where)
    assert ran >= 16


def _bash(script: str, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        ["bash", "-c", script],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=60,
        check=False,
    )
