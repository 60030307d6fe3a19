"""The commands hints name (shared/hints.py) run as written where the person is: from the
clone that `scripts/up` installed into (nothing on PATH), from another directory, and with
the installation's bin/ on PATH; the extra named is the one that brings what is missing."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from voicectl.shared.hints import extra_for

from .conftest import REPO

BARE_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
"""A shell's PATH with no virtualenv activated."""
BIN = str(Path(sys.prefix) / "bin")


def hint(expression: str, cwd: Path, path: str) -> str:
    """What `expression` of shared/hints.py says in a process started in `cwd` with `path`
    as its PATH, as a command of voicectl's would say it there."""
    done = subprocess.run(
        [sys.executable, "-c", f"from voicectl.shared.hints import *; print({expression})"],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "PATH": path},
        check=True,
    )
    return done.stdout.strip()


def run_as_written(
    command: str, cwd: Path, path: str, **env: str
) -> subprocess.CompletedProcess[str]:
    """`command` typed into a shell in `cwd` with `path` as its PATH."""
    return subprocess.run(
        ["bash", "-c", command],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "PATH": path, **env},
        timeout=120,
        check=False,
    )


@pytest.mark.parametrize(
    ("where", "path"),
    [("clone", BARE_PATH), ("elsewhere", BARE_PATH), ("clone", f"{BIN}:{BARE_PATH}")],
    ids=["from the clone", "from another directory", "with the venv on PATH"],
)
def test_a_voicectl_command_runs_as_written(where: str, path: str, tmp_path: Path) -> None:
    cwd = REPO if where == "clone" else tmp_path
    command = hint("voicectl_command('token')", cwd, path)
    if path.startswith(BIN):
        assert command == "voicectl token"
    done = run_as_written(command, cwd, path, VOICECTL_DATA=str(tmp_path / "data"))
    assert done.returncode == 0, (command, done.stderr)
    assert done.stdout.strip() == (tmp_path / "data" / "token").read_text().strip()


def test_a_pip_command_installs_the_extra_as_written() -> None:
    """Into this very installation (pip's dry run: it resolves, installs nothing)."""
    command = hint("pip_install('listen')", REPO, BARE_PATH)
    assert "[listen]'" in command, command
    words = shlex.split(command)
    assert words[1] == "install", command
    done = run_as_written(shlex.join([*words[:2], "--dry-run", *words[2:]]), REPO, BARE_PATH)
    assert done.returncode == 0, (command, done.stderr)


def test_an_apt_command_is_for_this_user() -> None:
    command = hint("apt_get_install('libportaudio2')", REPO, BARE_PATH)
    assert command.startswith("apt-get" if os.geteuid() == 0 else "sudo apt-get"), command
    if os.geteuid() == 0:  # apt-get's simulation: reads the package lists, changes nothing
        done = run_as_written(command.replace(" install ", " install -s "), REPO, BARE_PATH)
        assert done.returncode == 0, (command, done.stderr)


@pytest.mark.parametrize(
    ("module", "command_extra", "named"),
    [
        ("soxr", "listen", "listen"),
        ("sounddevice", "listen", "mic"),  # listen's microphone is an extra of its own
        ("text_to_num", "converter", "converter"),  # a robot's `voicectl parse`
        ("text_to_num", "", "converter"),
        ("pocketsphinx", "stt", "stt"),  # in stt and listen both: the command's own
        ("pocketsphinx", "listen", "listen"),
        ("starlette", "host", "host"),  # host brings web's packages
        ("starlette", "", "web"),
        ("cffi", "listen", "listen"),  # no extra names it: the command's own
    ],
)
def test_the_extra_named_is_the_one_that_brings_the_module(
    module: str, command_extra: str, named: str
) -> None:
    assert extra_for(module, command_extra) == named
