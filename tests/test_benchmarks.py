"""The benchmarks run: a benchmark measures, the suite only checks that it works (its
--quick mode, a minute at most). No figure is asserted here."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import REPO


@pytest.mark.timeout(300)
def test_e2e_runs_voice_to_motion_and_the_panel_api_quickly(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "bench/e2e.py", "--quick", "--speech", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=280,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    for figure in (
        "end of speech -> proposal at /api/events",
        "Send (POST /api/submit) -> first motion",
        "STOP (POST /api/stop) -> zero velocity",
        "baseline: raw Zenoh put -> subscriber",
        "2 speaking: end of speech -> final",
        "panel API: 5 clients x 10 requests: 50 answered, 0 errors",
    ):
        assert figure in done.stdout, done.stdout


@pytest.mark.timeout(300)
def test_fleet_runs_robots_beside_each_other_quickly() -> None:
    done = subprocess.run(
        [sys.executable, "bench/fleet.py", "--quick"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=280,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    for figure in (
        "3 robots",
        "Send -> first motion, every robot",
        "STOP -> zero velocity (one robot)",
        "baseline: raw Zenoh put -> subscriber",
        "supervisor RSS MB",
        "(0 problems;",
    ):
        assert figure in done.stdout, done.stdout
