"""The panel's spoken answers in a real headless Chromium: off until asked, then STOP's
answer and an order's outcome fetched from /api/speech and played to their end; and the
browser's wording (static/answers.js) held to shared/answers.py's."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec
import pytest

from voicectl.shared.answers import outcome_words, proposal_words, question_words, stopped_words
from voicectl.shared.edits import ended_by_edit
from voicectl.shared.messages import Order, OrderRecord, OrderStatus
from voicectl.shared.words import catalogue

from .conftest import REPO, Stack
from .test_answers import OUTCOMES, PLACES, PROPOSALS, QUESTIONS, STOPS
from .test_panel_browser import CHROMIUM, CHROMIUM_FLAGS, login, panel
from .test_panel_browser import pytestmark as pytestmark  # Chromium installed, or skipped

ANSWERS_JS = REPO / "services" / "web" / "static" / "answers.js"
WORDS_JS = REPO / "services" / "web" / "static" / "words.js"

LISTEN = """
// Every sound the page plays through WebAudio: its length, loudness, and whether it ended
// by itself (played to its end) or was stopped.
window.played = [];
const start = AudioBufferSourceNode.prototype.start;
AudioBufferSourceNode.prototype.start = function (...args) {
  const samples = this.buffer.getChannelData(0);
  let sum = 0;
  for (const sample of samples) sum += sample * sample;
  const sound = { seconds: this.buffer.duration, rms: Math.sqrt(sum / samples.length),
    startedAt: performance.now(), endedAt: null, stopped: false };
  window.played.push(sound);
  this.addEventListener("ended", () => { sound.endedAt = performance.now(); });
  const stop = this.stop;
  this.stop = (...stopArgs) => {
    sound.stopped = sound.endedAt === null;
    return stop.apply(this, stopArgs);
  };
  return start.apply(this, args);
};
"""


@contextmanager
def blank_page(profile: Path) -> Iterator[Any]:
    """A page of nothing, no panel behind it: for scripts that need only a browser."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(
            str(profile), executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS
        )
        try:
            yield browser.new_page()
        finally:
            browser.close()


def played_to_the_end(page: Any, count: int) -> list[dict[str, Any]]:
    """The sounds played once `count` of them have ended; each checked audible and whole."""
    page.wait_for_function(  # a function, not an expression: the panel's CSP forbids eval
        "count => window.played.length >= count && window.played[count - 1].endedAt !== null",
        arg=count,
    )
    sounds: list[dict[str, Any]] = page.evaluate("window.played")
    for sound in sounds[:count]:
        assert not sound["stopped"], sound
        assert 0.3 < sound["seconds"] < 3.0, sound
        assert sound["rms"] > 0.02, sound  # not silence
        assert sound["endedAt"] - sound["startedAt"] >= 0.9 * 1000 * sound["seconds"], sound
    return sounds


def test_answers_are_spoken_only_once_asked(stack: Stack, tmp_path: Path) -> None:
    from playwright.sync_api import Request, expect

    asked: list[str] = []

    def note(request: Request) -> None:
        if "/api/speech" in request.url:
            asked.append(json.loads(request.post_data or "{}")["text"])

    with panel(stack, tmp_path / "profile") as page:
        page.add_init_script(LISTEN)
        page.on("request", note)
        login(page, stack)
        # off by default: STOP says nothing aloud
        expect(page.locator("#speak-answers")).not_to_be_checked()
        page.click("#stop")
        expect(page.locator("#latched")).to_contain_text("Stopped")
        expect(page.locator("#held")).to_be_visible()
        page.wait_for_timeout(500)
        assert asked == []
        page.click("#release")
        expect(page.locator("#held")).to_be_hidden()

        page.check("#speak-answers")
        with page.expect_response("**/api/speech") as answered:
            page.click("#stop")
        wav = answered.value.body()
        assert wav[:4] == b"RIFF"
        assert wav[8:12] == b"WAVE"
        assert answered.value.headers["content-type"] == "audio/wav"
        played_to_the_end(page, 1)
        assert asked == ["stopped"]
        page.click("#release")
        expect(page.locator("#held")).to_be_hidden()

        # an order's outcome, in people's words
        page.fill("#text", "turn left")
        page.press("#text", "Enter")
        page.click("#send")
        expect(page.locator("#history tr").nth(0)).to_contain_text("succeeded")
        played_to_the_end(page, 2)
        assert asked == ["stopped", "turned left"]

        page.reload()  # the setting is remembered
        expect(page.locator("#speak-answers")).to_be_checked()


@pytest.mark.parametrize("language", ["en", "es", "de"])
def test_the_panel_says_what_the_service_would(tmp_path: Path, language: str) -> None:
    """answers.js and shared/answers.py on one table of messages, in each language's words
    (words.js given the catalogue the panel's web service serves). The answers about the
    queue are English in every language, as the queue's phrases are (orders/queue.yaml)."""
    places = msgspec.to_builtins(PLACES)
    cases = (
        [
            ("proposalWords", [msgspec.to_builtins(p)], proposal_words(p, language))
            for p, _ in PROPOSALS
        ]
        + [
            ("outcomeWords", [msgspec.to_builtins(r)], outcome_words(r, language))
            for r, _ in OUTCOMES
        ]
        + [("stoppedWords", [msgspec.to_builtins(s)], stopped_words(s, language)) for s, _ in STOPS]
        + [
            (
                "questionWords",
                [question, msgspec.to_builtins(state), msgspec.to_builtins(pose), places],
                question_words(question, state, pose, PLACES),
            )
            for question, state, pose, _ in QUESTIONS
        ]
        + [("endedByEdit", [msgspec.to_builtins(r)], ended_by_edit(r)) for r in ENDINGS]
    )
    with blank_page(tmp_path / "profile") as page:
        page.add_script_tag(path=str(WORDS_JS))
        page.evaluate(
            "([language, words]) => window.voicectlWords.use({ language, words })",
            [language, catalogue(language)],
        )
        page.add_script_tag(path=str(ANSWERS_JS))
        said = page.evaluate(
            "cases => cases.map(([name, args]) => window.voicectlAnswers[name](...args))",
            [[name, args] for name, args, _ in cases],
        )
    assert said == [expected for _, _, expected in cases]


ENDINGS = [
    OrderRecord(id="1", order=Order(order="o", label="x", description="d"), status=status,
                message=message)
    for status, message in [
        (OrderStatus.CANCELLED, "cancelled by “cancel kitchen”"),
        (OrderStatus.CANCELLED, "replaced by “reach base”"),
        (OrderStatus.CANCELLED, "undone"),
        (OrderStatus.CANCELLED, "cancelled by user"),
        (OrderStatus.SUCCEEDED, "cancelled by “x”"),
    ]
]  # fmt: skip
