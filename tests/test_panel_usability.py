"""The panel's usability review, item by item, in a real headless Chromium against the
real stack, on a desktop's screen (1280x800) and a phone's (390x844): messages where they
belong and gone once stale, the latched stop in the header, the phone's first screen,
suggestions that repair the sentence, Stop listening, the map's warnings and labels, words
for people, the icon. Screenshots go to $VOICECTL_ARTIFACTS (default test-artifacts/)
under usability/.

A test runs both screens on one stack and one Chromium: the desktop's pass, then the
phone's, each in a fresh browser context (no token, no storage: another person's device)
and each a subtest, so that a failure on one screen still has the other checked. Between
passes the stack is settled as it came up (`settle`: the stop released, nothing queued or
running); what settling cannot take back, the history and where the robot stands, the
tests that look at it reckon with, each on a stack of its own. The tests that need only a
settled robot share a stack, settled before each (`TestOnASettledStack`)."""

from __future__ import annotations

import os
import re
import signal
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from voicectl.services.converter.orders import OrderSet
from voicectl.services.converter.parser import Parser
from voicectl.shared.bus import Bus
from voicectl.shared.keys import RobotKeys, last_chunk
from voicectl.shared.messages import Doubt, Proposal

if TYPE_CHECKING:
    from playwright.sync_api import Browser, Page

from harness.wait import async_wait_until, wait_until

from .conftest import REPO, OnASettledStack, Speak, Stack, on_stack_bus, settle
from .test_panel_browser import ARTIFACTS, chromium, fresh_page, login, silent_wav
from .test_panel_browser import pytestmark as browser_marks

# Both screens in one test: twice the time a test of one screen had.
pytestmark = [*browser_marks, pytest.mark.timeout(240)]

SCREENS = {"desktop": (1280, 800), "phone": (390, 844)}
HELD_WHY = "Stopped: the robot is halted and its orders cancelled. Release it to send new orders."
"""What the latched stop's box says."""
SHOTS = Path(os.environ.get("VOICECTL_ARTIFACTS", str(ARTIFACTS))) / "usability"


def screens(stack: Stack, fresh: bool = True) -> Iterator[str]:
    """Each screen's name in turn, the stack settled before each pass but the first (and
    before that one too unless the stack is `fresh`: nothing of the test has run on it)."""
    for index, screen in enumerate(SCREENS):
        if index or not fresh:
            settle(stack)
        yield screen


@contextmanager
def screen_page(browser: Browser, screen: str) -> Iterator[Page]:
    """A fresh page of `browser` the size of `screen`."""
    width, height = SCREENS[screen]
    with fresh_page(browser, width, height) as page:
        yield page


def shot(page: Page, name: str, screen: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}-{screen}.png"))


def box(page: Page, selector: str) -> dict[str, float]:
    """Where `selector` is drawn, once it is: the panel draws some parts anew at every
    update (the running order's at each step of its progress), and an element measured
    as it is replaced has no box."""
    found: list[dict[str, float]] = []

    def measured() -> bool:
        drawn = page.locator(selector).bounding_box()
        found[:] = [dict(drawn)] if drawn is not None else []
        return bool(found)

    wait_until(measured, 20.0, f"{selector} to be shown")
    return found[0]


def on_first_screen(page: Page, selector: str) -> None:
    """`selector` lies wholly inside the first screen (the page scrolled to its top)."""
    place = box(page, selector)
    height = page.viewport_size["height"] if page.viewport_size else 0
    assert place["y"] >= 0, (selector, place)
    assert place["y"] + place["height"] <= height, (selector, place)


def type_command(page: Page, text: str) -> None:
    page.fill("#text", text)
    page.press("#text", "Enter")


def publish_proposal(stack: Stack, said: str, *doubts: Doubt) -> None:
    """A proposal for the panel's open microphone, with `doubts` (a stand-in for a
    recogniser that doubted, as in test_panel_browser)."""
    keys = RobotKeys("robot")

    async def propose(bus: Bus) -> None:
        sessions: list[str] = []
        bus.subscribe(keys.stt_audio_any, bytes, lambda key, _raw: sessions.append(last_chunk(key)))
        await async_wait_until(lambda: sessions, 20.0, "the panel's audio session")
        parsed = Parser(OrderSet.load(REPO / "orders")).parse(said)
        proposal = Proposal(
            transcript=said, orders=parsed.orders, session=sessions[-1], doubts=list(doubts)
        )
        bus.publish(keys.proposal, proposal)

    on_stack_bus(stack, propose)


SENTENCE = "go forward two meters then turn left then reach the kitchen then wait two seconds"


def stop_mid_sentence(page: Page, then: str = "", after: str = "") -> str:
    """Listen, and stop listening once the recogniser has shown part of the sentence (with
    `after` in it, if given) (and
    click `then` in the same turn of the page's event loop, before any answer can come);
    what the page says right after the stop."""
    from playwright.sync_api import expect

    heard = page.locator("#heard")
    page.click("#mic")
    expect(page.locator("#stt-summary")).to_have_text("Listening")
    expect(heard).not_to_have_text("listening…")
    expect(heard).to_have_class("heard partial")
    if after:
        expect(heard).to_contain_text(after)
    said: str = page.evaluate(
        """then => {
            document.querySelector("#mic").click();
            const said = document.querySelector("#heard").textContent;
            if (then) document.querySelector(then).click();
            return said;
        }""",
        then,
    )
    assert said.startswith("finishing “"), said
    return said


class TestOnASettledStack(OnASettledStack):
    """The items that need only a settled robot: one stack for them all."""

    def test_the_first_screen_holds_speak_the_current_order_and_stop(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """Item 3: with an order running, Listen, the order with its progress and STOP (or,
        latched, Release) are on the first screen without scrolling."""
        from playwright.sync_api import expect

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
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
                    assert (
                        page.evaluate("document.documentElement.scrollWidth") <= SCREENS[screen][0]
                    )

    def test_a_suggestion_repairs_the_sentence_and_keeps_the_rest(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """Item 4: a sentence with a suggested repair stays in the input, nothing of it staged;
        a suggestion puts its words in place and keeps the other suggestions; what does not
        parse at all stays in the input, to fix rather than retype."""
        from playwright.sync_api import expect

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
                    staged = page.locator("#staged li .what")
                    errors = page.locator("#errors li")
                    type_command(page, "turn lift then reach kitchin")
                    expect(errors).to_have_count(2)
                    expect(page.locator("#text")).to_have_value("turn lift then reach kitchin")
                    expect(staged).to_have_count(0)
                    shot(page, "4-two-suggestions", screen)
                    page.click("#errors button.suggestion:has-text('turn left')")
                    expect(page.locator("#text")).to_have_value("turn left then reach kitchin")
                    expect(errors).to_have_count(1)  # the other suggestion is still offered
                    expect(errors.locator("button.suggestion")).to_have_text(["reach kitchen"])
                    expect(staged).to_have_count(0)
                    page.click("#errors button.suggestion:has-text('reach kitchen')")
                    expect(staged).to_have_text(["turn left", "reach kitchen"])
                    expect(page.locator("#text")).to_have_value("")
                    expect(errors).to_have_count(0)
                    # the sentence once, not on every row
                    expect(page.locator("#staged li .said")).to_have_text(
                        ["turn left then reach kitchen"]
                    )

                    page.click("#clear")
                    type_command(page, "turn lift then reach kitchen then dance")
                    page.click("#errors button.suggestion:has-text('turn left')")
                    expect(staged).to_have_text(["turn left", "reach kitchen"])
                    expect(page.locator("#text")).to_have_value("dance")  # what did not parse
                    expect(errors).to_have_text(["dance no order matches"])
                    shot(page, "4-repaired", screen)

    def test_a_doubt_with_one_choice_is_a_yes_or_no(
        self, stack: Stack, tmp_path: Path, subtests: pytest.Subtests
    ) -> None:
        """Item 4: "Did you say … one? [yes, add it] [say again]", not a list of one."""
        from playwright.sync_api import expect

        silence = silent_wav(tmp_path / "silence.wav", 20.0)
        with chromium(microphone=silence) as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
                    page.click("#mic")
                    expect(page.locator("#mic")).to_have_attribute("aria-pressed", "true")
                    publish_proposal(
                        stack,
                        "go forward one meter",
                        Doubt(position=2, words="one", alternatives=[], confidence=0.0),
                    )
                    box_ = page.locator("#doubt")
                    expect(box_).to_be_visible()
                    expect(box_.locator("mark")).to_have_text("one")
                    expect(box_.locator("button")).to_have_text(["yes, add it", "say again"])
                    shot(page, "4-doubt-one-choice", screen)
                    box_.locator("button", has_text="yes").click()
                    expect(box_).to_be_hidden()
                    expect(page.locator("#staged li .what")).to_have_text(["move forward 1 m"])

    def test_every_doubt_of_a_proposal_is_asked(self, stack: Stack, tmp_path: Path) -> None:
        """Two values doubted in one sentence: both are marked, each is asked in turn, and
        only the answered words are staged (the panel once asked the first and staged the
        second as heard)."""
        from playwright.sync_api import expect

        silence = silent_wav(tmp_path / "silence.wav", 20.0)
        said = "turn left fifty degrees then turn right fifty degrees"
        with chromium(microphone=silence) as browser, screen_page(browser, "desktop") as page:
            login(page, stack)
            page.click("#mic")
            expect(page.locator("#mic")).to_have_attribute("aria-pressed", "true")
            publish_proposal(
                stack,
                said,
                Doubt(position=2, words="fifty", alternatives=["fifteen"], confidence=0.5),
                Doubt(position=7, words="fifty", alternatives=["fifteen"], confidence=0.5),
            )
            box_ = page.locator("#doubt")
            expect(box_.locator("mark")).to_have_text(["fifty", "fifty"])
            expect(box_.locator("button")).to_have_text(["fifty", "fifteen", "say again"])
            box_.locator("button", has_text="fifteen").click()
            expect(box_.locator("mark")).to_have_text(["fifty"])
            expect(page.locator("#staged li")).to_have_count(0)
            box_.locator("button", has_text="fifty").first.click()
            expect(box_).to_be_hidden()
            staged = page.locator("#staged li .what")
            expect(staged).to_have_text(["turn left 15 degrees", "turn right 50 degrees"])

    def test_stop_listening_mid_sentence_finishes_it_or_drops_it(
        self, stack: Stack, speech: Speak, subtests: pytest.Subtests
    ) -> None:
        """Item 5: Stop listening mid-sentence says it is finishing the sentence; the finished
        sentence (what was said before the stop) is decided on and shown, unless Send (or
        discard) came first: then it is dropped, said so, and never fills "To send" behind the
        person's back."""
        from playwright.sync_api import expect

        command = speech(SENTENCE, voice="flite:slt")
        heard = "#heard"
        # Every page's microphone plays the sentence from its start.
        with chromium(microphone=command) as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen):
                    with screen_page(browser, screen) as page:
                        login(page, stack)
                        type_command(page, "wait two seconds")
                        expect(page.locator("#staged li")).to_have_count(1)
                        # stopped once the part said is a command of its own: its late answer
                        # would stage
                        stop_mid_sentence(page, then="#send", after="kitchen")
                        expect(page.locator(heard)).to_contain_text("dropped: “")
                        expect(page.locator("#discard")).to_be_hidden()
                        # the recogniser's answer comes, and is shown for what it was, not staged
                        expect(page.locator(heard)).to_contain_text("not added", timeout=60_000)
                        expect(page.locator("#staged li")).to_have_count(0)
                        shot(page, "5-dropped", screen)

                    with screen_page(browser, screen) as page:
                        login(page, stack)
                        stop_mid_sentence(page)
                        shot(page, "5-finishing", screen)
                        # The recogniser decides on what it got before the stop: the part said
                        # is too short to be a command, and the page says so in place of
                        # "finishing".
                        expect(page.locator("#heard")).to_have_class(
                            re.compile(r"heard (final|rejected)"), timeout=60_000
                        )
                        expect(page.locator("#heard")).not_to_contain_text("finishing")
                        expect(page.locator("#discard")).to_be_hidden()
                        expect(page.locator("#speak")).not_to_contain_text("microphone(s) open")
                        shot(page, "5-finished", screen)

    def test_words_for_people_with_the_detail_one_click_away(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """Item 7: the recogniser's line is a calm "Ready to listen", its engine one click
        away; the stop's box says what happened in one sentence, each part's report one click
        away; a staged sentence is shown once, each order on a line of its own."""
        from playwright.sync_api import expect

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
                    expect(page.locator("#stt-summary")).to_have_text("Ready to listen")
                    engine = page.locator("#stt-status")
                    expect(engine).to_be_hidden()
                    page.click("#stt-summary")
                    expect(engine).to_be_visible()
                    expect(engine).to_contain_text("grammar")
                    expect(engine).to_contain_text("listening for")

                    type_command(page, "turn left then reach kitchen then wait two seconds")
                    rows = page.locator("#staged li")
                    expect(rows).to_have_count(3)
                    expect(page.locator("#staged .said")).to_have_count(1)
                    heights = [rows.nth(i).bounding_box() for i in (1, 2)]
                    assert all(h and h["height"] < 45 for h in heights), heights  # one line each
                    shot(page, "7-staged", screen)

                    page.click("#stop")
                    expect(page.locator("#held-why")).to_have_text(HELD_WHY)
                    detail = page.locator("#held-detail")
                    expect(detail).to_be_hidden()
                    page.click("#held-more summary")
                    expect(detail).to_be_visible()
                    expect(detail).to_contain_text("zero velocity")
                    shot(page, "7-stopped", screen)

    def test_a_stop_not_confirmed_says_so_and_keeps_stop_at_hand(
        self, stack: Stack, subtests: pytest.Subtests
    ) -> None:
        """Item 2's exception: when a part did not confirm the stop, the header keeps STOP
        beside "Stopped — Release" and the banner says what did not confirm. The stop is the
        real one; only its answer is rewritten on the way back (as a part that missed it
        would make it)."""
        from playwright.sync_api import Route, expect

        def unconfirmed(route: Route) -> None:
            answer = route.fetch()
            body = {**answer.json(), "confirmed": False, "detail": "executor: no answer"}
            route.fulfill(response=answer, json=body)

        with chromium() as browser:
            for screen in screens(stack):
                with subtests.test(screen=screen), screen_page(browser, screen) as page:
                    login(page, stack)
                    page.route("**/api/stop*", unconfirmed)
                    page.click("#stop")
                    expect(page.locator("#latched")).to_be_visible()
                    expect(page.locator("#stop")).to_be_visible()
                    banner = page.locator("#banner")
                    expect(banner).to_contain_text("not confirmed: executor: no answer")
                    shot(page, "2-stop-not-confirmed", screen)
                    page.unroute("**/api/stop*")
                    page.click("#stop")
                    expect(page.locator("#stop")).to_be_hidden()
                    expect(
                        banner
                    ).to_be_hidden()  # the stop that worked is news the banner had wrong


def test_messages_stand_by_their_control_and_go_when_stale(
    stack: Stack, subtests: pytest.Subtests
) -> None:
    """Items 1, 2 and 8: Send refused under a latched stop says so under Send, in the
    panel's words, and the note goes when the stop is released; the latched header reads
    "Stopped — Release"; a lost connection is a banner that goes once it is back, with
    the stale queue, map and recogniser marked so; no request of the page fails (the
    icon)."""
    from playwright.sync_api import expect

    with chromium() as browser:
        for screen in screens(stack):
            with subtests.test(screen=screen):
                with screen_page(browser, screen) as page:
                    missing = failed_requests(page)
                    login(page, stack)
                    type_command(page, "wait two seconds")
                    expect(page.locator("#staged li")).to_have_count(1)

                    page.click("#stop")
                    latched = page.locator("#latched")
                    expect(latched).to_be_visible()
                    expect(latched).to_contain_text("Stopped")
                    expect(page.locator("#stop")).to_be_hidden()
                    expect(page.locator("header #head-release")).to_have_text("Release")
                    expect(page.locator("#held-why")).to_have_text(HELD_WHY)
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
                    # The supervisor's own refusal names the command that releases (as it
                    # runs where the stack runs: `.venv/bin/voicectl release` from a clone);
                    # in the panel's words it is left out.
                    refusal = page.evaluate(SUBMIT_REFUSED)
                    assert "(" in refusal["said"], refusal  # the hint was there
                    assert "emergency stop is on" in refusal["shown"], refusal
                    assert "voicectl" not in refusal["shown"], refusal

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
                    type_command(page, "reach kitchen")  # a dashed route on the map
                    route = page.locator("#map .step.staged line")
                    expect(route).to_have_count(1)
                    live = route.evaluate("e => getComputedStyle(e).stroke")
                    kill_the_web_service(stack)  # `voicectl up` starts it again
                    banner = page.locator("#banner")
                    expect(banner).to_contain_text("Connection to the robot lost")
                    expect(banner).to_be_in_viewport()
                    expect(page.locator("#stt-summary")).to_contain_text("Not connected")
                    expect(page.locator("#stt-status")).to_contain_text("last known, not live")
                    expect(page.locator("#queue button").first).to_be_disabled()
                    expect(page.locator("#map-stale")).to_be_visible()
                    stale = route.evaluate("e => getComputedStyle(e).stroke")
                    assert stale != live, (stale, live)  # greyed, not drawn as if live
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


SUBMIT_REFUSED = """async () => {
  // The staged order submitted through the panel's own api(): what the refusal said,
  // and what the panel shows of it.
  try {
    await api("/api/submit", { orders: [view.staged[0].order], request_id: newRequestId() });
  } catch (error) {
    return { said: error.message, shown: forPerson(error.message) };
  }
  return null;
}"""


def failed_requests(page: Page) -> list[str]:
    """What `page` asks for from now on and does not get (but for the API's refusals)."""
    from playwright.sync_api import Response

    failed: list[str] = []

    def note(response: Response) -> None:
        if response.status >= 400 and "/api/" not in response.url:
            failed.append(f"{response.status} {response.url}")

    page.on("response", note)
    return failed


def kill_the_web_service(stack: Stack) -> None:
    """SIGKILL the stack's web service (its panel's server), as a crash would."""
    kill_service(stack, "web")


def kill_service(stack: Stack, name: str) -> None:
    """SIGKILL one service of the stack, as a crash would; `voicectl up` starts it again."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
            parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if parent == stack.process.pid and f"voicectl.services.{name}".encode() in argv:
            os.kill(int(entry.name), signal.SIGKILL)
            return
    raise AssertionError(f"no {name} service under the stack")


def stack_get(stack: Stack, path: str) -> tuple[int, str]:
    import urllib.request

    with urllib.request.urlopen(f"http://127.0.0.1:{stack.port}{path}", timeout=10) as reply:
        return reply.status, reply.headers.get("content-type", "")


OVERLAPS = """() => {
  // Every pair of the map's labels, and each label with the robot, that overlap on screen
  // by more than a pixel each way.
  const rect = (node) => node.getBoundingClientRect();
  const labels = [...document.querySelectorAll("#map .place text, #map .step text")];
  const robot = document.querySelector("#map .robot");
  const hit = (a, b) => Math.min(a.right, b.right) - Math.max(a.left, b.left) > 1
    && Math.min(a.bottom, b.bottom) - Math.max(a.top, b.top) > 1;
  const found = [];
  labels.forEach((label, index) => {
    for (const other of labels.slice(index + 1)) {
      if (hit(rect(label), rect(other))) found.push([label.textContent, other.textContent]);
    }
    if (robot && hit(rect(label), rect(robot))) found.push([label.textContent, "robot"]);
  });
  return found;
}"""


def test_the_map_warns_of_goals_off_the_map_places_labels_apart_and_breaks_the_trail(
    stack: Stack, subtests: pytest.Subtests
) -> None:
    """Item 6: a goal outside the robot's map (or on an obstacle, or unseen) is warned of
    beside Send and on the map before it is sent; labels and step numbers do not cover
    each other or the robot; the legend's entries never wrap; after the panel's server
    restarts, the trail breaks instead of joining the old pose with a straight line."""
    from playwright.sync_api import expect

    with chromium() as browser:
        for screen in screens(stack):
            with subtests.test(screen=screen), screen_page(browser, screen) as page:
                login(page, stack)
                expect(page.locator("#map image.grid")).to_have_count(1)
                warning = page.locator("#goal-warning")
                type_command(page, "go forward ten meters then go forward ten meters")
                expect(warning).to_be_visible()
                expect(warning).to_contain_text("move forward 10 m")
                expect(warning).to_contain_text("the robot's map")
                below = box(page, "#goal-warning")["y"] - box(page, "#send")["y"]
                assert 0 < below < 200, below
                expect(page.locator("#map .step.warn .goal-warn").first).to_be_attached()
                page.locator("#map").scroll_into_view_if_needed()
                shot(page, "6-goal-off-the-map", screen)
                page.click("#clear")
                expect(warning).to_be_hidden()
                type_command(
                    page, "turn left then reach kitchen then reach dumpster then reach bathroom"
                )
                expect(page.locator("#map .step.staged")).to_have_count(4)
                expect(warning).to_be_hidden()  # every goal lies on free, known cells
                assert page.evaluate(OVERLAPS) == []
                legend = page.locator("#where .legend li")
                expect(legend).to_have_count(5)
                heights = [legend.nth(i).bounding_box() for i in range(5)]
                line = max(h["height"] for h in heights if h)
                assert all(h and h["height"] == line for h in heights), heights
                assert line < 30, line  # one line each
                if screen == "desktop":  # and the whole legend on one line where there is room
                    whole = box(page, "#where .legend")
                    assert whole["height"] < 1.5 * line, (whole, line)
                page.locator("#map").scroll_into_view_if_needed()
                shot(page, "6-labels", screen)

    # Moving the robot last, on both screens, so that it stands where a new stack has it
    # while the labels are looked at; each screen's trail from where the robot stands.
    with chromium() as browser:
        for screen in screens(stack, fresh=False):
            with subtests.test(screen=screen), screen_page(browser, screen) as page:
                login(page, stack)
                start = shown_x(page)
                pose = page.locator("#pose")
                type_command(page, "go forward one meter")
                page.click("#send")
                expect(pose).to_contain_text(f"x {start + 1:.1f} m", timeout=60_000)
                trail = page.locator("#map polyline.trail")
                expect(trail).to_have_count(1)
                kill_the_web_service(stack)
                expect(page.locator("#connection")).to_have_text("reconnecting")
                expect(page.locator("#connection")).to_have_text("connected", timeout=60_000)
                type_command(page, "go forward one meter")
                page.click("#send")
                expect(pose).to_contain_text(f"x {start + 2:.1f} m", timeout=60_000)
                expect(trail).to_have_count(2)  # two pieces, not one line across the restart
                # The executor restarts (the robot's odometry may start anywhere then): the
                # trail breaks again, though the panel's connection stayed up and the pose did
                # not jump.
                kill_service(stack, "executor")
                executor = page.locator('#parts li[data-part="executor"]')
                expect(executor).to_have_class(re.compile(r"\boffline\b"), timeout=30_000)
                expect(executor).to_have_class(re.compile(r"\bonline\b"), timeout=60_000)
                type_command(page, "go forward one meter")
                page.click("#send")
                expect(pose).to_contain_text(f"x {start + 3:.1f} m", timeout=60_000)
                expect(trail).to_have_count(3)
                page.locator("#map").scroll_into_view_if_needed()
                shot(page, "6-trail-after-restart", screen)


def shown_x(page: Page) -> float:
    """The robot's x in metres as the page shows it, once it shows a pose."""
    from playwright.sync_api import expect

    shown = re.compile(r"x (-?\d+\.\d) m")
    expect(page.locator("#pose")).to_contain_text(shown)
    found = shown.search(page.locator("#pose").inner_text())
    assert found is not None
    return float(found.group(1))


def test_a_photo_an_order_took_is_shown_in_its_history_row(
    photo_at_once_stack: Stack, subtests: pytest.Subtests
) -> None:
    """A photo is a file on the robot: its history row shows it, fetched with the token,
    and keeps it when the history is drawn again."""
    from playwright.sync_api import expect

    stack = photo_at_once_stack

    with chromium() as browser:
        # The history keeps what the passes before took: each pass's rows are the newest.
        for taken, screen in enumerate(screens(stack)):
            with subtests.test(screen=screen), screen_page(browser, screen) as page:
                login(page, stack)
                photos = page.locator("#history tr", has_text="photo")
                waits = page.locator("#history tr", has_text="wait")
                expect(photos).to_have_count(taken)
                expect(waits).to_have_count(taken)
                type_command(page, "take a picture")
                expect(page.locator("#staged li")).to_have_count(1)
                page.click("#send")
                expect(photos).to_have_count(taken + 1, timeout=60_000)
                row = photos.first
                expect(row.locator("td.succeeded")).to_be_visible()
                # Where the file is kept on the robot is one click away, not on the row.
                message = row.locator("td.message")
                expect(message).to_contain_text("took a 64x48 photo")
                assert "kept on the robot" not in message.inner_text()
                message.locator("details.more summary").click()
                expect(message).to_contain_text("kept on the robot as ")
                row.locator("button.show-photo").click()
                image = row.locator("img.photo")
                expect(image).to_be_visible()
                page.wait_for_function(
                    "() => document.querySelector('#history img.photo')?.naturalWidth === 64"
                )
                type_command(page, "wait one second")  # the history is drawn again as it runs
                page.click("#send")
                expect(waits).to_have_count(taken + 1, timeout=60_000)
                expect(waits.first.locator("td.succeeded")).to_be_visible()
                expect(page.locator("#history img.photo")).to_have_count(1)
                image.scroll_into_view_if_needed()
                shot(page, "9-photo-in-history", screen)
