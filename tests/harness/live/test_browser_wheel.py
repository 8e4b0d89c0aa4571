"""Driving by wheel in a real browser: Debian's Chromium with software WebGL (the driver's view)
against `trustroute live` with `[live] driving = "continuous"` and real SUMO. A script injected into
the page replaces `navigator.getGamepads` with a virtual wheel (pedals resting at 1 and pressed at
-1, like a G29's); the test calibrates it on the station's calibration page, then turns it and
presses its pedals as a person would, reading the driver's view's frames:

- on an obstacle road it takes over, steers into the oncoming lane, passes, steers back and hands
  back; the part's kinematics show the lateral movement at 20 Hz, every tick of it manual;
- in a second session it steers into the oncoming truck of a truck road: the collision is shown
  and logged, the car stops against it, the person hands back and the episode goes on to its
  end on autopilot (harness/simulation/wheel_driving.py, docs/live_studies.md).

The person is a script in the page too (`PERSON`): it reacts to every frame the page receives,
within the page's own input delay, however loaded the machine (a round trip to the test per frame
made it steer late and weave). Each session is one short trial of a spec written here (two
Town01 roads: a start road, then the incident's road, entered straight on), at a person's pace (1):
about a minute of simulated and of wall time per session."""

from __future__ import annotations

import math
import threading
import time

import httpx
import pytest

from benchmarks.bench_live import start_live_server
from tests.browser import chromium_executable
from trustroute.core.dataset import read_kinematics
from trustroute.harness.study.parts import read_part

from .test_browser import CHROMIUM_ARGS, create_participant

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

CONFIG = """[study]
name = "wheel-live"
participants = 1
seed = {seed}
engine = "live"
specs = ["{spec}.toml"]
conditions = ["free"]

[live]
driving = "continuous"
inputs = ["wheel"]
"""
# one trial: the start road, then the incident's road (its end satisfies the spec)
SPEC = 'name = "{name}"\nstart = "{start}"\nformula = "F v1"\n\n[states]\nv1 = ["{road}"]\n'
# E-A: an obstacle 180-280 m into its 510 m, after a corner 85 m in; entered straight on from L-E.
# Seed 24 stands it 271 m in with no oncoming vehicle: the person sees it straight ahead once it is
# within the frames' 150 m (harness/live/view.py), about 118 m in, some 55 m (4 s) before SUMO's
# autopilot pulls out to pass it, about 174 m in. The takeover must come in between, and on a
# loaded machine the frames the page sees may be a second or two behind: seed 1's obstacle, 202 m
# in, left about 1 s from the corner's end
PASS = {"name": "wheelpass", "start": "L-E", "road": "E-A", "seed": 24}
CRASH = {"name": "wheelcrash", "start": "J-K", "road": "K-L", "seed": 1}   # K-L: an oncoming truck, 128 m
VIRTUAL_WHEEL = """
window.wheel = { steer: 0, throttle: 0, brake: 0, button: false };
navigator.getGamepads = () => [{
  id: "virtual wheel", index: 0, connected: true, mapping: "", timestamp: performance.now(),
  axes: [window.wheel.steer, 1 - 2 * window.wheel.throttle, 1 - 2 * window.wheel.brake, 0],
  buttons: Array.from({ length: 12 }, (_, i) => {
    const pressed = i === 4 && window.wheel.button;
    return { pressed, touched: pressed, value: pressed ? 1 : 0 };
  }),
}];
"""
# The person, in the page: at every new frame of the driver's view (the frames the page draws) it
# reads the station as a participant would and turns the virtual wheel and presses its pedals;
# being in the page, it reacts within the page's own input delay, however loaded the machine.
# Its state (stage, outcome, a trace of what it saw) is `window.person`.
PERSON = """
window.startPerson = async ({ road, crash, cruise }) => {
  const net = await (await fetch("/api/net")).json();
  let shape = null, lowest = Infinity;   // the centre line of the road's rightmost lane for cars
  for (const lane of net.lanes) {
    if (lane.id.slice(0, lane.id.lastIndexOf("_")) === road && lane.kind === "road" && lane.index < lowest) {
      shape = lane.shape; lowest = lane.index;
    }
  }
  const $ = (id) => document.getElementById(id);
  const wheel = window.wheel;
  const person = window.person = { stage: "wait", trace: [], thing: null, pressing: null,
    outcome: { took_over: false, passed: false, collision_shown: false, handed_back: false } };
  // [metres left of the line, its SUMO angle there, metres along it] of a point; the line goes on
  // straight before its start (the junction before the road)
  const onLane = (x, y) => {
    let best = null, travelled = 0;
    for (let i = 0; i + 1 < shape.length; i++) {
      const [ax, ay] = shape[i], [bx, by] = shape[i + 1];
      const length = Math.hypot(bx - ax, by - ay) || 1;
      const t = Math.max(i === 0 ? -Infinity : 0,
                         Math.min(1, ((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / length ** 2));
      const distance = Math.hypot(x - ax - t * (bx - ax), y - ay - t * (by - ay));
      if (!best || distance < best[0]) {
        const cross = (bx - ax) * (y - ay) - (by - ay) * (x - ax);
        best = [distance, Math.sign(cross) * distance, Math.atan2(bx - ax, by - ay) * 180 / Math.PI,
                travelled + t * length];
      }
      travelled += length;
    }
    return best.slice(1);
  };
  const headingError = (frame) => {   // radians, clockwise positive
    const [, angle] = onLane(frame.x, frame.y);
    return ((frame.angle - angle + 540) % 360 - 180) * Math.PI / 180;
  };
  const ahead = (frame, thing) => {
    const heading = frame.angle * Math.PI / 180;
    return (thing[0] - frame.x) * Math.sin(heading) + (thing[1] - frame.y) * Math.cos(heading);
  };
  const aside = (frame, thing) => {   // metres to the right of the car's heading
    const heading = frame.angle * Math.PI / 180;
    return (thing[0] - frame.x) * Math.cos(heading) - (thing[1] - frame.y) * Math.sin(heading);
  };
  // toward `target` metres left of the lane's centre at about `speed` (m/s)
  const steerTo = (frame, target, speed) => {
    const [left] = onLane(frame.x, frame.y);
    const wanted = Math.max(-0.25, Math.min(0.25, 0.12 * (left - target)));
    wheel.steer = Math.max(-0.3, Math.min(0.3, 0.8 * (wanted - headingError(frame))));
    wheel.throttle = frame.speed < speed ? 0.5 : 0;
    wheel.brake = frame.speed > speed + 1 ? 0.6 : 0;
    return left;
  };
  // the button held until the mode is `mode` (or 1.5 s: a refused hand-back), then let go
  const press = (mode) => {
    if (!person.pressing) { wheel.button = true; person.pressing = { mode, since: performance.now() }; }
  };
  const pressed = (mode) => {
    const pressing = person.pressing;
    if (!pressing) return false;
    const done = $("mode").textContent === pressing.mode;
    if (done || performance.now() - pressing.since > 1500) { wheel.button = false; person.pressing = null; }
    return done;
  };
  let seen = -1;
  const react = () => {
    const frames = window.driverView ? window.driverView.frames : [];
    if (!frames.length || $("drive-step").classList.contains("hidden")) return;
    const frame = frames[frames.length - 1].frame;
    if (frame.t === seen) return;
    seen = frame.t;
    const notice = $("incident").textContent;
    const [left, , along] = onLane(frame.x, frame.y);
    person.trace.push([frame.t, frame.lane, frame.mode, +along.toFixed(1), +left.toFixed(2), frame.speed,
                       person.stage, notice]);
    if (person.trace.length > 4000) person.trace.shift();
    const stage = person.stage;
    if (stage === "wait") {
      // in the junction before the incident's road or on it (a takeover still on the road before is
      // held at that road's end), along it, in its own lane, with the obstacle straight ahead: past
      // the road's corner, and before SUMO's autopilot pulls out to pass it (PASS)
      const there = String(frame.lane).startsWith(":") || String(frame.lane).startsWith(`${road}_`);
      if (frame.road !== road || !there || frame.mode !== "auto" || Math.abs(headingError(frame)) > 0.2
          || Math.abs(left) > 1) return;
      const thing = (frame.vehicles || []).find((v) => crash
        ? v[3] === "truck" && ahead(frame, v) > 25 && ahead(frame, v) < 90
        : v[3] === "obstacle" && ahead(frame, v) > 10
          && Math.abs(aside(frame, v)) < 3 && Math.abs(onLane(v[0], v[1])[0]) < 1);   // straight ahead
      if (!thing) return;
      person.thing = thing;
      wheel.throttle = 0.3;
      press("MANUAL");
      person.stage = "take over";
    } else if (stage === "take over") {
      if (pressed("MANUAL")) { person.outcome.took_over = true; person.stage = "drive"; }
      else if (!person.pressing) press("MANUAL");
    } else if (stage === "drive" && !crash) {
      if (notice.includes("Collision")) {   // into the obstacle: the pass failed, and is over
        person.outcome.collision_shown = true;
        person.stage = "hand back";
        return;
      }
      // metres from the car's front to the obstacle's back, along the lane (negative: beside or past it)
      const gap = onLane(person.thing[0], person.thing[1])[2] - person.thing[6] - along;
      const out = gap < 60 && gap > -person.thing[6] - 8;   // pull out, pass, then back in
      // slow while not yet out, and stop short of it rather than touch it
      const speed = !out || left > 2 || gap < 0 ? cruise : gap < 8 ? 0 : 3;
      steerTo(frame, out ? 3.0 : 0.0, speed);
      if (gap < -person.thing[6] - 6 && Math.abs(left) < 0.6) {   // back in the own lane past it
        person.outcome.passed = true;
        person.stage = "hand back";
      }
    } else if (stage === "drive") {
      if (notice.includes("Collision")) {   // a second of shock, foot off the pedals, then the hand-back
        person.outcome.collision_shown = true;
        person.stage = "shock";
        person.until = frame.t + 1.0;
        Object.assign(wheel, { steer: 0, throttle: 0, brake: 0 });
      } else steerTo(frame, 3.2, cruise + 1);   // into the oncoming lane: the truck's path
    } else if (stage === "shock") {
      if (frame.t > person.until) person.stage = "hand back";
    } else if (stage === "hand back") {
      if (!crash) steerTo(frame, 0, cruise);
      if (pressed("AUTOPILOT")) {
        person.outcome.handed_back = true;
        person.stage = "done";
        Object.assign(wheel, { steer: 0, throttle: 0, brake: 0 });
      } else if (!person.pressing) press("AUTOPILOT");
    }
  };
  setInterval(react, 10);
};
"""
OVER = "#ready-step:visible, #done-step:visible"
PROMPT = "#prompt:visible"   # a road's report prompt, answered with a key from 1 to 7
REPORT = "5"
TRIAL_MS = 300_000      # wall milliseconds a trial may take on a loaded machine
# simulated seconds per wall second, a person's: the person, in the page, sees the obstacle once
# it is straight ahead and takes over (a round trip to the server) before SUMO's autopilot pulls
# out, also with the CPU-bound lane's workers busy on both cores (PASS)
PACE = 1.0
CRUISE = 6.0            # m/s the person drives at


def set_wheel(page, **wheel) -> None:
    values = {"steer": 0, "throttle": 0, "brake": 0, "button": False, **wheel}
    page.evaluate("(values) => Object.assign(window.wheel, values)", values)


def calibrate(page) -> None:
    """The station's calibration page, with the virtual wheel held as each step asks."""
    page.locator("#calibrate").click()
    for wheel in ({}, {"steer": -1}, {"steer": 1}, {"throttle": 1}, {"brake": 1}, {"button": True}):
        set_wheel(page, **wheel)
        page.locator("#calibrate-next").click()
    set_wheel(page)
    assert "Calibrated" in page.locator("#calibration-text").inner_text()


def drive(page, road: str, crash: bool) -> dict:
    """One trial from the ready step, driven by the person in the page: what happened, with the
    last of what they saw."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    page.evaluate("(plan) => window.startPerson(plan)", {"road": road, "crash": crash, "cruise": CRUISE})
    page.locator("#start-trust button", has_text="5").click()
    page.locator("#drive-step").wait_for(state="visible")
    deadline = time.monotonic() + TRIAL_MS / 1000
    try:
        # the person answers each road's report prompt as it shows: the trial's end waits for the
        # last road's answer (harness/live/worker.py, final_report_seconds)
        while not page.locator(OVER).first.is_visible():
            left_ms = (deadline - time.monotonic()) * 1000
            page.locator(f"{OVER}, {PROMPT}").first.wait_for(state="visible", timeout=max(left_ms, 1.0))
            if page.locator(PROMPT).is_visible():
                page.keyboard.press(REPORT)
                page.locator(PROMPT).wait_for(state="hidden", timeout=max(left_ms, 1.0))
    except PlaywrightTimeout:
        person = page.evaluate("window.person")
        raise AssertionError(("the trial did not end", person["stage"], person["trace"][-30:])) from None
    person = page.evaluate("window.person")
    trace = person["trace"]
    # where each stage began (with the lane, the mode and the metres along and left of the road):
    # when the takeover came against where SUMO's autopilot pulled out, say
    stages = [row for before, row in zip([None, *trace], trace, strict=False)
              if before is None or before[6] != row[6] or before[2] != row[2]]
    return {**person["outcome"], "trace": trace[-30:], "stages": stages}


def session(tmp_path, spec: dict, crash: bool):
    from playwright.sync_api import sync_playwright

    (tmp_path / f"{spec['name']}.toml").write_text(SPEC.format(**spec))
    config_path = tmp_path / "wheel.toml"
    config_path.write_text(CONFIG.format(spec=spec["name"], seed=spec["seed"]))
    study_dir = tmp_path / "study"
    process, address, token = start_live_server(config_path, study_dir, "--pace", str(PACE), "--no-warm-up")
    # the server's output read on (SUMO's warnings, say): a full pipe would stop the server
    output: list[str] = []
    threading.Thread(target=lambda: output.extend(process.stdout), daemon=True).start()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            try:
                link = create_participant(browser, address, token)
                page = browser.new_context(viewport={"width": 480, "height": 360}).new_page()
                page.set_default_timeout(60_000)
                page.add_init_script(VIRTUAL_WHEEL + PERSON)
                errors: list[str] = []   # the page's uncaught errors, for the assertions' messages
                page.on("pageerror", lambda error: errors.append(str(error)))
                page.goto(link)
                page.wait_for_url("**/station")
                page.locator("#agree").click()
                page.locator("#ready-step").wait_for(state="visible")
                calibrate(page)
                outcome = drive(page, spec["road"], crash)
                outcome["errors"] = errors[:5]
                outcome["server"] = output[-10:]
                outcome["done"] = page.locator("#done-step").is_visible()   # else the trial is to run again
                headers = {"Authorization": f"Bearer {token}"}
                states = httpx.get(f"http://{address}/api/participants", headers=headers).json()
                states = states["participants"]
                if (error := states[0]["last_error"]):   # why an episode failed, for the assertion's message
                    outcome["last_error"] = error
                net = httpx.get(f"http://{address}/api/net", headers=headers).json()
            finally:
                browser.close()
    finally:
        process.kill()
        process.wait()
    lane = min((lane for lane in net["lanes"]
                if lane["id"].startswith(f"{spec['road']}_") and lane["kind"] == "road"),
               key=lambda lane: lane["index"])
    return outcome, study_dir, lane["shape"]


def left_of(shape: list, x: float, y: float) -> float:
    """Metres to the left of a lane's centre line of a point (the line going on straight before its
    start, as the person's in the page)."""
    best = None
    for i, ((ax, ay), (bx, by)) in enumerate(zip(shape, shape[1:], strict=False)):
        length = math.hypot(bx - ax, by - ay) or 1.0
        t = min(1.0, ((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / length ** 2)
        t = t if i == 0 else max(0.0, t)
        distance = math.hypot(x - ax - t * (bx - ax), y - ay - t * (by - ay))
        if best is None or distance < abs(best):
            best = math.copysign(distance, (bx - ax) * (y - ay) - (by - ay) * (x - ax))
    return best


def happened(outcome: dict) -> dict:
    keys = ("took_over", "passed", "collision_shown", "handed_back", "done")
    return {key: outcome.get(key) for key in keys}


def test_a_person_passes_an_obstacle_by_wheel(tmp_path):
    outcome, study_dir, shape = session(tmp_path, PASS, crash=False)
    assert happened(outcome) == {"took_over": True, "passed": True, "collision_shown": False,
                                 "handed_back": True, "done": True}, outcome
    kinematics = read_kinematics(study_dir)
    manual = kinematics[kinematics["mode"] == "manual"]
    times = manual["time"].to_numpy()
    # one row per SUMO step while the person drives: 0.05 s, 20 Hz, one takeover
    assert len(times) > 40 and max(b - a for a, b in zip(times, times[1:], strict=False)) <= 0.05 + 1e-6
    # the lateral movement: out to the oncoming lane's centre (a lane's width to the left) and back
    left = [left_of(shape, x, y) for x, y in zip(manual["x"], manual["y"], strict=True)]
    assert abs(left[0]) < 1.5 and max(left) > 2.5 and abs(left[-1]) < 1.0, \
        (left[0], max(left), left[-1], outcome["stages"])
    # the pass through the oncoming lane, driven by hand
    oncoming = kinematics[kinematics["lane"].str.startswith("A-E_")]
    assert len(oncoming) >= 10 and set(oncoming["mode"]) == {"manual"}, kinematics["lane"].value_counts()
    part = read_part(next((study_dir / "parts").glob("*.zip")))
    events = [event["type"] for event in part.summary["live"]["driving"]]
    assert "oncoming" in events and "own_lane" in events and "collision" not in events
    # a wheel-only study: every control came from the wheel
    assert {e["source"] for e in part.summary["live"]["events"] if e["type"] == "control"} == {"wheel"}
    # the person's report after the incident's road (the one road that ends in the trial) answers
    # that road's prompt: the trial's end waited for it, not for final_report_seconds
    reports = [e for e in part.summary["live"]["events"] if e["type"] == "trust"]
    assert [(e["road"], e["answers_prompt"], e["value"]) for e in reports] == [(1, True, int(REPORT))]


def test_steering_into_the_oncoming_truck_is_a_logged_collision_and_the_episode_goes_on(tmp_path):
    outcome, study_dir, _ = session(tmp_path, CRASH, crash=True)
    assert happened(outcome) == {"took_over": True, "passed": False, "collision_shown": True,
                                 "handed_back": True, "done": True}, outcome
    part = read_part(next((study_dir / "parts").glob("*.zip")))
    collisions = [e for e in part.summary["live"]["driving"] if e["type"] == "collision"]
    assert len(collisions) == 1 and collisions[0]["object"].endswith(".truck")
    assert collisions[0]["speed"] > 1.0
    # the person handed back where the car stood, and the autopilot drove the episode to its end
    hand_back = next(e["t"] for e in part.summary["live"]["events"] if e["type"] == "hand_back")
    kinematics = read_kinematics(study_dir)
    # (the person's second of shock against the truck)
    standing = kinematics[(kinematics["time"] > collisions[0]["t"] + 0.1) & (kinematics["time"] < hand_back)]
    assert len(standing) >= 5 and standing["speed"].max() < 0.5, standing
    after = kinematics[kinematics["time"] > hand_back]
    assert len(after) > 10 and set(after["mode"]) == {"auto"} and after["speed"].max() > 3.0
