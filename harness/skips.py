"""Every test CI skipped, and why; a failure when one of them is meant to run.

Each step of `.ci/run` (the README's test command, the real ROS 2 tests, the container
tests) writes a JUnit report of its pytest run. A test skipped in one step is fine when
another step ran it (the real ROS 2 tests are skipped by the first step and run by the
second); any other skip must be in `ALLOWED`, with the reason CI may leave it out. A step
that wrote no report ran none of its tests, which is the same as skipping them all.

    python -m harness.skips test.xml ros2.xml containers.xml
"""

from __future__ import annotations

import argparse
import fnmatch
import sys
import xml.etree.ElementTree as ElementTree
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class Allowed:
    """Tests CI may skip: a glob over test ids (`tests.test_x::test_y[param]`)."""

    pattern: str
    reason: str
    """Why CI may leave them out, said beside every one it left out."""


ALLOWED: tuple[Allowed, ...] = ()
"""None today: every test runs in some step of CI. An entry needs a reason a reviewer
accepts; a test that cannot run in CI is better fixed than listed."""


@dataclass(frozen=True)
class Outcome:
    step: str
    """The report it came from, by name (`test` for test.xml)."""
    test: str
    skipped: str | None
    """Why it was skipped; None when it ran (passed, failed or errored)."""


def outcomes(report: Path) -> list[Outcome]:
    """Every test case of a JUnit report, as pytest writes them."""
    found = []
    for case in ElementTree.parse(report).iter("testcase"):
        classname, name = case.get("classname", ""), case.get("name", "")
        test = f"{classname}::{name}" if classname else name  # a module skipped whole
        skipped = case.find("skipped")
        reason = None if skipped is None else skipped.get("message") or "(no reason given)"
        found.append(Outcome(report.stem, test, reason))
    return found


@dataclass(frozen=True)
class Verdict:
    skip: Outcome
    why_fine: str | None
    """Why this skip does not fail CI; None when it does."""


def judge(
    reports: Sequence[Path], allowed: Sequence[Allowed] = ALLOWED
) -> tuple[list[Verdict], list[str]]:
    """Each skip with its verdict, and each report that is missing (its step ran none of
    its tests)."""
    missing = [str(report) for report in reports if not report.is_file()]
    everything = [o for report in reports if report.is_file() for o in outcomes(report)]
    ran: dict[str, str] = {}
    for outcome in everything:
        if outcome.skipped is None:
            ran.setdefault(outcome.test, outcome.step)
    verdicts = []
    for outcome in everything:
        if outcome.skipped is None:
            continue
        fine = None
        if outcome.test in ran:
            fine = f"ran in {ran[outcome.test]}"
        else:
            entry = next((a for a in allowed if fnmatch.fnmatchcase(outcome.test, a.pattern)), None)
            if entry is not None:
                fine = f"allowed: {entry.reason}"
        verdicts.append(Verdict(outcome, fine))
    return verdicts, missing


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m harness.skips", description=__doc__)
    parser.add_argument("reports", nargs="+", type=Path, help="JUnit reports, one per step")
    args = parser.parse_args(argv)
    verdicts, missing = judge(args.reports)
    wrong = [v for v in verdicts if v.why_fine is None]
    print(f"== skipped in this run: {len(verdicts)} ({len(wrong)} that CI is meant to run)")
    for verdict in verdicts:
        skip = verdict.skip
        said = verdict.why_fine or "NOT ALLOWED: CI is meant to run it"
        print(f"{skip.step}: {skip.test}: {skip.skipped} [{said}]")
    for report in missing:
        print(f"NO REPORT: {report}: its step ran none of its tests")
    return 1 if wrong or missing else 0


if __name__ == "__main__":
    sys.exit(main())
