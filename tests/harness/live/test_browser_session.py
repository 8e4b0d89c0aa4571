"""A participant's link in a real browser (Debian's Chromium, a profile on disk): the token that
opens the session is in no URL the browser keeps (its history database holds the link's spent
token only, which no longer opens anything), and a second tab takes the session over, the first
saying so."""

from __future__ import annotations

import sqlite3

import httpx
import pytest

from tests.browser import chromium_executable

from .test_browser import CHROMIUM_ARGS, create_participant
from .test_live_restart import start_server

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

CONFIG = """[study]
name = "browser-session"
participants = 1
seed = 3
engine = "live"
specs = ["phi1"]
conditions = ["free"]
"""


def test_the_link_leaves_no_live_token_in_the_history_and_a_second_tab_takes_over(tmp_path):
    from playwright.sync_api import expect, sync_playwright

    config = tmp_path / "session.toml"
    config.write_text(CONFIG)
    profile = tmp_path / "profile"
    process, address, token = start_server(str(config), tmp_path / "study", 20.0)
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            link = create_participant(browser, address, token)
            browser.close()
            spent = link.rsplit("/", 1)[1]
            context = playwright.chromium.launch_persistent_context(
                str(profile), executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            first = context.new_page()
            first.goto(link)
            first.wait_for_url("**/station")
            expect(first.locator("#consent-step")).to_be_visible()
            assert spent not in first.url
            live = next(c["value"] for c in context.cookies() if c["name"] == "trustroute_participant")
            assert live != spent
            second = context.new_page()
            second.goto(f"http://{address}/station")
            expect(second.locator("#error")).to_contain_text("another window")
            expect(first.locator("#error")).to_contain_text("open in another window")
            first.screenshot(path=str(tmp_path / "replaced.png"))
            again = context.new_page()   # the link, opened again (from the history, say), is spent
            again.goto(link)
            expect(again.locator("#message")).to_contain_text("used already")
            context.close()
        history = sqlite3.connect(profile / "Default" / "History")
        urls = [row[0] for row in history.execute("SELECT url FROM urls")]
        assert urls and not any(live in url for url in urls)
        me = f"http://{address}/api/me"
        assert httpx.get(me, headers={"Authorization": f"Bearer {spent}"}).status_code == 403
        assert httpx.get(me, headers={"Authorization": f"Bearer {live}"}).status_code == 200
    finally:
        process.terminate()
        process.wait(30)
