"""README's table of what each command prints, checked against the commands run on a
real stack: the stdout it names, stderr at most one line, the exit statuses it lists."""

from __future__ import annotations

import json
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

from voicectl.cli import build_parser

from .conftest import REPO, Stack

TABLE_AFTER = "What each command prints"


@dataclass(frozen=True)
class Row:
    stdout: str
    stderr: str
    exit: str


def readme_rows() -> dict[str, Row]:
    """Each command of README's table (as written in its first cell) and its row."""
    text = (REPO / "README.md").read_text().partition(TABLE_AFTER)[2]
    rows = {}
    for line in text.splitlines():
        if not line.startswith("| `"):
            if rows:
                break
            continue
        first, stdout, stderr, exit_status = (c.strip() for c in line.strip("|").split(" | "))
        for command in re.findall(r"`([^`]+)`", first):
            rows[command] = Row(stdout, stderr, exit_status)
    return rows


def test_every_command_is_in_the_table() -> None:
    parser = build_parser()
    commands = parser._subparsers._group_actions[0].choices  # type: ignore[union-attr]
    documented = {command.split()[0] for command in readme_rows()}
    assert documented == set(commands)


def promised_keys(row: Row) -> set[str]:
    """The keys of the JSON object a row's stdout names (`a`, `b`, ...); none: any."""
    return set(re.findall(r"`(\w+)`", row.stdout))


def check_shape(command: str, row: Row, code: int, stdout: str, stderr: str) -> None:
    """`command`'s output as its row says: nothing but its stdout's shape on stdout (a
    JSON object with the keys it names), at most one line on stderr (none when it
    succeeded and the row says nothing), and an exit status the row lists (or 2, which
    the README gives every usage error). A row whose object comes "refused or not"
    prints it when refused (exit status 1) too."""
    readme = (REPO / "README.md").read_text()
    usage = code == 2 and re.search(
        r"A usage error .*? exit status 2 for every command", readme, re.S
    )
    assert usage or re.search(rf"\b{code}\b", row.exit), f"{command}: exit {code}, {row.exit!r}"
    if code == 0 and row.stderr.startswith("nothing"):
        assert stderr == "", (command, stderr)
    elif stderr:
        assert stderr.endswith("\n"), (command, stderr)
        assert stderr.count("\n") == 1, (command, stderr)
    lines = stdout.splitlines()
    answers = code == 0 or (code == 1 and "refused or not" in row.stdout)
    if not answers and not stdout:
        return  # a failure may say it only on stderr
    if row.stdout.startswith("a JSON object per file"):
        assert lines, (command, stdout)
        assert all(isinstance(json.loads(line), dict) for line in lines), (command, stdout)
    elif row.stdout.startswith("a JSON object"):
        printed = json.loads(stdout)
        assert isinstance(printed, dict), (command, stdout)
        assert not promised_keys(row) or set(printed) == promised_keys(row), (command, stdout)
    elif row.stdout.startswith("one line per"):
        assert len(lines) > 1, (command, stdout)
    elif row.stdout.startswith("one line"):
        assert len(lines) == 1, (command, stdout)
    else:
        assert row.stdout.startswith("lines for a person"), row.stdout
        assert lines, (command, stdout)


def test_each_command_prints_what_the_readme_says(stack: Stack, tmp_path: Path) -> None:
    rows = readme_rows()
    bus = ("--connect", stack.router)
    panel = ("--url", f"http://127.0.0.1:{stack.port}/api/health")
    runs: list[tuple[str, list[str], int | tuple[int, ...]]] = [
        ("parse TEXT", ["parse", "turn left"], 0),
        ("parse TEXT", ["parse", "turn left then dance"], 1),
        ("transcribe AUDIO.wav...", ["transcribe", "README.md"], 1),
        ("transcribe AUDIO.wav...", ["transcribe", str(tmp_path / "gone.wav")], 2),
        ("say TEXT", ["say", "turn left", *bus], 0),
        ("say TEXT", ["say", "dance", *bus], 1),
        ("say TEXT", ["say", "--partial", "turn left then dance", *bus], 0),
        ("state", ["state", *bus], 0),
        ("history", ["history", "--limit", "5", *bus], 0),
        ("history", ["history", "--limit", "0", *bus], 2),
        ("history", ["history", "--limit", "1000", *bus], 2),
        ("history", ["history", "--offset", "-1", *bus], 2),
        ("cancel ID", ["cancel", "no-such-order", *bus], 1),
        ("reorder ID POSITION", ["reorder", "no-such-order", "0", *bus], 1),
        ("reorder ID POSITION", ["reorder", "no-such-order", "-1", *bus], 2),
        ("cancel-all", ["cancel-all", *bus], 0),
        ("resume", ["resume", *bus], 0),
        # Confirmed, or (on a loaded machine) not confirmed in time: either is documented.
        ("stop", ["stop", *bus], (0, 4)),
        ("say TEXT", ["say", "turn left", *bus], 1),  # refused: the stop is on
        ("release", ["release", *bus], 0),
        ("health SERVICE", ["health", "converter", *bus], 0),
        ("health SERVICE", ["health", "supervisor", "--robot", "nobody", *bus], 1),
        ("health", ["health", *panel, *bus], 0),
        ("token", ["token"], 0),
        ("cert HOST...", ["cert", "localhost", "--out", str(tmp_path / "tls")], 0),
        ("bus-secrets", ["bus-secrets", str(tmp_path / "bus")], 0),
        ("bus-secrets", ["bus-secrets", str(tmp_path / "bus")], 1),
        ("bus-secrets", ["bus-secrets", str(tmp_path / "bus"), "--if-missing"], 0),
        ("bus-secrets", ["bus-secrets", str(tmp_path / "bus"), "--client", "operator"], 0),
        ("bus-secrets", ["bus-secrets", str(tmp_path / "bus"), "--client", "nobody"], 1),
        ("up", ["up", "--router", stack.router, "--port", str(stack.port)], 2),
    ]
    refused = hint = None
    for command, argv, expected in runs:
        done = stack.voicectl(*argv)
        allowed = expected if isinstance(expected, tuple) else (expected,)
        assert done.returncode in allowed, (argv, done.stdout, done.stderr)
        check_shape(command, rows[command], done.returncode, done.stdout, done.stderr)
        if argv[:2] == ["say", "turn left"] and done.returncode == 1:
            refused = json.loads(done.stdout)
            hint = re.search(r"\(([^(]*) release, or Release in the panel\)", done.stderr)
    # The refusal says why, and holds back what was understood without calling it sent.
    assert refused is not None
    assert "emergency stop" in refused["refused"], refused
    assert [order["description"] for order in refused["not_sent"]] == ["turn left"], refused
    assert refused["submitted"] is False
    assert refused["orders"] == refused["order_ids"] == []
    # Its hint runs as written where the command ran (the router named by its variable).
    assert hint is not None
    release = subprocess.run(
        ["bash", "-c", f"{hint.group(1)} release"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**stack.env, "ZENOH_CONNECT": stack.router},
        timeout=60,
        check=False,
    )
    assert release.returncode == 0, (hint.group(1), release.stderr)
