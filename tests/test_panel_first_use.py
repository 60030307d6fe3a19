"""The panel as a first-time user meets it, in a real headless Chromium against the real
stack, on a desktop's screen and a phone's: a failed order stays in "Now" until the next
one starts or it is dismissed; goals outside the robot's map are warned of in one
sentence; History says why an order was cancelled in words, never an id; the header says
what is down as a person notices it; the engines', files' and keys' words are one click
away. Screenshots go to $VOICECTL_ARTIFACTS (default test-artifacts/) under usability/."""

from __future__ import annotations

import os
import re
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from .conftest import OnASettledStack, Stack
from .test_panel_browser import chromium, login
from .test_panel_usability import pytestmark as usability_marks
from .test_panel_usability import screen_page, screens, shot, type_command

if TYPE_CHECKING:
    from playwright.sync_api import Page

pytestmark = usability_marks

ORDER_ID = re.compile(r"\b[0-9a-f]{16}\b")
"""How the supervisor names an order for programs."""
THREE_DRIVES = "go forward ten meters then go forward ten meters then go forward ten meters"
"""At least two of its goals lie outside the simulator's map (walls at 10 m), wherever in
it the robot stands: the first of those fails, and the rest of the command is cancelled."""


def test_a_failure_stays_in_now_and_history_says_why_the_rest_was_cancelled(
    stack: Stack, subtests: pytest.Subtests
) -> None:
    """Two or more staged goals outside the map: one sentence naming them all. Sent: the
    failure stays in "Now" while nothing runs, History names the order that failed in the
    reason of those cancelled after it; the next order that starts takes its place; a
    failure dismissed is gone."""
    from playwright.sync_api import expect

    with chromium() as browser:
        for screen in screens(stack):
            with subtests.test(screen=screen), screen_page(browser, screen) as page:
                login(page, stack)
                expect(page.locator("#map image.grid")).to_have_count(1)
                type_command(page, THREE_DRIVES)
                warning = page.locator("#goal-warning")
                expect(warning).to_contain_text("outside the robot's map")
                said = warning.inner_text()
                assert said.count("outside the robot's map") == 1, said  # one sentence...
                assert "their goals are outside the robot's map" in said, said  # ...for all
                assert said.count("(") >= 2, said  # each named by its number on the map
                shot(page, "47-one-warning", screen)

                page.click("#send")
                now = page.locator("#current")
                failure = now.locator(".ended.failed")
                expect(failure).to_contain_text("move forward 10 m failed: ", timeout=60_000)
                expect(failure).to_contain_text("outside the robot's map")
                expect(now).not_to_contain_text("idle")
                cancelled = page.locator("#history tr", has_text="cancelled").first
                expect(cancelled.locator("td.message")).to_have_text(
                    "cancelled because “move forward 10 m” before it failed"
                )
                assert not ORDER_ID.search(page.locator("#history").inner_text())
                shot(page, "47-failure-in-now", screen)

                type_command(page, "wait two seconds")
                page.click("#send")
                expect(now).to_contain_text("wait 2 s")  # the next order took its place
                expect(failure).to_have_count(0)
                expect(now).to_have_text("idle", timeout=60_000)  # and it is not back

                type_command(page, "go forward ten meters then go forward ten meters")
                page.click("#send")
                expect(failure).to_be_visible(timeout=60_000)
                failure.get_by_role("button", name="dismiss").click()
                expect(now).to_have_text("idle")


@contextmanager
def robot_not_answering(stack: Stack) -> Iterator[None]:
    """The simulated robot stopped (SIGSTOP), as a robot that hangs: no odometry comes;
    it goes on (SIGCONT) on leaving."""
    sim = child_pid(stack, "sim")
    os.kill(sim, signal.SIGSTOP)
    try:
        yield
    finally:
        os.kill(sim, signal.SIGCONT)


def child_pid(stack: Stack, name: str) -> int:
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if parent == stack.process.pid and f"voicectl.services.{name}".encode() in argv:
            return int(entry.name)
    raise AssertionError(f"no {name} service under the stack")


def visible_text(page: Page, selector: str) -> str:
    """What of `selector` a person sees (innerText leaves out what is hidden)."""
    return str(page.locator(selector).inner_text())


class TestOnASettledStack(OnASettledStack):
    """The items that need only a settled robot: one stack for them all."""

    def test_the_header_says_what_is_down_in_words(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """What is up is not listed; what is down is said as a person notices it, on a
        desktop as on a phone; the part's own name is in its title."""
        from playwright.sync_api import expect

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
                    parts = page.locator("#parts")
                    for part in ("converter", "stt", "supervisor", "executor", "robot"):
                        expect(parts.locator(f'[data-part="{part}"]')).to_be_hidden()
                    with robot_not_answering(stack):
                        down = parts.locator('[data-part="robot"]')
                        expect(down).to_have_text("the robot is not answering", timeout=30_000)
                        expect(down).to_be_visible()
                        expect(down).to_have_attribute("title", "robot offline")
                        assert visible_text(page, "#parts") == "the robot is not answering"
                        shot(page, "47-robot-not-answering", screen)
                    expect(parts.locator('[data-part="robot"]')).to_be_hidden(timeout=30_000)

    def test_engineers_words_are_one_click_away(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """The login asks for an access code (the API token one click away); the keyboard
        hint is for a keyboard, the buttons' for a phone."""
        from playwright.sync_api import expect

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    page.goto(f"http://127.0.0.1:{stack.port}/")
                    expect(page.locator("#login")).to_be_visible()
                    assert "token" not in visible_text(page, "#login").lower()
                    page.click("#login summary")
                    expect(page.locator("#login details")).to_contain_text("API token")
                    login(page, stack)
                    keys, touch = page.locator(".hint.keys"), page.locator(".hint.touch")
                    if screen == "phone":
                        expect(keys).to_be_hidden()
                        expect(touch).to_be_visible()
                    else:
                        expect(keys).to_be_visible()
                        expect(touch).to_be_hidden()
                    assert "Alt+" not in visible_text(page, "#staging") or screen != "phone"
