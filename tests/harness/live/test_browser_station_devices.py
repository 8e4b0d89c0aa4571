"""Several driving devices at once in real Chromium: a wheel whose pedals are a device of their own
(a Thrustmaster T-LCM, Fanatec pedals, a Logitech wheel with its pedals on their own USB), each
calibrated for what is on it in one walk-through, and a gamepad beside them; each control taken
from the device that gives it, of two the one deflected furthest (harness/live/pages/inputs.js,
docs/live_studies.md "Driving with a wheel"). The websocket is answered by the test with the
server's messages as in test_browser_station.py.

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import pytest

from .test_browser_station import station_fixture
from .test_browser_station_controls import (
    DEAD_ZONE,
    SET_DEVICES,
    calibrate,
    controls,
    devices_ready,
    drive,
    gamepad,
    outside,
)
from .test_driver_view import wait_until

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


station = station_fixture("devices")

WHEEL = "virtual wheel, pedals apart"
PEDALS = "virtual pedal box"
# The calibrations the page keeps (inputs.js, loadCalibrations), by device id.
CALIBRATIONS = """async () => (await import("/static/inputs.js")).loadCalibrations()"""


def wheel_alone(steer: float = 0, button: bool = False) -> dict:
    """A wheel with no pedals on it: its steering axis 0, its take-over button 4."""
    return {"id": WHEEL, "mapping": "", "axes": [steer, 0, 0, 0], "buttons": {4: 1} if button else {}}


def pedal_box(throttle: float = 0, brake: float = 0) -> dict:
    """Pedals on their own USB, with no button: accelerator, brake and clutch axes resting at 1 and
    pressed at -1 (a T-LCM's); the clutch is never pressed."""
    return {"id": PEDALS, "mapping": "", "axes": [1 - 2 * throttle, 1 - 2 * brake, 1], "buttons": {}}


def wheel_and_pedals(steer: float = 0, throttle: float = 0, brake: float = 0,
                     button: bool = False) -> list[dict]:
    return [wheel_alone(steer, button), pedal_box(throttle, brake)]


def test_a_wheel_and_a_separate_pedal_box_drive_together(station, tmp_path):
    """One walk-through calibrates both: the wheel for its steering and button, the pedal box for
    its accelerator and brake, each its own calibration; in the drive the steering comes from the
    wheel and the pedals from the box at once, the wheel's button takes over and hands back. A
    gamepad connected beside them at rest takes nothing over; its stick deflected further than the
    wheel steers, its trigger pressed further than the box's accelerator accelerates."""
    with devices_ready(station, ["wheel", "gamepad"]) as (page, socket, sent_after, frame):
        page.evaluate(SET_DEVICES, wheel_and_pedals())
        page.locator("#calibration-text").filter(has_text="not calibrated").wait_for()
        page.locator("#calibrate").click()
        page.locator("#calibration-text").filter(has_text=PEDALS).wait_for()
        page.screenshot(path=str(tmp_path / "calibrate-two-devices.png"))
        said = calibrate(page, wheel_and_pedals)[-1]   # started again
        page.screenshot(path=str(tmp_path / "calibrated-two-devices.png"))
        assert f'"{WHEEL}": the steering, the button' in said
        assert f'"{PEDALS}": the accelerator, the brake' in said
        kept = page.evaluate(CALIBRATIONS)
        assert kept[WHEEL]["steer"]["axis"] == 0 and kept[WHEEL]["button"] == 4
        assert kept[WHEEL]["throttle"] is None and kept[WHEEL]["brake"] is None
        assert kept[PEDALS]["steer"] is None and kept[PEDALS]["button"] is None
        assert (kept[PEDALS]["throttle"]["axis"], kept[PEDALS]["brake"]["axis"]) == (0, 1)
        drive(page, socket, {**frame, "speed": 5.0})
        dead_zone = page.evaluate(DEAD_ZONE)
        half = round(outside(0.5, dead_zone), 3)
        assert controls(sent_after(SET_DEVICES, wheel_and_pedals(steer=-1.0, throttle=1.0))) == [
            ("wheel", -1.0, 1.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, wheel_and_pedals(steer=0.5, brake=1.0))) == [
            ("wheel", half, 0.0, 1.0)]
        pressed = sent_after(SET_DEVICES, wheel_and_pedals(steer=0.5, brake=1.0, button=True))
        assert [message["type"] for message in pressed] == ["hand_back"]
        page.evaluate(SET_DEVICES, wheel_and_pedals(steer=0.5, brake=1.0))
        resting_pad = [*wheel_and_pedals(steer=0.5, throttle=0.5), gamepad()]
        assert controls(sent_after(SET_DEVICES, resting_pad)) == [("wheel", half, half, 0.0)]
        further = [*wheel_and_pedals(steer=0.5, throttle=0.5), gamepad(steer=-1.0, throttle=1.0)]
        assert controls(sent_after(SET_DEVICES, further)) == [("gamepad", -1.0, 1.0, 0.0)]


def test_the_pedal_box_unplugged_mid_drive_lets_go_of_the_accelerator(station, tmp_path):
    """The pedal box goes with the accelerator down: the page sends it let go (the episode keeps
    the last control it was sent) while the wheel still steers, and says what is missing; back,
    it accelerates again."""
    with devices_ready(station, ["wheel"]) as (page, socket, sent_after, frame):
        page.evaluate(SET_DEVICES, wheel_and_pedals())
        calibrate(page, wheel_and_pedals)
        drive(page, socket, {**frame, "speed": 5.0})
        assert controls(sent_after(SET_DEVICES, wheel_and_pedals(steer=1.0, throttle=1.0))) == [
            ("wheel", 1.0, 1.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [wheel_alone(steer=1.0)])) == [("wheel", 1.0, 0.0, 0.0)]
        missing = "No device connected gives the accelerator or the brake"
        page.locator("#incident").filter(has_text=missing).wait_for()
        page.screenshot(path=str(tmp_path / "pedals-unplugged.png"))
        assert controls(sent_after(SET_DEVICES, [wheel_alone(steer=-1.0)])) == [("wheel", -1.0, 0.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, wheel_and_pedals(steer=-1.0, throttle=1.0))) == [
            ("wheel", -1.0, 1.0, 0.0)]
        wait_until(page, "!document.getElementById('incident').textContent.includes('No device')")


def test_a_pedal_box_alone_is_calibrated_without_a_steering_step(station, tmp_path):
    """A pedal box has no steering axis: the steps it does not move (the wheel's, the button's) are
    not on it, and the walk-through goes on to the pedals without asking for the right turn; its
    calibration gives the accelerator and the brake only. Driving with it, the steering is asked
    for, the accelerator drives."""
    with devices_ready(station, ["wheel"]) as (page, socket, sent_after, frame):
        page.evaluate(SET_DEVICES, [pedal_box()])
        shown = calibrate(page, lambda steer=0, button=False, **pedals: [pedal_box(**pedals)])
        assert not [text for text in shown if "fully to the right" in text]
        assert shown[-1].startswith("Calibrated") and f'"{PEDALS}": the accelerator, the brake).' in shown[-1]
        # the ready step goes on saying both what was calibrated and what is still wanted
        wait_until(page, "(t => t.startsWith('Calibrated') && t.includes('No device connected gives "
                   "the steering'))(document.getElementById('calibration-text').textContent)")
        page.screenshot(path=str(tmp_path / "pedal-box-calibrated.png"))
        kept = page.evaluate(CALIBRATIONS)[PEDALS]
        assert kept["steer"] is None and kept["button"] is None
        assert (kept["throttle"]["rest"], kept["throttle"]["full"]) == (1, -1)
        assert (kept["brake"]["axis"], kept["brake"]["rest"], kept["brake"]["full"]) == (1, 1, -1)
        drive(page, socket, {**frame, "speed": 5.0})
        assert controls(sent_after(SET_DEVICES, [pedal_box(throttle=1.0)])) == [("wheel", 0.0, 1.0, 0.0)]
        page.locator("#incident").filter(has_text="No device connected gives the steering").wait_for()


# Counts the page's looks at the devices (`window.looks`) and the animation frames (`window.drawn`).
COUNT_LOOKS = """() => {
  const look = navigator.getGamepads;
  window.looks = 0;
  navigator.getGamepads = () => { window.looks += 1; return look(); };
  window.drawn = 0;
  const count = () => { window.drawn += 1; requestAnimationFrame(count); };
  requestAnimationFrame(count);
}"""
COUNTS = "[window.looks, window.drawn]"


def test_the_station_looks_at_the_devices_once_an_animation_frame(station):
    """The controls and what the station asks for come from one look at the devices (one
    `navigator.getGamepads()` call) in each animation frame of a drive."""
    with devices_ready(station, ["gamepad"]) as (page, socket, _, frame):
        page.evaluate(SET_DEVICES, [gamepad()])
        drive(page, socket, {**frame, "speed": 5.0})
        page.evaluate(COUNT_LOOKS)
        page.wait_for_timeout(200)
        looks, drawn = page.evaluate(COUNTS)
        page.wait_for_timeout(1000)
        looks_after, drawn_after = page.evaluate(COUNTS)
    frames = drawn_after - drawn
    assert frames > 10, frames
    assert frames - 2 <= looks_after - looks <= frames + 2, (looks_after - looks, frames)
