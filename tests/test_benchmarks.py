"""The benchmarks run: a benchmark measures, the suite only checks that it works, at the
smallest size that still reports every figure (`RUNS`). No figure is asserted here."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import REPO

QUICK = {
    "edits": (
        "--- dev, clean",
        "commands: ",
        "non-commands: ",
        "speech end -> edit applied (answer)",
        "speech end -> answer's first sound",
        "baseline: typed -> edit applied",
    ),
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
    "languages": ("de dev: 4 of", "non-commands refused", "p95", "espeak clean"),
    "supervisor": (
        "raw Zenoh request/reply (baseline)",
        "submit to dispatch (order at the executor)",
        "raw Zenoh requests per second (64 in flight)",
        "orders accepted per second (64 in flight)",
    ),
}
"""What each benchmark's report must hold."""

RUNS = {
    "edits": ["--split", "dev", "--conditions", "clean", "--sample", "3"],
    "e2e": [
        *("--utterances", "3", "--speakers", "1,2", "--rounds", "1"),
        *("--clients", "5", "--requests", "10"),
    ],
    "fleet": ["--robots", "3", "--seconds", "4"],
    "supervisor": ["--quick"],
    "languages": [*("--language", "de", "--split", "dev", "--limit", "4", "--paced", "0.3")],
}
"""How each runs here. --quick is a person's one-minute look at the figures: e2e's streams
10 utterances in real time and fleet's keeps its robots busy for 8 s, more than the report
needs: three utterances are one in each of the benchmark's voices, and 4 s give each
robot an order (one every 3 s, the first within 3 s), the STOP included. The rest is as
--quick has it."""


@pytest.mark.timeout(300)
@pytest.mark.parametrize("bench", sorted(QUICK))
def test_a_benchmark_runs_quickly(bench: str, tmp_path: Path) -> None:
    # The speech e2e makes goes to a directory of the test's own; so do the temporary
    # directories of the benchmark and its services, to see that none is left behind.
    where = {"e2e": ["--speech", str(tmp_path)], "languages": ["--set", str(tmp_path)]}
    extra = where.get(bench, [])
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    done = subprocess.run(
        [sys.executable, "-m", f"bench.{bench}", *RUNS[bench], *extra],
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
