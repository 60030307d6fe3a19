"""Edits of the queue and questions in the panel, in a real Chromium against the stack: the
edit or question heard (typed, and spoken into the fake microphone), its answer kept true
as the state changes, a correction of an order still staged, and undo of the last edit,
by whoever made it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from voicectl.shared.bus import Bus
from voicectl.shared.client import VoicectlClient

from .conftest import Speak, Stack, on_stack_bus
from .test_panel_browser import login, panel
from .test_panel_browser import pytestmark as pytestmark  # Chromium installed, or skipped


def type_in(page: Any, text: str) -> None:
    page.fill("#text", text)
    page.press("#text", "Enter")


def test_the_panel_shows_edits_and_answers_and_undoes(stack: Stack, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        login(page, stack)
        staged = page.locator("#staged li .what")
        queue = page.locator("#queue li .what")
        answer = page.locator("#talk-answer")

        # An edit is staged like an order, marked as one, and sent with Send.
        type_in(page, "pause")
        expect(staged).to_have_text(["pause"])
        expect(page.locator("#staged li.edit")).to_contain_text("changes the queue")
        expect(page.locator("#staged li")).not_to_contain_text("no executor serves")
        page.click("#send")
        expect(page.locator("#talk-said")).to_have_text("pause")
        expect(answer).to_have_text("paused; 0 waiting")
        expect(page.locator("#undo")).to_have_text("undo “pause”")

        type_in(page, "reach the kitchen then reach the bathroom")
        page.click("#send")
        expect(queue).to_have_text(["reach kitchen", "reach bathroom"])

        # A question is asked at once, never staged, and its answer stays true.
        type_in(page, "how many are left")
        expect(page.locator("#talk-said")).to_have_text("how many are left")
        expect(answer).to_have_text("2 waiting until you say go on")
        expect(staged).to_have_count(0)

        async def elsewhere(bus: Bus) -> None:  # another client changes the queue
            client = VoicectlClient(bus)
            result = await client.parse("cancel the bathroom")
            await client.send("robot", result.orders, "cancel the bathroom")

        on_stack_bus(stack, elsewhere)
        expect(answer).to_have_text("1 waiting until you say go on")
        expect(queue).to_have_text(["reach kitchen"])
        # ... and the panel offers to undo the last edit, whoever made it
        expect(page.locator("#undo")).to_have_text("undo “cancel bathroom”")
        page.click("#undo")
        expect(answer).to_have_text("undone: cancel bathroom")
        expect(queue).to_have_text(["reach kitchen", "reach bathroom"])
        expect(page.locator("#undo")).to_have_text("undo “pause”")

        # An edit naming an order that is not there: said, and nothing changes.
        type_in(page, "cancel the dumpster")
        page.click("#send")
        expect(answer).to_have_text("there is no dumpster in the queue")
        expect(queue).to_have_text(["reach kitchen", "reach bathroom"])

        # A correction of an order staged and not sent replaces it there.
        type_in(page, "go forward two meters")
        expect(staged).to_have_text(["move forward 2 m"])
        type_in(page, "no three")
        expect(staged).to_have_text(["move forward 3 m"])
        expect(answer).to_have_text("now move forward 3 metres, not move forward 2 metres")
        page.click("#clear")

        # The history keeps each edit, with who asked and how.
        history = page.locator("#history tr")
        expect(history.nth(0)).to_contain_text("cancel dumpster")
        expect(history.nth(0)).to_contain_text("there is no dumpster in the queue")
        expect(history.nth(0)).to_contain_text("(panel)")


def test_a_question_spoken_into_the_panel_is_answered(
    stack: Stack, speech: Speak, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    question = speech("what are you doing?", voice="flite:rms")
    with panel(stack, tmp_path / "speak", microphone=question) as page:
        login(page, stack)
        expect(page.locator("#stt-summary")).to_have_text("Ready to listen")
        page.click("#mic")
        expect(page.locator("#talk-said")).to_have_text("what are you doing")
        expect(page.locator("#talk-answer")).to_have_text("nothing: the queue is empty")
        expect(page.locator("#staged li")).to_have_count(0)
