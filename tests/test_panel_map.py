"""The panel's map in a real headless Chromium against the real stack: the places of the
orders, the robot and its trail, where staged and queued orders will take it, the
simulator's own map, a click on a place; a phone-sized screen; a panel with no token.
Screenshots go to test-artifacts/."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from playwright.sync_api import Page

from harness.wait import wait_until

from .conftest import REPO, Stack
from .test_panel_browser import ARTIFACTS, CHROMIUM, CHROMIUM_FLAGS, login, panel, pytestmark

__all__ = ["pytestmark"]  # the browser's marks and skip, as in test_panel_browser

MAP_JS = REPO / "services" / "web" / "static" / "map.js"


def in_page(page: Page, expression: str, timeout: float = 30.0) -> Any:
    """What `expression` gives in the page once it is truthy, asked from here until then.
    Not Playwright's wait_for_function: it polls with eval inside the page, which the
    panel's Content-Security-Policy forbids, as it should."""
    found: list[Any] = []

    def holds() -> bool:
        found[:] = [page.evaluate(expression)]
        return bool(found[0])

    wait_until(holds, timeout, expression)
    return found[0]


def test_the_map_shows_places_robot_and_where_orders_go_before_and_after_send(
    stack: Stack, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        page.set_viewport_size({"width": 1280, "height": 900})
        login(page, stack)
        places = page.locator("#map .place")
        expect(places).to_have_count(4)  # base, bathroom, kitchen, dumpster (orders/demo.yaml)
        expect(places.filter(has_text="kitchen")).to_have_count(1)
        expect(page.locator("#map .robot")).to_have_count(1)
        # The simulator's occupancy grid, relayed by the executor while the panel shows it.
        grid = page.locator("#map image.grid")
        expect(grid).to_have_count(1, timeout=15_000)
        assert grid.get_attribute("href").startswith("data:image/png;base64,")
        # The view takes in the robot's map (walls from -10 to 10 m), not only the places.
        in_page(page, "document.querySelector('#map').viewBox.baseVal.width >= 20")
        box = page.eval_on_selector(
            "#map", "m => { const b = m.viewBox.baseVal; return [b.x, b.y, b.width, b.height]; }"
        )
        assert box[0] <= -10, box
        assert box[0] + box[2] >= 10, box
        assert box[1] <= -10, box
        assert box[1] + box[3] >= 10, box
        assert box[2] <= 26, box  # and little else: the walls fill the view

        # Before Send: the turn is drawn where the robot stands, the path to the kitchen
        # from where the turn ends.
        page.fill("#text", "turn left then reach the kitchen")
        page.press("#text", "Enter")
        staged = page.locator("#map .step.staged")
        expect(staged).to_have_count(2)
        assert [staged.nth(i).get_attribute("data-order") for i in range(2)] == [
            "turn left",
            "reach kitchen",
        ]
        path = staged.nth(1).locator("line")
        assert float(path.get_attribute("x2")) == 3.0
        assert float(path.get_attribute("y2")) == -5.0  # SVG's y points down
        assert abs(float(path.get_attribute("x1"))) < 0.2  # from the turn's end, at base
        # The turn on the spot is drawn around the robot, not hidden under its arrow.
        expect(staged.nth(0).locator("path.turn")).to_be_visible()
        # Both boxes in one look: the map is drawn again at every pose, and an element
        # measured between two drawings is gone.
        arc, robot = in_page(
            page,
            """() => {
                const boxes = ["#map .step.staged path.turn", "#map .robot"].map((s) => {
                    const found = document.querySelector(s);
                    return found && found.getBoundingClientRect();
                });
                return boxes.every((b) => b && b.width) &&
                    boxes.map((b) => ({x: b.x, y: b.y, width: b.width, height: b.height}));
            }""",
        )
        outside = (
            arc["x"] + arc["width"] > robot["x"] + robot["width"] + 5 or arc["y"] < robot["y"] - 5
        )
        assert outside, (arc, robot)
        assert (
            page.eval_on_selector("#map", "m => m.lastElementChild.dataset.order")
            == "reach kitchen"
        )  # the orders are drawn over the robot
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "map-staged.png"), full_page=True)

        # A click on a place stages what saying it would.
        places.filter(has_text="bathroom").click()
        expect(page.locator("#staged li .what")).to_have_text(
            ["turn left", "reach kitchen", "reach bathroom"]
        )
        expect(staged).to_have_count(3)

        # After Send: the queue, the running order highlighted, the trail growing.
        page.evaluate(
            """() => {
                window.runningSeen = [];
                setInterval(() => {
                    const step = document.querySelector('#map .step.running');
                    const seen = window.runningSeen;
                    if (step && seen[seen.length - 1] !== step.dataset.order) {
                        seen.push(step.dataset.order);
                    }
                }, 20);
            }"""
        )
        page.click("#send")
        expect(page.locator("#map .step.running")).to_have_count(1)
        trail = page.locator("#map .trail")
        expect(trail).to_have_count(1)
        before = len(trail.get_attribute("points").split())
        in_page(
            page,
            f"document.querySelector('#map .trail').getAttribute('points').split(' ').length"
            f" > {before + 1}",  # poses come twice a second; the robot drives 10x life
        )
        expect(page.locator("#current .progress-text")).to_contain_text(" to ")
        page.screenshot(path=str(ARTIFACTS / "map-running.png"), full_page=True)
        history = page.locator("#history tr")
        expect(history.nth(0)).to_contain_text("reached bathroom", timeout=60_000)
        expect(history.nth(2)).to_contain_text("turned left 90°")
        # The highlight went from one order to the next as the robot drove.
        seen = page.evaluate("window.runningSeen")
        orders = ["turn left", "reach kitchen", "reach bathroom"]
        assert len(seen) >= 2, seen
        assert [orders.index(name) for name in seen] == sorted(
            {orders.index(name) for name in seen}
        ), seen
        expect(page.locator("#map .step.running")).to_have_count(0)

        # Another robot: nothing of this one stays on the map or in the header.
        page.eval_on_selector(
            "#robot",
            "s => { s.append(new Option('other', 'other')); s.value = 'other'; "
            "s.dispatchEvent(new Event('change')); }",
        )
        expect(page.locator("#pose")).to_have_text("no position yet")
        expect(page.locator("#map .robot")).to_have_count(0)
        expect(page.locator("#map .trail")).to_have_count(0)
        expect(page.locator("#map image.grid")).to_have_count(0)
        page.select_option("#robot", "robot")
        expect(page.locator("#map .robot")).to_have_count(1)


LABELS = """() => [...document.querySelectorAll("#map .place")].map((group) => {
  // Each place's label: where it is drawn from its circle's centre, and its box, in the
  // map's own units.
  const circle = group.querySelector("circle");
  const text = group.querySelector("text");
  const box = text.getBBox();
  const [cx, cy] = [Number(circle.getAttribute("cx")), Number(circle.getAttribute("cy"))];
  return {name: text.textContent, cx, cy,
          dx: Number(text.getAttribute("x")) - cx, dy: Number(text.getAttribute("y")) - cy,
          box: {x: box.x, y: box.y, w: box.width, h: box.height}};
})"""


def labels_of(page: Page) -> dict[str, tuple[float, float]]:
    """Where each place's label is drawn from its own place, once two looks agree (the
    map is framed anew when the robot's map is read), after checking that each is nearer
    its own place than any other."""
    seen: list[list[dict[str, Any]]] = []

    def settled() -> bool:
        seen.append(page.evaluate(LABELS))
        return len(seen) > 1 and bool(seen[-1]) and seen[-1] == seen[-2]

    wait_until(settled, 30.0, "the places' labels to be drawn")
    labels = seen[-1]
    for label in labels:
        box = label["box"]

        def away(x: float, y: float, box: dict[str, float] = box) -> float:
            dx = max(box["x"] - x, 0.0, x - box["x"] - box["w"])
            dy = max(box["y"] - y, 0.0, y - box["y"] - box["h"])
            return math.hypot(dx, dy)

        own = away(label["cx"], label["cy"])
        for other in labels:
            if other is not label:
                assert own < away(other["cx"], other["cy"]), (label["name"], other["name"])
    return {label["name"]: (round(label["dx"], 6), round(label["dy"], 6)) for label in labels}


def test_each_place_keeps_its_label_beside_it_at_every_redraw(stack: Stack, tmp_path: Path) -> None:
    """A label is nearer its own place than any other, and at the same spot by it whatever
    else the map shows: orders staged far away (the view widens), the robot driven to
    another place."""
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        page.set_viewport_size({"width": 1280, "height": 900})
        login(page, stack)
        expect(page.locator("#map image.grid")).to_have_count(1, timeout=15_000)
        expect(page.locator("#map .place")).to_have_count(4)
        first = labels_of(page)
        page.fill("#text", "go forward ten meters then go forward ten meters")
        page.press("#text", "Enter")
        expect(page.locator("#map .step.staged")).to_have_count(2)
        assert labels_of(page) == first
        page.click("#clear")
        page.fill("#text", "reach bathroom")
        page.press("#text", "Enter")
        page.click("#send")
        expect(page.locator("#pose")).to_contain_text("x 5.0 m, y 2.0 m", timeout=60_000)
        assert labels_of(page) == first
        page.screenshot(path=str(ARTIFACTS / "map-labels.png"))


def test_on_a_phone_nothing_scrolls_sideways_and_stop_stays_in_reach(
    stack: Stack, tmp_path: Path
) -> None:
    from playwright.sync_api import expect

    with panel(stack, tmp_path / "profile") as page:
        # Without a token the panel says it is not connected, and STOP says why it is off.
        page.set_viewport_size({"width": 390, "height": 844})
        page.goto(f"http://127.0.0.1:{stack.port}/")
        expect(page.locator("#connection")).to_have_text("not connected")
        expect(page.locator("#stop")).to_be_disabled()
        expect(page.locator("#panel")).to_be_hidden()  # no idle queue, no live-looking map
        looks = "e => { const s = getComputedStyle(e); return [s.opacity, s.backgroundColor]; }"
        off = page.eval_on_selector("#stop", looks)
        header_off = page.eval_on_selector("header", "e => getComputedStyle(e).backgroundColor")
        ARTIFACTS.mkdir(exist_ok=True)
        page.screenshot(path=str(ARTIFACTS / "phone-not-connected.png"))

        login(page, stack)
        expect(page.locator("#connection")).to_have_text("connected")
        expect(page.locator("#stop")).to_be_enabled()
        # A STOP that cannot stop does not look like one that can, nor the panel live.
        on = page.eval_on_selector("#stop", looks)
        assert off[0] != on[0], (off, on)
        assert off[1] != on[1], (off, on)
        assert header_off != page.eval_on_selector(
            "header", "e => getComputedStyle(e).backgroundColor"
        )
        # Nothing overlaps: the header's parts, and the panel's blocks below it.
        boxes = page.evaluate(
            """() => {
                const box = (e) => {
                    const r = e.getBoundingClientRect();
                    return {name: e.id || e.className || e.tagName, x: r.x, y: r.y + scrollY,
                            right: r.right, bottom: r.bottom + scrollY};
                };
                const shown = (e) => e.getClientRects().length > 0 && !e.hidden;
                return {
                    header: [...document.querySelectorAll('header > *')].filter(shown).map(box),
                    main: [document.querySelector('header'),
                           ...document.querySelectorAll('main > section')].filter(shown).map(box),
                    map: [...document.querySelectorAll('#where > *')].filter(shown).map(box),
                };
            }"""
        )
        for group, found in boxes.items():
            assert len(found) >= 3, (group, found)
            for box in found:
                assert box["x"] >= 0, (group, box)
                assert box["right"] <= 390, (group, box)
            for i, one in enumerate(found):
                for other in found[i + 1 :]:
                    apart = (
                        one["right"] <= other["x"] + 0.5
                        or other["right"] <= one["x"] + 0.5
                        or one["bottom"] <= other["y"] + 0.5
                        or other["bottom"] <= one["y"] + 0.5
                    )
                    assert apart, (group, one, other)
        page.fill("#text", "turn left then turn right then wait two seconds")
        page.press("#text", "Enter")
        page.click("#send")
        expect(page.locator("#history tr")).to_have_count(3, timeout=60_000)
        assert page.evaluate("document.documentElement.scrollWidth") <= 390
        page.evaluate("window.scrollTo(0, document.body.scrollHeight)")
        stop = page.locator("#stop").bounding_box()
        assert stop is not None
        assert stop["y"] >= 0, stop
        assert stop["y"] + stop["height"] <= 844, stop
        page.screenshot(path=str(ARTIFACTS / "map-phone.png"), full_page=False)
        page.screenshot(path=str(ARTIFACTS / "map-phone-full.png"), full_page=True)


def test_where_chained_orders_take_the_robot(tmp_path: Path) -> None:
    """The map's own arithmetic (map.js), run in Chromium: a relative order goes from where
    the one before ends, an absolute one to its place, one without a pose nowhere."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(
            str(tmp_path / "profile"), executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS
        )
        try:
            page = browser.new_page()
            page.set_content("<svg id='map'></svg>")
            page.add_script_tag(path=str(MAP_JS))
            steps = page.evaluate(
                """() => {
                    const pose = (frame, x, y, yaw) => ({frame, x, y, yaw});
                    return voicectlPlan({x: 1, y: 2, yaw: 0}, [
                        {target_pose: pose("base_link", 0, 0, Math.PI / 2)},
                        {target_pose: pose("base_link", 2, 0, 0)},
                        {target_pose: pose("map", 3, 5, 1)},
                        {target_pose: null},
                        {target_pose: pose("base_link", -1, 0, 3.14)},
                    ]);
                }"""
            )
        finally:
            browser.close()
    ends = [step["to"] for step in steps]
    assert ends[0] == {"x": 1, "y": 2, "yaw": math.pi / 2}
    assert (round(ends[1]["x"], 9), round(ends[1]["y"], 9)) == (1.0, 4.0)
    assert ends[2] == {"x": 3, "y": 5, "yaw": 1}
    assert ends[3] is None
    assert steps[4]["from"] == {"x": 3, "y": 5, "yaw": 1}  # the photo left it where it was
    assert ends[4]["x"] == pytest.approx(3 - math.cos(1))
    assert ends[4]["y"] == pytest.approx(5 - math.sin(1))
    assert ends[4]["yaw"] == pytest.approx(1 + 3.14 - 2 * math.pi)  # kept in [-pi, pi)
