"""CI cannot skip to green: a step that cannot run what it is there to run fails under CI
instead of passing with a word about it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from harness.skips import Allowed, judge

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


# --- the list of skips ------------------------------------------------------------------------

TINY = """
import os

import pytest


def test_runs() -> None:
    pass


def test_runs_in_the_second_step() -> None:
    if os.environ["STEP"] == "first":
        pytest.skip("the second step runs it")


def test_never_runs() -> None:
    pytest.skip("nothing to run it with")
"""


def step(tmp_path: Path, name: str) -> Path:
    """A real pytest run of TINY as the step `name` of a CI run; its JUnit report."""
    (tmp_path / "test_tiny.py").write_text(TINY)
    report = tmp_path / f"{name}.xml"
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q", f"--junitxml={report}"],
        cwd=tmp_path,
        env={**os.environ, "STEP": name},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout
    return report


def skips(*reports: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "harness.skips", *map(str, reports)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )


def test_every_skip_is_listed_and_one_no_step_ran_fails_the_run(tmp_path: Path) -> None:
    first, second = step(tmp_path, "first"), step(tmp_path, "second")
    done = skips(first, second)
    assert done.returncode == 1, done.stdout
    assert done.stdout.splitlines() == [
        "== skipped in this run: 3 (2 that CI is meant to run)",
        "first: test_tiny::test_runs_in_the_second_step: the second step runs it [ran in second]",
        "first: test_tiny::test_never_runs: nothing to run it with "
        "[NOT ALLOWED: CI is meant to run it]",
        "second: test_tiny::test_never_runs: nothing to run it with "
        "[NOT ALLOWED: CI is meant to run it]",
    ]


def test_a_skip_another_step_ran_or_the_allow_list_names_passes(tmp_path: Path) -> None:
    first, second = step(tmp_path, "first"), step(tmp_path, "second")
    allowed = [Allowed("test_tiny::test_never_*", "needs a robot")]
    verdicts, missing = judge([first, second], allowed)
    assert missing == []
    assert [(v.skip.test, v.why_fine) for v in verdicts] == [
        ("test_tiny::test_runs_in_the_second_step", "ran in second"),
        ("test_tiny::test_never_runs", "allowed: needs a robot"),
        ("test_tiny::test_never_runs", "allowed: needs a robot"),
    ]


def test_a_step_without_a_report_ran_nothing_and_fails_the_run(tmp_path: Path) -> None:
    first = step(tmp_path, "first")
    done = skips(first, tmp_path / "containers.xml")
    assert done.returncode == 1
    assert done.stdout.splitlines()[-1] == (
        f"NO REPORT: {tmp_path / 'containers.xml'}: its step ran none of its tests"
    )


STEPS = ("test", "test-install", "test-ros2", "test-containers")
"""The scripts .ci/run runs, in order."""


def ci_run(tmp_path: Path, failing: str = "") -> subprocess.CompletedProcess[str]:
    """.ci/run itself, in a copy of the repository whose steps are stand-ins: each runs
    TINY with pytest and the arguments .ci/run gives it (the first step as `first`, the
    others as `second`); the one named `failing` fails instead, writing nothing."""
    (tmp_path / ".ci").mkdir()
    (tmp_path / ".ci" / "run").write_text((REPO / ".ci" / "run").read_text())
    (tmp_path / "scripts").mkdir()
    (tmp_path / "test_tiny.py").write_text(TINY)
    for name in STEPS:
        role = "first" if name == "test" else "second"
        pytest = f'"{sys.executable}" -m pytest -p no:cacheprovider -q test_tiny.py'
        body = f'STEP={role} exec {pytest} "$@"'
        if name == failing:
            body = "exit 1"
        (tmp_path / "scripts" / name).write_text(f"#!/usr/bin/env bash\n{body}\n")
    return subprocess.run(
        ["bash", str(tmp_path / ".ci" / "run")],
        cwd=tmp_path,
        env={
            **os.environ,
            "VOICECTL_VENV": sys.prefix,
            "PYTHONPATH": str(REPO),  # harness.skips, from this checkout
            "TMPDIR": str(tmp_path),
        },
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


def test_ci_ends_with_the_skips_and_fails_on_one_no_step_ran(tmp_path: Path) -> None:
    done = ci_run(tmp_path)
    assert done.returncode == 1, done.stdout
    tail = done.stdout.splitlines()[-6:]
    assert tail[0] == "== skipped in this run: 5 (4 that CI is meant to run)", done.stdout
    assert tail[1] == (
        "test: test_tiny::test_runs_in_the_second_step: the second step runs it [ran in install]"
    )
    assert tail[2:] == [
        f"{step}: test_tiny::test_never_runs: nothing to run it with "
        "[NOT ALLOWED: CI is meant to run it]"
        for step in ("test", "install", "ros2", "containers")
    ]


def test_ci_that_stops_at_a_failing_step_still_lists_the_skips(tmp_path: Path) -> None:
    done = ci_run(tmp_path, failing="test-ros2")
    assert done.returncode == 1, done.stdout
    lines = done.stdout.splitlines()
    assert "== skipped in this run: 3 (2 that CI is meant to run)" in lines, done.stdout
    assert [line.rsplit("/", 1)[-1] for line in lines if line.startswith("NO REPORT: ")] == [
        "ros2.xml: its step ran none of its tests",
        "containers.xml: its step ran none of its tests",
    ]


# --- tests that skip for something missing fail under CI --------------------------------------


def run_tests(tmp_path: Path, *tests: str, **env: str) -> subprocess.CompletedProcess[str]:
    """Some of the project's own tests, in a pytest of their own, on a PATH with nothing
    on it (no flite, no ip): the machine lacks what they need."""
    empty = tmp_path / "empty-path"
    empty.mkdir(exist_ok=True)
    base = {k: v for k, v in os.environ.items() if k not in ("CI", "VOICECTL_ROS2")}
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-n", "0", "-q", *tests],
        cwd=REPO,
        env={**base, "PATH": str(empty), **env},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )


MISSING = [
    (
        "tests/test_tts.py::test_each_engine_speaks_audibly_for_a_plausible_time[flite]",
        "flite is not installed (scripts/test installs it)",
    ),
    (
        "tests/test_cross_host.py::test_orders_run_across_the_link",
        "two hosts: iproute2's `ip` is not installed",
    ),
]


@pytest.mark.parametrize(("test", "why"), MISSING, ids=["tts", "cross-host"])
def test_a_test_that_lacks_something_skips_elsewhere_and_fails_under_ci(
    tmp_path: Path, test: str, why: str
) -> None:
    elsewhere = run_tests(tmp_path, test, "-rs")
    assert elsewhere.returncode == 0, elsewhere.stdout
    assert why in elsewhere.stdout
    assert "1 skipped" in elsewhere.stdout
    under_ci = run_tests(tmp_path, test, CI="true")
    assert under_ci.returncode == 1, under_ci.stdout
    assert f"{why} (CI is set: every test must run)" in under_ci.stdout


def test_a_real_ros_test_that_lacks_something_fails_where_ros_is_required(tmp_path: Path) -> None:
    test = (
        "tests/test_ros2_transport.py::"
        "test_every_dds_participant_is_in_a_namespace_no_packet_leaves"
    )
    done = run_tests(tmp_path, test, VOICECTL_ROS2="required")
    assert done.returncode == 1, done.stdout
    assert "(VOICECTL_ROS2=required)" in done.stdout
