"""The panel's usability review, item by item, in a real headless Chromium against the
real stack, on a desktop's screen (1280x800) and a phone's (390x844): messages where they
belong and gone once stale, the latched stop in the header, the phone's first screen,
suggestions that repair the sentence, Stop listening, the map's warnings and labels, words
for people, the icon. Screenshots go to $VOICECTL_ARTIFACTS (default test-artifacts/)
under usability/."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from playwright.sync_api import Page

from .conftest import Stack
from .test_panel_browser import ARTIFACTS, login, panel, pytestmark

__all__ = ["pytestmark"]  # the browser's marks and skip, as in test_panel_browser

SCREENS = {"desktop": (1280, 800), "phone": (390, 844)}
SHOTS = Path(os.environ.get("VOICECTL_ARTIFACTS", str(ARTIFACTS))) / "usability"


@pytest.fixture(params=list(SCREENS))
def screen(request: pytest.FixtureRequest) -> str:
    """The screen a test runs on: 'desktop' or 'phone'."""
    name: str = request.param
    return name


def open_panel(page: Page, stack: Stack, screen: str) -> None:
    width, height = SCREENS[screen]
    page.set_viewport_size({"width": width, "height": height})
    login(page, stack)


def shot(page: Page, name: str, screen: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}-{screen}.png"))


def box(page: Page, selector: str) -> dict[str, float]:
    found = page.locator(selector).bounding_box()
    assert found is not None, f"{selector} is not shown"
    return dict(found)


def on_first_screen(page: Page, selector: str) -> None:
    """`selector` lies wholly inside the first screen (the page scrolled to its top)."""
    place = box(page, selector)
    height = page.viewport_size["height"] if page.viewport_size else 0
    assert place["y"] >= 0, (selector, place)
    assert place["y"] + place["height"] <= height, (selector, place)


def type_command(page: Page, text: str) -> None:
    page.fill("#text", text)
    page.press("#text", "Enter")


def test_messages_stand_by_their_control_and_go_when_stale(
    stack: Stack, tmp_path: Path, screen: str
) -> None:
    """Items 1, 2 and 8: Send refused under a latched stop says so under Send, in the
    panel's words, and the note goes when the stop is released; the latched header reads
    "Stopped — Release"; a lost connection is a banner that goes once it is back, with
    the stale queue, map and recogniser marked so; no request of the page fails (the
    icon)."""
    from playwright.sync_api import Response, expect

    missing: list[str] = []

    def note_failure(response: Response) -> None:
        if response.status >= 400 and "/api/" not in response.url:
            missing.append(f"{response.status} {response.url}")

    with panel(stack, tmp_path / "profile") as page:
        page.on("response", note_failure)
        open_panel(page, stack, screen)
        type_command(page, "wait two seconds")
        expect(page.locator("#staged li")).to_have_count(1)

        page.click("#stop")
        latched = page.locator("#latched")
        expect(latched).to_be_visible()
        expect(latched).to_contain_text("Stopped")
        expect(page.locator("#stop")).to_be_hidden()
        expect(page.locator("header #head-release")).to_have_text("Release")
        expect(page.locator("#held-why")).to_have_text(
            "Stopped: the robot is halted and its orders cancelled. Release it to send new orders."
        )
        page.mouse.wheel(0, 3000)  # wherever the person has scrolled to
        expect(latched).to_be_in_viewport()
        page.evaluate("window.scrollTo(0, 0)")

        page.click("#send")
        sent = page.locator("#send-note")
        expect(sent).to_contain_text("the emergency stop is on")
        assert "voicectl" not in sent.inner_text()
        # beside Send, not at the bottom of the page
        below = box(page, "#send-note")["y"] - box(page, "#send")["y"]
        assert 0 < below < 200, below
        expect(page.locator("#banner")).to_be_hidden()
        shot(page, "1-send-refused-while-latched", screen)

        page.click("#head-release")
        expect(latched).to_be_hidden()
        expect(page.locator("#stop")).to_be_visible()
        expect(sent).to_be_hidden()  # no longer true: gone by itself
        page.click("#send")
        expect(page.locator("#current")).to_contain_text("wait 2 s")
        expect(sent).to_be_hidden()

        type_command(page, "wait ten seconds then wait ten seconds")
        page.click("#send")
        expect(page.locator("#queue li")).to_have_count(1)
        kill_the_web_service(stack)  # `voicectl up` starts it again
        banner = page.locator("#banner")
        expect(banner).to_contain_text("Connection to the robot lost")
        expect(banner).to_be_in_viewport()
        expect(page.locator("#stt-summary")).to_contain_text("Not connected")
        expect(page.locator("#queue button").first).to_be_disabled()
        expect(page.locator("#map-stale")).to_be_visible()
        shot(page, "1-connection-lost", screen)
        expect(page.locator("#connection")).to_have_text("connected", timeout=60_000)
        expect(banner).to_be_hidden()
        expect(page.locator("#map-stale")).to_be_hidden()
        expect(page.locator("#stt-summary")).to_have_text("Ready to listen")
        expect(page.locator("#queue button").first).to_be_enabled()

    assert missing == []
    answer = stack_get(stack, "/favicon.ico")
    assert answer[0] == 200, answer
    assert answer[1].startswith("image/svg"), answer


def kill_the_web_service(stack: Stack) -> None:
    """SIGKILL the stack's web service (its panel's server), as a crash would."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if parent == stack.process.pid and b"services.web" in argv:
            os.kill(int(entry.name), signal.SIGKILL)
            return
    raise AssertionError("no web service under the stack")


def stack_get(stack: Stack, path: str) -> tuple[int, str]:
    import urllib.request

    with urllib.request.urlopen(f"http://127.0.0.1:{stack.port}{path}", timeout=10) as reply:
        return reply.status, reply.headers.get("content-type", "")


def test_the_first_screen_holds_speak_the_current_order_and_stop(
    stack: Stack, tmp_path: Path, screen: str
) -> None:
    """Item 3: with an order running, Listen, the order with its progress and STOP (or,
    latched, Release) are on the first screen without scrolling."""
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        open_panel(page, stack, screen)
        type_command(page, "wait twenty seconds then turn left")
        page.click("#send")
        expect(page.locator("#current .progress-text")).not_to_be_empty()
        page.evaluate("window.scrollTo(0, 0)")
        for selector in ("#mic", "#current .what", "#current .progress-text", "#stop"):
            on_first_screen(page, selector)
        shot(page, "3-first-screen", screen)
        page.click("#stop")
        expect(page.locator("#latched")).to_be_visible()
        on_first_screen(page, "#head-release")
        on_first_screen(page, "#held-why")
        shot(page, "3-first-screen-latched", screen)
        # nothing scrolls sideways
        assert page.evaluate("document.documentElement.scrollWidth") <= SCREENS[screen][0]
