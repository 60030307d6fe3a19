"""The panel in a real headless Chromium against the real stack: log in with the token,
type a command, see the orders, send them, watch the history fill in."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from .conftest import Stack

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

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(
        not Path(CHROMIUM).exists() and not os.environ.get("CI"),
        reason="Debian's chromium is not installed (scripts/test installs it)",
    ),
]


def test_type_parse_send_and_watch(stack: Stack, tmp_path: Path) -> None:
    from playwright.sync_api import expect, sync_playwright

    token = Path(stack.env["VOICECTL_DATA"], "token").read_text().strip()
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(
            str(tmp_path / "profile"),
            executable_path=CHROMIUM,
            headless=True,
            args=CHROMIUM_FLAGS,
        )
        try:
            page = browser.new_page()
            page.goto(f"http://127.0.0.1:{stack.port}/")

            expect(page.locator("#login")).to_be_visible()
            page.fill("#token", "wrong")
            page.click("#save-token")
            expect(page.locator("#status")).to_contain_text("token", timeout=10_000)

            page.fill("#token", token)
            page.click("#save-token")
            expect(page.locator("#executor")).to_have_text("executor online", timeout=20_000)

            page.fill("#text", "turn left then reach kitchen then dance")
            page.click("#command button[type=submit]")
            expect(page.locator("#orders li")).to_have_text(["turn left", "reach kitchen"])
            expect(page.locator("#errors li")).to_have_text(["dance: no order matches"])

            page.click("#send")
            history = page.locator("#history tr")
            expect(history).to_have_count(2, timeout=60_000)
            expect(history.nth(0)).to_contain_text("reach kitchen")
            expect(history.nth(0)).to_contain_text("succeeded")
            expect(history.nth(1)).to_contain_text("turn left")
            expect(history.nth(1)).to_contain_text("succeeded")
            page.screenshot(path=str(tmp_path / "panel.png"), full_page=True)

            # the token survives a reload; the state is there at once
            page.reload()
            expect(page.locator("#history tr")).to_have_count(2, timeout=20_000)
        finally:
            browser.close()
