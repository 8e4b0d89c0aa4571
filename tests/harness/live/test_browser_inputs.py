"""The inputs a study allows, in a real browser: `[live] inputs = ["wheel"]` on a continuous study.
Debian's Chromium (software WebGL) against `trustroute live`: once in control with no wheel
connected, the station asks for one and sends no control; a gamepad (the browser's standard
mapping) is not read either; a wheel (another mapping) is not read until it is calibrated, which
the station asks for in the drive and offers there; calibrated, it drives, and every control the
page sends names it as its input. A car that coasted to the hold before the junction meanwhile (a
slow machine) is handed back as the station asks, and taken over again on the next road."""

from __future__ import annotations

import json
import time

import pytest

from benchmarks.bench_live import start_live_server
from tests.browser import chromium_executable

from .test_browser import CHROMIUM_ARGS, create_participant
from .test_browser_station_controls import DEVICES, SET_DEVICES, calibrate_wheel, gamepad, wheel
from .test_driver_view import wait_until

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

CONFIG = """[study]
name = "wheel-only"
participants = 1
seed = 1
engine = "live"
specs = ["phi1"]
conditions = ["free"]

[live]
driving = "continuous"
inputs = ["wheel"]
"""


def take_over(page) -> None:
    """In control (space), unless already: the autopilot takes the car back at a junction."""
    from playwright.sync_api import expect

    if "MANUAL" not in page.locator("#mode").inner_text():
        page.keyboard.press("Space")
        expect(page.locator("#mode")).to_contain_text("MANUAL")


def manual_for(page, seconds: float) -> None:
    """`seconds` of wall time in control, taking over again whenever the autopilot has the car."""
    held_since = time.monotonic()
    while time.monotonic() - held_since < seconds:
        if "MANUAL" not in page.locator("#mode").inner_text():
            take_over(page)
            held_since = time.monotonic()
        time.sleep(0.05)


def told_to_hand_back(page) -> bool:
    """The station asks for the hand-back: the car is held for it before the junction (and, once
    it stands there, no control can be sent: station.js `allowed`)."""
    text = page.locator("#incident").inner_text().lower()
    return "hand back now" in text or "hand back before the junction" in text


# Metres to the junction on the dashboard ("Straight on in 490 m", next_turn.js), -1 when none said
# (in the junction).
METRES_TO_JUNCTION = """() => {
  const said = /in (\\d+) m$/.exec(document.getElementById("turn-text").textContent);
  return said === null ? -1 : Number(said[1]);
}"""


def hand_back_for_the_next_road(page) -> None:
    """What a person held before the junction does: hands back (space), as the station asks;
    then waits for the autopilot to bring the car onto the next road, to take over well before its
    end (the dashboard's distance to the junction far longer than where it was held)."""
    from playwright.sync_api import expect

    held_at = page.evaluate(METRES_TO_JUNCTION)
    page.keyboard.press("Space")
    expect(page.locator("#mode")).to_contain_text("AUTOPILOT")
    wait_until(page, f"({METRES_TO_JUNCTION})() > {held_at + 50}", seconds=120)


def test_a_wheel_only_study_reads_only_a_wheel(tmp_path):
    from playwright.sync_api import expect, sync_playwright

    executable = chromium_executable()
    config_path = tmp_path / "wheel.toml"
    config_path.write_text(CONFIG)
    process, address, token = start_live_server(config_path, tmp_path / "study", "--pace", "1",
                                                "--no-warm-up")
    sent: list[dict] = []
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
            try:
                link = create_participant(browser, address, token)
                page = browser.new_context(viewport={"width": 640, "height": 480}).new_page()
                page.set_default_timeout(60_000)
                page.add_init_script(DEVICES)   # none until the test connects one
                errors: list[str] = []
                page.on("pageerror", lambda error: errors.append(str(error)))
                page.on("websocket", lambda socket: socket.on(
                    "framesent", lambda payload: sent.append(json.loads(payload))))
                page.goto(link)
                page.wait_for_url("**/station")
                page.locator("#agree").click()
                page.locator("#start-trust button", has_text="5").click()
                expect(page.locator("#speed")).to_contain_text("km/h", timeout=120_000)
                take_over(page)
                asked = "Connect a steering wheel with pedals to drive"
                expect(page.locator("#incident")).to_contain_text(asked)
                page.screenshot(path=tmp_path / "no-wheel.png")
                page.evaluate(SET_DEVICES, [gamepad(throttle=1.0)])
                manual_for(page, 1.0)
                expect(page.locator("#incident")).to_contain_text(asked)
                assert not [message for message in sent if message["type"] == "control"]
                page.evaluate(SET_DEVICES, [wheel(throttle=1.0)])   # not calibrated: not read
                manual_for(page, 1.0)
                expect(page.locator("#incident")).to_contain_text("not calibrated")
                assert not [message for message in sent if message["type"] == "control"]
                calibrate_wheel(page)   # in the drive, where the station offers it
                page.evaluate(SET_DEVICES, [wheel(throttle=1.0)])
                # on a slow machine the car, coasting (paced in real time) while no device was
                # read, may reach the hold before the junction meanwhile and stand there, where no
                # control is sent: then the person hands back and takes over on the next road
                deadline = time.monotonic() + 120
                while not [message for message in sent if message["type"] == "control"]:
                    assert time.monotonic() < deadline, ("no control was sent for the wheel", errors)
                    if "MANUAL" in page.locator("#mode").inner_text() and told_to_hand_back(page):
                        hand_back_for_the_next_road(page)
                    take_over(page)
                    time.sleep(0.05)
                expect(page.locator("#incident")).not_to_contain_text(asked)
            finally:
                browser.close()
    finally:
        process.kill()
        process.wait()
    controls = [message for message in sent if message["type"] == "control"]
    assert controls and {message["source"] for message in controls} == {"wheel"}
