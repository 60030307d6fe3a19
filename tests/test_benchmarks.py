"""The benchmarks run: a benchmark measures, the suite only checks that it works (its
--quick mode, a minute at most). No figure is asserted here."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import REPO

QUICK = {
    "e2e": (
        "end of speech -> proposal at /api/events",
        "Send (POST /api/submit) -> first motion",
        "STOP (POST /api/stop) -> zero velocity",
        "baseline: raw Zenoh put -> subscriber",
        "2 speaking: end of speech -> final",
        "panel API: 5 clients x 10 requests: 50 answered, 0 errors",
    ),
    "fleet": (
        "3 robots",
        "Send -> first motion, every robot",
        "STOP -> zero velocity (one robot)",
        "baseline: raw Zenoh put -> subscriber",
        "supervisor RSS MB",
        "(0 problems;",
    ),
    "supervisor": (
        "raw Zenoh request/reply (baseline)",
        "submit to dispatch (order at the executor)",
        "raw Zenoh requests per second (64 in flight)",
        "orders accepted per second (64 in flight)",
    ),
}
"""Each benchmark with --quick, and what its report must hold."""


@pytest.mark.timeout(300)
@pytest.mark.parametrize("bench", sorted(QUICK))
def test_a_benchmark_runs_quickly(bench: str, tmp_path: Path) -> None:
    # The speech e2e makes goes to a directory of the test's own; so do the temporary
    # directories of the benchmark and its services, to see that none is left behind.
    extra = ["--speech", str(tmp_path)] if bench == "e2e" else []
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    done = subprocess.run(
        [sys.executable, "-m", f"bench.{bench}", "--quick", *extra],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "TMPDIR": str(temporary)},
        timeout=280,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    for figure in QUICK[bench]:
        assert figure in done.stdout, done.stdout
    assert not list(temporary.iterdir())
