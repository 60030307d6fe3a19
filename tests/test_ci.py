"""CI cannot skip to green: a step that cannot run what it is there to run fails under CI
instead of passing with a word about it."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from .conftest import REPO

FAKE_ENGINE = {
    "docker": 'echo "Cannot connect to the Docker daemon (a fake)" >&2; exit 1',
    "dockerd": 'echo "dockerd: cannot start here (a fake)" >&2; exit 1',
    "sudo": 'exec "$@"',
}
"""Fakes, at the one seam a test cannot reach for real: a machine where no Docker engine
can be started (this one can start one, which the test must not)."""


def no_engine(tmp_path: Path) -> dict[str, str]:
    """An environment whose PATH finds the fake engine first, with no CI variables, and
    temporary files under `tmp_path`."""
    bin_dir = tmp_path / "fake-bin"
    bin_dir.mkdir()
    for name, body in FAKE_ENGINE.items():
        (bin_dir / name).write_text(f"#!/bin/sh\n{body}\n")
        (bin_dir / name).chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "VOICECTL_CONTAINERS")}
    env["PATH"] = f"{bin_dir}:{env['PATH']}"
    env["TMPDIR"] = str(tmp_path)  # where the script keeps its dockerd's log
    return env


@pytest.mark.parametrize(
    ("setting", "status", "said"),
    [
        ({}, 0, "test-containers: SKIPPED: no Docker engine could be started here"),
        ({"CI": "true"}, 1, "test-containers: FAILED: no Docker engine could be started here"),
        (
            {"VOICECTL_CONTAINERS": "required"},
            1,
            "test-containers: FAILED: no Docker engine could be started here",
        ),
    ],
    ids=["elsewhere", "CI", "required"],
)
def test_the_container_step_fails_under_ci_when_no_engine_starts(
    tmp_path: Path, setting: dict[str, str], status: int, said: str
) -> None:
    done = subprocess.run(
        ["bash", str(REPO / "scripts" / "test-containers")],
        env={**no_engine(tmp_path), **setting},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == status, (done.stdout, done.stderr)
    assert said in done.stdout.splitlines()[-1], done.stdout
    assert "dockerd: cannot start here (a fake)" in done.stderr  # its log, shown
