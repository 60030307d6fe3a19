"""The panel in a real headless Chromium against the real stack (`voicectl up`): logging
in from the printed address, typing and speaking through Chromium's fake microphone (a
WAV made with espeak-ng), staging, sending, watching, reordering, cancelling, stopping. The
tests that need only a settled robot share a stack (`OnASettledStack`)."""

from __future__ import annotations

import os
import re
import shutil
import wave
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from harness.wait import async_wait_until
from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.shared.bus import Bus
from voicectl.shared.keys import RobotKeys, last_chunk
from voicectl.shared.messages import Doubt, Proposal

from .conftest import REPO, OnASettledStack, Speak, Stack, on_stack_bus

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMIUM_FLAGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ARTIFACTS = REPO / "test-artifacts"
"""Screenshots of the panel, kept after the run (the directory is ignored by git)."""
WAIT = 60_000
EXPECT_WAIT = 20_000

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(
        not Path(CHROMIUM).exists() and not os.environ.get("CI"),
        reason="Debian's chromium is not installed (scripts/test installs it)",
    ),
]


def chromium_flags(microphone: Path | None = None, extra: tuple[str, ...] = ()) -> list[str]:
    """Chromium's command line flags, with `microphone` (a WAV file, played once from its
    start by every stream that opens it) as the fake microphone."""
    flags = [*CHROMIUM_FLAGS, *extra]
    if microphone is not None:
        flags += [
            "--use-fake-ui-for-media-stream",
            "--use-fake-device-for-media-stream",
            f"--use-file-for-fake-audio-capture={microphone}%noloop",
        ]
    return flags


@contextmanager
def panel(
    stack: Stack, profile: Path, microphone: Path | None = None, extra: tuple[str, ...] = ()
) -> Iterator[Any]:
    """A page for the stack's panel, with `microphone` as the fake microphone."""
    from playwright.sync_api import expect, sync_playwright

    # What the page shows comes over the bus and an event stream: on a machine running
    # two suites at once, 5 s (Playwright's default) was once too short to connect.
    expect.set_options(timeout=EXPECT_WAIT)
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(
            str(profile),
            executable_path=CHROMIUM,
            headless=True,
            args=chromium_flags(microphone, extra),
        )
        try:
            page = browser.new_page()
            page.set_default_timeout(WAIT)
            yield page
        finally:
            browser.close()


@contextmanager
def chromium(microphone: Path | None = None) -> Iterator[Any]:
    """One headless Chromium for several pages (`fresh_page`), each as a person on another
    device would open the panel; `microphone` is the fake microphone of them all."""
    from playwright.sync_api import expect, sync_playwright

    expect.set_options(timeout=EXPECT_WAIT)  # as in `panel`
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(
            executable_path=CHROMIUM, headless=True, args=chromium_flags(microphone)
        )
        try:
            yield browser
        finally:
            browser.close()


@contextmanager
def fresh_page(browser: Any, width: int, height: int) -> Iterator[Any]:
    """A `width` x `height` page of `browser` in a context of its own: a new profile, with
    no token, storage or cache of any page before it."""
    context = browser.new_context(viewport={"width": width, "height": height})
    try:
        page = context.new_page()
        page.set_default_timeout(WAIT)
        yield page
    finally:
        context.close()


def login(page: Any, stack: Stack) -> None:
    """Open the address `voicectl up` prints on a terminal: the token in its fragment logs
    in. (Into the fixture's pipe it prints the address without the token.)"""
    from playwright.sync_api import expect

    prefix = "voicectl up: panel on "
    [address] = [line.removeprefix(prefix) for line in stack.output if line.startswith(prefix)]
    token = Path(stack.env["VOICECTL_DATA"], "token").read_text().strip()
    page.goto(f"{address}#token={token}")
    expect(page.locator("#panel")).to_be_visible()
    assert "token" not in page.url  # the page took the token and dropped the fragment
    for part in ("converter", "stt", "supervisor", "executor", "robot", "navigation"):
        expect(page.locator(f'#parts [data-part="{part}"]')).to_have_class("badge online")


def test_log_in_type_stage_edit_suggest_send_and_watch(stack: Stack, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        page.goto(f"http://127.0.0.1:{stack.port}/")
        expect(page.locator("#login")).to_be_visible()
        page.fill("#token", "wrong")
        page.click("#save-token")
        expect(page.locator("#status")).to_contain_text("token")

        login(page, stack)
        staged = page.locator("#staged li .what")
        page.fill("#text", "turn left then reach kitchen then dance")
        page.press("#text", "Enter")
        expect(staged).to_have_text(["turn left", "reach kitchen"])
        expect(page.locator("#errors li")).to_have_text(["dance no order matches"])

        # edit: keyboard reorder, delete, then a suggestion puts an order back
        page.locator("#staged li").first.focus()
        page.keyboard.press("Alt+ArrowDown")
        expect(staged).to_have_text(["reach kitchen", "turn left"])
        page.drag_and_drop("#staged li:nth-child(2)", "#staged li:nth-child(1)")
        expect(staged).to_have_text(["turn left", "reach kitchen"])
        page.locator("#staged li").nth(0).focus()
        page.keyboard.press("Delete")
        expect(staged).to_have_text(["reach kitchen"])
        page.fill("#text", "turn lift")
        page.press("#text", "Enter")
        page.click("#errors button.suggestion:has-text('turn left')")
        expect(staged).to_have_text(["reach kitchen", "turn left"])
        page.click("#clear")
        expect(staged).to_have_count(0)

        page.fill("#text", "please turn left then reach the kitchen")
        page.press("#text", "Enter")
        expect(staged).to_have_text(["turn left", "reach kitchen"])
        page.click("#send")
        expect(staged).to_have_count(0)
        history = page.locator("#history tr")
        expect(history.nth(0)).to_contain_text("reach kitchen")
        expect(history.nth(0)).to_contain_text("succeeded")
        expect(history.nth(1)).to_contain_text("turn left")
        expect(history.nth(1)).to_contain_text("succeeded")
        expect(page.locator("#pose")).to_contain_text("x 3.0 m")

        # a reload keeps the login and shows the history at once
        page.reload()
        expect(page.locator("#history tr").nth(0)).to_contain_text("succeeded")


def test_queue_reorder_cancel_and_stop(stack: Stack, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        login(page, stack)
        page.fill(
            "#text",
            "wait ten seconds then wait two seconds then wait three seconds then wait four seconds",
        )
        page.press("#text", "Enter")
        page.click("#send")
        queue = page.locator("#queue li .what")
        expect(page.locator("#current")).to_contain_text("wait 10 s")
        expect(queue).to_have_text(["wait 2 s", "wait 3 s", "wait 4 s"])
        page.locator("#queue li").nth(2).locator("button[title='run earlier']").click()
        expect(queue).to_have_text(["wait 2 s", "wait 4 s", "wait 3 s"])
        page.locator("#queue li").nth(0).locator("button:has-text('cancel')").click()
        expect(queue).to_have_text(["wait 4 s", "wait 3 s"])
        page.on("dialog", lambda dialog: dialog.dismiss())  # "cancel all?" answered no
        page.click("#cancel-all")
        expect(queue).to_have_text(["wait 4 s", "wait 3 s"])
        page.click("#stop")  # no question asked
        expect(queue).to_have_count(0)
        expect(page.locator("#current")).to_have_text("idle")
        expect(page.locator("#history tr").nth(0)).to_contain_text("cancelled")
        # the stop latches: new orders are refused until it is released
        expect(page.locator("#held")).to_contain_text("Stopped")
        page.fill("#text", "wait two seconds")
        page.press("#text", "Enter")
        page.click("#send")
        expect(page.locator("#send-note")).to_contain_text("the emergency stop is on")
        page.click("#release")
        expect(page.locator("#held")).to_be_hidden()
        page.click("#send")
        expect(page.locator("#current")).to_contain_text("wait 2 s")


SAID = re.compile(r"^\s*turn left (then|and) reach kitchen\s*$")
SAID_IN = re.compile(r"turn left (then|and) reach kitchen")


def test_speak_a_command_and_a_non_command(stack: Stack, speech: Speak, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    command = speech("turn left then reach kitchen", voice="flite:slt")
    with panel(stack, tmp_path / "speak", microphone=command) as page:
        login(page, stack)
        # what the recogniser listens with is shown beside the microphone
        expect(page.locator("#stt-summary")).to_have_text("Ready to listen")
        expect(page.locator("#stt-status")).to_contain_text("whisper · grammar ")
        expect(page.locator("#stt-status")).to_contain_text("listening for")
        page.click("#mic")
        expect(page.locator("#mic")).to_have_attribute("aria-pressed", "true")
        # "then" and "and" join the same two orders; which one the grammar ear picks from
        # this voice varies with how Chromium's fake microphone paces the file on a busy machine
        expect(page.locator("#heard")).to_have_text(SAID)
        expect(page.locator("#heard")).to_have_class("heard final")
        expect(page.locator("#staged li .what")).to_have_text(["turn left", "reach kitchen"])
        # what each ear heard, and why the orders are these: the engines' words, one
        # click away
        expect(page.locator("#ears")).to_be_hidden()
        page.click("#ears-more summary")
        ears = page.locator("#ears li")
        expect(ears.nth(0)).to_contain_text("grammar")
        expect(ears.nth(0)).to_contain_text(SAID_IN)
        expect(ears.nth(1)).to_contain_text("moonshine")
        expect(ears.nth(1)).to_contain_text("turn left; reach kitchen")
        # then Whisper, when the first two left it a doubt; the decision last
        decided = re.compile(r"grammar(, | and )moonshine( and whisper)? heard 'turn left; reach")
        expect(ears.last).to_contain_text(decided)
        page.click("#mic")  # stop listening
        page.click("#send")
        history = page.locator("#history tr")
        expect(history.nth(0)).to_contain_text("reach kitchen")
        expect(history.nth(0)).to_contain_text("succeeded")
        expect(history.nth(1)).to_contain_text("succeeded")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "panel-spoken.png"), full_page=True)

    chatter = speech("what is the weather like")
    with panel(stack, tmp_path / "chatter", microphone=chatter) as page:
        login(page, stack)
        page.click("#mic")
        expect(page.locator("#heard")).to_have_class("heard rejected")
        expect(page.locator("#heard")).to_contain_text("not a command")
        expect(page.locator("#ears li").nth(1)).to_contain_text("what is the weather like")
        expect(page.locator("#staged li")).to_have_count(0)
        page.screenshot(path=str(ARTIFACTS / "panel-rejected.png"), full_page=True)
        # on a phone's screen STOP stays in view while the page scrolls
        page.set_viewport_size({"width": 390, "height": 844})
        page.mouse.wheel(0, 2000)
        expect(page.locator("#stop")).to_be_in_viewport()
        page.screenshot(path=str(ARTIFACTS / "panel-phone.png"), full_page=False)


class TestOnASettledStack(OnASettledStack):
    """What needs only a settled robot: one stack for it all."""

    def test_a_send_retried_after_a_lost_answer_queues_once(
        self, stack: Stack, tmp_path: Path
    ) -> None:
        from playwright.sync_api import Route, expect

        with panel(stack, tmp_path / "profile") as page:
            login(page, stack)
            page.fill("#text", "wait ten seconds then wait two seconds")
            page.press("#text", "Enter")
            sent: list[str] = []

            def lose_the_first_answer(route: Route) -> None:
                sent.append(route.request.post_data_json["request_id"])
                if len(sent) == 1:
                    route.fetch()  # the server queues the orders...
                    route.abort()  # ...and its answer is lost on the way back
                else:
                    route.continue_()

            page.route("**/api/submit*", lose_the_first_answer)
            page.click("#send")
            expect(page.locator("#send-note")).to_contain_text("Not sent")
            expect(page.locator("#staged li")).to_have_count(2)  # still there to send again
            page.click("#send")
            expect(page.locator("#staged li")).to_have_count(0)
            expect(page.locator("#current")).to_contain_text("wait 10 s")
            expect(page.locator("#queue li .what")).to_have_text(["wait 2 s"])
            assert len(sent) == 2
            assert sent[0] == sent[1], sent

    def test_without_https_the_panel_says_why_there_is_no_microphone(
        self, stack: Stack, tmp_path: Path
    ) -> None:
        from playwright.sync_api import expect

        # panel.test is the stack on loopback, but not "localhost": no secure context
        mapped = ("--host-resolver-rules=MAP panel.test 127.0.0.1",)
        with panel(stack, tmp_path / "profile", extra=mapped) as page:
            token = Path(stack.env["VOICECTL_DATA"], "token").read_text().strip()
            page.goto(f"http://panel.test:{stack.port}/#token={token}")
            expect(page.locator("#panel")).to_be_visible()
            page.click("#mic")
            expect(page.locator("#mic-note")).to_contain_text("only over HTTPS or on localhost")
            expect(page.locator("#mic")).to_have_attribute("aria-pressed", "false")

    def test_a_doubtful_value_is_asked_never_sent(self, stack: Stack, tmp_path: Path) -> None:
        """The recogniser's doubt ("ten", or "two"?) reaches the panel as a choice; with
        auto-send on, nothing is sent until the person picks. The proposal is published on
        the converter's key by the test (a stand-in for a recogniser that doubted): which
        speech makes the real one doubt is tests/test_hearing.py's business."""
        from playwright.sync_api import expect

        silence = silent_wav(tmp_path / "silence.wav", 20.0)
        with panel(stack, tmp_path / "doubt", microphone=silence) as page:
            login(page, stack)
            page.check("#auto-send")
            page.click("#mic")
            expect(page.locator("#mic")).to_have_attribute("aria-pressed", "true")
            keys = RobotKeys("robot")

            async def doubt(bus: Bus) -> None:
                sessions: list[str] = []
                bus.subscribe(
                    keys.stt_audio_any, bytes, lambda key, _raw: sessions.append(last_chunk(key))
                )
                await async_wait_until(lambda: sessions, 20.0, "the panel's audio session")
                said = "go forward ten meters"
                parsed = Parser(OrderSet.load(REPO / "orders")).parse(said)
                proposal = Proposal(
                    transcript=said,
                    orders=parsed.orders,
                    session=sessions[-1],
                    doubts=[Doubt(position=2, words="ten", alternatives=["two"], confidence=0.0)],
                )
                bus.publish(keys.proposal, proposal)

            on_stack_bus(stack, doubt)
            box = page.locator("#doubt")
            expect(box).to_be_visible()
            expect(box.locator("mark")).to_have_text("ten")
            expect(box.locator("button")).to_have_text(["ten", "two", "say again"])
            expect(page.locator("#staged li")).to_have_count(0)
            page.wait_for_timeout(500)  # auto-send had its chance: it must not have taken it
            expect(page.locator("#current")).to_have_text("idle")
            expect(page.locator("#queue li")).to_have_count(0)
            box.locator("button", has_text="two").click()
            expect(box).to_be_hidden()
            expect(page.locator("#staged li .what")).to_have_text(["move forward 2 m"])


def silent_wav(path: Path, seconds: float) -> Path:
    """A 16 kHz mono WAV of silence: a fake microphone that hears nothing."""
    with wave.open(str(path), "wb") as out:
        out.setnchannels(1)
        out.setsampwidth(2)
        out.setframerate(16000)
        out.writeframes(bytes(2 * int(16000 * seconds)))
    return path
