"""A participant's link in a real browser (Debian's Chromium, a profile on disk): the token that
opens the session is in no URL the browser keeps (its history database holds the link's spent
token only, which no longer opens anything), a second tab takes the session over, the first
saying so, and a window closed mid-drive and opened again finds the car where it stopped."""

from __future__ import annotations

import math
import sqlite3
import time

import httpx
import pytest

from tests.browser import chromium_executable

from .test_browser import CHROMIUM_ARGS, TIMEOUT_MS, VIEWPORT, create_participant
from .test_browser_station import ego_pixels
from .test_driver_view import wait_until
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


def test_a_station_closed_mid_drive_and_opened_again_shows_the_car_where_sumo_holds_it(tmp_path):
    """A real drive (SUMO in the episode's process): the participant's window closes mid-drive,
    which pauses the episode; the station opened again in the same browser shows the car where the
    server's newest frame has it (its road is the one the console reports), in the view and on the
    mini-map, before any resume; the resume goes on from there, not from the start."""
    from playwright.sync_api import expect, sync_playwright

    config = tmp_path / "session.toml"
    config.write_text(CONFIG)
    # a slow pace: the warm-up's seven roads must still be ahead when the window closes
    process, address, token = start_server(str(config), tmp_path / "study", 4.0)
    console = {"Authorization": f"Bearer {token}"}
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            link = create_participant(browser, address, token)
            context = browser.new_context(viewport=VIEWPORT)
            first = context.new_page()
            first.goto(link)
            first.wait_for_url("**/station")
            first.locator("#agree").click()
            first.locator("#start-trust button", has_text="5").click()
            expect(first.locator("#speed")).to_contain_text("km/h", timeout=TIMEOUT_MS)
            wait_until(first, "window.driverView.stats.frames > 20", seconds=30)   # under way
            before = first.evaluate("window.driverView.stats.pose")
            first.close()
            shown = wait_for_phase(address, console, "paused")
            assert shown["paused_by"] == "disconnect" and shown["road"]

            again = context.new_page()   # the session's cookie is the browser's: no new link
            again.goto(f"http://{address}/station")
            expect(again.locator("#overlay-text")).to_contain_text("connection was lost")
            wait_until(again, "Boolean(window.driverView && window.driverView.stats.pose)", seconds=30)
            still = again.evaluate("window.driverView.stats.pose")
            assert again.evaluate("window.driverView.stats.frames") == 1   # the server's last frame only
            assert again.locator("#road").get_attribute("data-road") == shown["road"]
            # where the closed window left it, give or take the pause's latency
            assert math.dist(still[:2], before[:2]) < 60.0
            assert ego_pixels(again) > 0
            again.screenshot(path=str(tmp_path / "reopened.png"))

            again.locator("#resume").click()
            wait_until(again, "window.driverView.stats.frames >= 2", seconds=30)
            onward = again.evaluate("window.driverView.frames[1].frame")   # the first after the resume
            assert math.dist((onward["x"], onward["y"]), still[:2]) < 30.0   # on from there, not anew
            assert wait_for_phase(address, console, "driving")["trial_status"] == "driving the warm-up"
            browser.close()
    finally:
        process.terminate()
        process.wait(30)


def wait_for_phase(address: str, headers: dict, phase: str) -> dict:
    """The only participant's state, once it is in `phase`."""
    deadline = time.monotonic() + 30
    while True:
        state = httpx.get(f"http://{address}/api/participants/0", headers=headers).json()
        if state["phase"] == phase:
            return state
        assert time.monotonic() < deadline, state
        time.sleep(0.05)
