"""The station's driving controls in real Chromium (a gamepad read through the Gamepad API, a
wheel's pedals, each device by its own calibration or the standard mapping, the dead zone, the
arrow keys), the websocket answered by the test with the server's messages as in
test_browser_station.py.

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import contextlib
import json
import math

import pytest

from .test_browser_station import GOAL, end_message, state_message, station_fixture
from .test_driver_view import scene_on, wait_until

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


station = station_fixture("controls")


GAMEPAD = """window.pad = { steer: 0, throttle: 0, button: false, connected: true };
navigator.getGamepads = () => !window.pad.connected ? [null] : [{
  id: "virtual gamepad", index: 0, connected: true, mapping: "standard", timestamp: performance.now(),
  axes: [window.pad.steer, 0, 0, 0], buttons: Array.from({ length: 17 }, (_, i) => {
    const pressed = i === 0 && window.pad.button;
    return { pressed, touched: pressed, value: i === 7 ? window.pad.throttle : Number(pressed) };
  }),
}];"""


def gamepad_station(page, socket, frame: dict):
    """The page in a continuous drive read from the virtual gamepad, `frame` shown and the car
    taken over; returns sent_for(**pad): the controls and hand-backs the page sends once the pad is
    set to `pad` (what the messages before it brought is sent by then, and left out)."""
    sent_after = listen(page, socket)
    page.evaluate(GAMEPAD)
    welcome(socket, ["gamepad"])
    drive(page, socket, frame)
    return lambda **pad: sent_after("(values) => Object.assign(window.pad, values)", pad)


def listen(page, socket):
    """sent_after(script, arg): the controls and hand-backs the page sends once `script` has run
    with `arg` in the page (what came before it is sent by then, and left out)."""
    received: list[dict] = []
    socket.on_message(lambda text: received.append(json.loads(text)))

    def sent(messages: list[dict]) -> list[dict]:
        return [message for message in messages if message["type"] in ("control", "hand_back")]

    def sent_after(script: str, arg) -> list[dict]:
        # what the page sends before `script` has settled first: 300 ms with nothing more sent (on a
        # loaded machine the page's first control after a takeover can come later than 300 ms)
        before = -1
        while len(sent(received)) != before:
            before = len(sent(received))
            page.wait_for_timeout(300)
        count = len(received)
        page.evaluate(script, arg)
        page.wait_for_timeout(400)   # many animation frames have read the device by then
        return sent(received[count:])

    return sent_after


def reading(page):
    """read(value): what the page sends for a stick or trigger at `value` (the dead zone taken
    out, inputs.js DEAD_ZONE; rounded as the page rounds it)."""
    dead_zone = page.evaluate(DEAD_ZONE)
    return lambda value: round(outside(value, dead_zone), 3)


def welcome(socket, inputs: list[str]) -> None:
    socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver",
                            "driving": "continuous", "inputs": inputs}))


def drive(page, socket, frame: dict) -> None:
    """The drive runs, `frame` shown, and the car taken over."""
    socket.send(state_message("driving"))
    socket.send(json.dumps({"type": "episode_start", "episode_id": "x", "trust": 4}))
    socket.send(json.dumps(frame))
    socket.send(json.dumps({"type": "mode", "mode": "manual", "t": 10.0}))
    wait_until(page, "document.getElementById('mode').textContent === 'MANUAL'")


def test_a_gamepad_sends_nothing_while_the_car_is_held_paused_or_its_drive_over(station, tmp_path):
    """The one rule of the buttons and keys holds for a wheel or gamepad: while the car is held for
    the hand-back (in its lane, or back in it after being guided back) the accelerator is sent let
    go and, once the car stands, nothing at all; guided back from the oncoming lane the pedals still
    drive it; its button hands back; while paused, and once the drive is over, nothing is sent.
    Each driving event comes as the episode sends it: its warning, then the step's frame with the
    hold as the episode has it then (`held`)."""
    frame, _ = scene_on(station.net_path)
    moving = {**frame, "speed": 5.0}
    with station.open() as (page, socket):
        sent_for = gamepad_station(page, socket, moving)
        read = reading(page)

        def warn(kind: str, held: bool = False, **shown) -> None:
            socket.send(json.dumps({"type": "warning", "kind": kind, "t": 11.0}))
            socket.send(json.dumps({**moving, "t": 11.0, **shown, "held": held}))

        assert [c["throttle"] for c in sent_for(throttle=1.0)] == [1.0]
        for kind in ("oncoming", "hand_back", "guide_back"):   # guided back: the pedals still drive it
            warn(kind)
        assert [c["throttle"] for c in sent_for(throttle=0.6)] == [read(0.6)]
        warn("own_lane", held=True)   # back in its lane: the hold brakes it to a stand
        held = sent_for(steer=0.5, throttle=0.9)
        assert [(c["steer"], c["throttle"], c["brake"]) for c in held] == [(read(0.5), 0.0, 0.0)]
        socket.send(json.dumps({**frame, "t": 10.5, "held": True}))   # standing
        assert sent_for(steer=-0.5, throttle=1.0) == []
        assert [m["type"] for m in sent_for(button=True)] == ["hand_back"]
        socket.send(json.dumps({"type": "mode", "mode": "auto", "t": 12.0}))
        page.evaluate("window.pad.button = false")
        socket.send(json.dumps({**moving, "t": 12.5}))
        socket.send(json.dumps({"type": "mode", "mode": "manual", "t": 13.0}))   # taken over again
        assert [c["throttle"] for c in sent_for(throttle=0.8)] == [read(0.8)]
        warn("hold", held=True, t=13.5)   # held in its lane
        page.locator("#incident").filter(has_text="the car stops here").wait_for()
        assert [c["throttle"] for c in sent_for(steer=0.2, throttle=0.7)] == [0.0]
        page.screenshot(path=str(tmp_path / "gamepad-held.png"))
        socket.send(state_message("paused", paused_by="experimenter", mode="manual"))
        page.locator("#overlay-text").filter(has_text="Paused by the experimenter").wait_for()
        assert sent_for(steer=-0.3, button=True) == []
        page.evaluate("window.pad.button = false")
        socket.send(state_message("driving", mode="manual"))
        socket.send(end_message({**GOAL, "takeovers": 1}))
        assert sent_for(steer=0.4, throttle=1.0, button=True) == []
        page.screenshot(path=str(tmp_path / "gamepad-over.png"))


def test_by_wheel_the_station_holds_the_pedals_as_the_frames_say_not_as_the_warnings_do(station, tmp_path):
    """The hold is the episode's (each frame's `held`, harness/simulation/wheel_driving.py
    `Wheel.held`), never worked out in the page from the warnings: frames held with no warning
    at all make the page send the pedals let go, and nothing once the car stands; a `hold` warning
    whose frames are not held leaves the pedals to the person."""
    frame, _ = scene_on(station.net_path)
    moving = {**frame, "speed": 5.0, "mode": "manual"}
    with station.open() as (page, socket):
        sent_for = gamepad_station(page, socket, moving)
        read = reading(page)
        assert [c["throttle"] for c in sent_for(throttle=1.0)] == [1.0]
        page.screenshot(path=str(tmp_path / "wheel-normal.png"))
        socket.send(json.dumps({**moving, "t": 10.5, "held": True}))
        held = sent_for(steer=0.3, throttle=0.7)
        assert [(c["steer"], c["throttle"], c["brake"]) for c in held] == [(read(0.3), 0.0, 0.0)]
        page.screenshot(path=str(tmp_path / "wheel-held.png"))
        socket.send(json.dumps({**moving, "t": 11.0, "speed": 0.0, "held": True}))   # standing
        assert sent_for(steer=-0.3, throttle=1.0) == []
        socket.send(json.dumps({"type": "warning", "kind": "hold", "t": 11.5}))
        socket.send(json.dumps({**moving, "t": 11.5, "held": False}))
        page.locator("#incident").filter(has_text="the car stops here").wait_for()
        sent = sent_for(steer=0.1, throttle=0.5)
        assert [(c["steer"], c["throttle"]) for c in sent] == [(read(0.1), read(0.5))]


def test_a_gamepad_disconnected_in_control_lets_go_of_what_it_last_sent(station):
    """The episode keeps the last control it was sent: a pad unplugged (or its batteries flat)
    with the accelerator down would leave the car accelerating with no one's foot on it. The page
    sends the controls let go (steer, throttle and brake 0, as a person's hands and feet off a
    wheel and pedals), once, says what to connect, and the pad drives again when it is back."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        sent_for = gamepad_station(page, socket, {**frame, "speed": 5.0})
        read = reading(page)
        assert [(c["steer"], c["throttle"]) for c in sent_for(steer=0.2, throttle=1.0)] == [(read(0.2), 1.0)]
        gone = sent_for(connected=False)
        assert [(c["source"], c["steer"], c["throttle"], c["brake"]) for c in gone] == [("gamepad", 0, 0, 0)]
        page.locator("#incident").filter(has_text="Connect a gamepad").wait_for()
        assert [c["throttle"] for c in sent_for(connected=True, throttle=0.5)] == [read(0.5)]


KEY_STEERING = """async ([speed, step, steps]) => {
  if (!window.keyInputs) window.keyInputs = new (await import("/static/inputs.js")).Inputs(["keyboard"]);
  window.keyInputs.keySteer = 0;
  return Array.from({ length: steps }, () => window.keyInputs.read(step, speed).steer);
}"""


def lateral_acceleration(speed: float, steer: float) -> float:
    """m/s^2 of the vehicle model (harness/simulation/vehicle_model.py) at `speed` and `steer`."""
    from trustroute.harness.simulation.vehicle_model import VehicleParams

    params = VehicleParams()
    return speed**2 * math.tan(math.radians(abs(steer) * params.max_wheel_angle)) / params.wheelbase


def test_the_arrow_keys_steer_more_gently_the_faster_the_car(station):
    """A held arrow key turns the wheel to full lock in about 0.67 s at a walking pace; at 50 km/h
    a tap of 0.1 s asks for under 1 m/s^2 of lateral acceleration and a key held on for 3 s for no
    more than about 4.3 m/s^2 (full lock at 4.5 m/s), reached in about the same 0.67 s."""
    step = 0.02
    with station.open() as (page, _):
        page.evaluate(KEY_STEERING, [0, step, 1])   # listening to the keys
        page.keyboard.down("ArrowRight")
        slow = page.evaluate(KEY_STEERING, [2.0, step, 40])
        fast = page.evaluate(KEY_STEERING, [13.9, step, 150])
        page.keyboard.up("ArrowRight")
    assert slow[33] == pytest.approx(1.0)   # full lock after 0.68 s
    assert lateral_acceleration(13.9, fast[4]) < 1.0   # a tap of 0.1 s
    assert max(lateral_acceleration(13.9, steer) for steer in fast) <= 4.4
    assert lateral_acceleration(13.9, fast[34]) > 3.5   # the most it asks, within 0.7 s
    assert all(later >= earlier for earlier, later in zip(fast, fast[1:], strict=False))


# The devices the page finds (`window.devices`, the first is read): a wheel, its pedals axes resting
# at 1 and pressed at -1 (a G29's), its button 4; a gamepad in the standard mapping, its left stick
# axis 0, its triggers buttons 6 (brake) and 7 (throttle), its A button 0.
DEVICES = """window.devices = [];
navigator.getGamepads = () => window.devices.map((device, index) => ({
  id: device.id, index, connected: true, mapping: device.mapping, timestamp: performance.now(),
  axes: [...device.axes], buttons: Array.from({ length: 17 }, (_, i) => {
    const value = device.buttons[i] ?? 0;
    return { pressed: value > 0.5, touched: value > 0, value };
  }),
}));"""
SET_DEVICES = "(devices) => { window.devices = devices; }"
DEAD_ZONE = """async () => (await import("/static/inputs.js")).DEAD_ZONE"""


def wheel(steer: float = 0, throttle: float = 0, brake: float = 0, button: bool = False,
          name: str = "virtual wheel A") -> dict:
    return {"id": name, "mapping": "", "axes": [steer, 1 - 2 * throttle, 1 - 2 * brake, 0],
            "buttons": {4: 1} if button else {}}


def gamepad(steer: float = 0, throttle: float = 0, brake: float = 0, name: str = "virtual gamepad B") -> dict:
    return {"id": name, "mapping": "standard", "axes": [steer, 0, 0, 0], "buttons": {6: brake, 7: throttle}}


# What a person does at each step of the calibration, by the words of its instruction (inputs.js,
# STEPS; "Connect": the first step before any device is connected, at rest like it).
CALIBRATION_STEPS = {"Connect": {}, "Let go": {}, "fully to the left": {"steer": -1},
                     "fully to the right": {"steer": 1}, "accelerator pedal fully": {"throttle": 1},
                     "brake pedal fully": {"brake": 1}, "Hold the button": {"button": True}}


def calibrate(page, devices) -> list[str]:
    """The station's calibration (*Calibrate the wheel*, then *Next* at each step) of the devices
    `devices(**held)` (the list the page finds), held as each step's instruction asks, and let go
    after it; returns the texts it showed, the last the one it ended with."""
    page.locator("#calibrate").click()
    text = page.locator("#calibration-text")
    shown = [text.text_content() or ""]
    for _ in range(len(CALIBRATION_STEPS)):
        held = next((held for words, held in CALIBRATION_STEPS.items() if words in shown[-1]), None)
        assert held is not None, f"the calibration asks for no step of a person's: {shown[-1]!r}"
        page.evaluate(SET_DEVICES, devices(**held))
        page.locator("#calibrate-next").click()
        shown.append(text.text_content() or "")
        if shown[-1].startswith("Calibrated"):
            break
    # (in a drive the box goes once the wheel is read: its text is looked at, not seen)
    wait_until(page, "document.getElementById('calibration-text').textContent.startsWith('Calibrated')")
    page.evaluate(SET_DEVICES, devices())
    return shown


def calibrate_wheel(page, **wheel_values) -> None:
    """The calibration of the wheel `wheel(**wheel_values)` alone."""
    calibrate(page, lambda **held: [wheel(**{**wheel_values, **held})])


def outside(value: float, dead_zone: float) -> float:
    """`value` (-1..1) past the dead zone, rescaled to full travel (inputs.js, DEAD_ZONE)."""
    return math.copysign(max(0.0, abs(value) - dead_zone) / (1 - dead_zone), value)


@contextlib.contextmanager
def devices_ready(station, inputs: list[str]):
    """A station whose page reads devices the test sets (DEVICES), welcomed to a study of
    `inputs`, on its ready step: yields (page, socket, sent_after, a frame of the scene)."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        sent_after = listen(page, socket)
        page.evaluate(DEVICES)
        welcome(socket, inputs)
        socket.send(state_message("ready", trial=0))
        yield page, socket, sent_after, frame


def controls(sent: list[dict]) -> list[tuple]:
    return [(c["source"], c["steer"], c["throttle"], c["brake"]) for c in sent if c["type"] == "control"]


def test_a_calibration_is_the_devices_own_and_another_device_is_read_by_the_standard_mapping(station):
    """A wheel calibrated on the ready step is read by its calibration; a gamepad connected
    after it is read in the standard mapping (its stick steers, its trigger accelerates), not
    through the wheel's axes (where its resting axis 1 would be the accelerator half pressed); the
    wheel back, its calibration still applies."""
    with devices_ready(station, ["wheel", "gamepad"]) as (page, socket, sent_after, frame):
        page.locator("#calibrate").wait_for(state="visible")
        page.evaluate(SET_DEVICES, [wheel()])
        calibrate_wheel(page)
        drive(page, socket, {**frame, "speed": 5.0})
        full = sent_after(SET_DEVICES, [wheel(steer=1.0, throttle=1.0)])
        assert controls(full) == [("wheel", 1.0, 1.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [gamepad(steer=-1.0, throttle=1.0)])) == [
            ("gamepad", -1.0, 1.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [gamepad()])) == [("gamepad", 0.0, 0.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [wheel(brake=1.0)])) == [("wheel", 0.0, 0.0, 1.0)]


def test_a_wheel_not_calibrated_is_not_read_and_the_station_offers_the_calibration(station, tmp_path):
    """A device outside the standard mapping, with no calibration for its id, is not read through
    the standard layout (its pedals, axes there, would do nothing): the ready step and, in a
    drive, the notice over the view say it must be calibrated, nothing is sent for it, and
    *Calibrate the wheel* is there in the drive too; once calibrated it drives."""
    with devices_ready(station, ["wheel", "gamepad"]) as (page, socket, sent_after, frame):
        page.evaluate(SET_DEVICES, [wheel()])
        asked = "not calibrated"
        page.locator("#calibration-text").filter(has_text=asked).wait_for()
        page.screenshot(path=str(tmp_path / "uncalibrated-ready.png"))
        drive(page, socket, {**frame, "speed": 5.0})
        assert controls(sent_after(SET_DEVICES, [wheel(steer=0.5, throttle=1.0)])) == []
        page.locator("#incident").filter(has_text=asked).wait_for()
        page.locator("#calibrate").wait_for(state="visible")
        page.screenshot(path=str(tmp_path / "uncalibrated-drive.png"))
        calibrate_wheel(page)
        wait_until(page, f"!document.getElementById('incident').textContent.includes({asked!r})")
        assert controls(sent_after(SET_DEVICES, [wheel(throttle=1.0)])) == [("wheel", 0.0, 1.0, 0.0)]


def test_a_dead_zone_keeps_a_drifting_stick_or_an_off_centre_wheel_from_steering(station):
    """Within DEAD_ZONE of rest (after the calibration) the steering and the pedals read 0, so a
    stick or pedal that drifts sends nothing; beyond it they are rescaled, full travel still full."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        sent_for = gamepad_station(page, socket, {**frame, "speed": 5.0})
        dead_zone = page.evaluate(DEAD_ZONE)
        assert 0 < dead_zone < 0.2
        drift = 0.8 * dead_zone
        assert [(c["steer"], c["throttle"]) for c in sent_for(steer=drift, throttle=1.0)] == [(0.0, 1.0)]
        assert [(c["steer"], c["throttle"]) for c in sent_for(steer=-drift, throttle=0.0)] == [(0.0, 0.0)]
        assert sent_for(steer=drift, throttle=drift) == []   # drifting: nothing to send
        half = [(c["steer"], c["throttle"]) for c in sent_for(steer=-0.5, throttle=0.5)]
        assert half == [(pytest.approx(outside(-0.5, dead_zone), abs=1e-3),
                         pytest.approx(outside(0.5, dead_zone), abs=1e-3))]
        assert [(c["steer"], c["throttle"]) for c in sent_for(steer=1.0, throttle=1.0)] == [(1.0, 1.0)]


def test_a_calibrated_wheel_resting_off_centre_sends_no_steering(station):
    """The dead zone applies after the calibration: a wheel resting a little off the centre it
    was calibrated at, its pedals a little off their rest, reads 0; full lock is still 1."""
    with devices_ready(station, ["wheel"]) as (page, socket, sent_after, frame):
        page.evaluate(SET_DEVICES, [wheel()])
        calibrate_wheel(page)
        drive(page, socket, {**frame, "speed": 5.0})
        off = 0.8 * page.evaluate(DEAD_ZONE)
        full = sent_after(SET_DEVICES, [wheel(steer=1.0, throttle=1.0)])
        assert controls(full) == [("wheel", 1.0, 1.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [wheel(steer=off, throttle=off, brake=off)])) == [
            ("wheel", 0.0, 0.0, 0.0)]
        assert controls(sent_after(SET_DEVICES, [wheel(steer=-off, brake=off)])) == []


def test_a_person_held_for_the_hand_back_is_told_to_hand_back_whatever_else_is_said(station, tmp_path):
    """Held for the hand-back, the car waits for it: the station says so until it comes, over
    whatever else comes meanwhile. A hold that begins while the wheel waits for its calibration is
    said beside that ask, and stays once the wheel is calibrated; an incident ahead and the road's
    end do not take it down; frames held with no warning at all (a takeover after the commit point
    is held at the road's end with no warning to hand back; a page opened mid-hold saw none) say it
    too; the hand-back ends it."""
    incident = "document.getElementById('incident').textContent"
    with devices_ready(station, ["wheel"]) as (page, socket, _, frame):
        moving = {**frame, "speed": 5.0, "mode": "manual"}
        page.evaluate(SET_DEVICES, [wheel()])
        drive(page, socket, moving)
        asked = "not calibrated"
        page.locator("#incident").filter(has_text=asked).wait_for()
        socket.send(json.dumps({"type": "warning", "kind": "hold", "t": 10.5}))
        socket.send(json.dumps({**moving, "t": 10.5, "speed": 0.0, "held": True}))
        # said beside the ask (which the page writes at every animation frame)
        hold = "The junction is near: the car stops here. Hand back now."
        wait_until(page, f"{incident}.includes({asked!r}) && {incident}.endsWith({hold!r})")
        page.screenshot(path=str(tmp_path / "held-uncalibrated.png"))
        calibrate_wheel(page)
        wait_until(page, f"!{incident}.includes({asked!r})")
        page.wait_for_timeout(300)   # animation frames read the calibrated wheel
        assert page.evaluate(incident) == hold
        socket.send(json.dumps({"type": "incident", "kind": "obstacle", "t": 11.0}))
        socket.send(json.dumps({"type": "road", "index": 1, "incident": "none", "takeover": True,
                                "performance": "succ", "t": 11.0, "prompt": None}))
        page.wait_for_timeout(300)
        assert page.evaluate(incident) == hold
        page.screenshot(path=str(tmp_path / "held-calibrated.png"))
        socket.send(json.dumps({"type": "mode", "mode": "auto", "t": 12.0}))
        socket.send(json.dumps({**moving, "t": 12.0, "mode": "auto", "held": False}))
        wait_until(page, f"{incident} === ''")
        socket.send(json.dumps({"type": "mode", "mode": "manual", "t": 13.0}))   # after the commit point
        socket.send(json.dumps({**moving, "t": 13.0, "held": False}))
        page.wait_for_timeout(300)
        assert page.evaluate(incident) == ""
        socket.send(json.dumps({**moving, "t": 13.5, "held": True}))   # held, with no warning
        page.locator("#incident").filter(has_text="Hand back before the junction (space)").wait_for()
        page.screenshot(path=str(tmp_path / "held-unwarned.png"))
