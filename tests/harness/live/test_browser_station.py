"""What a participant sees at the station, in real Chromium: the live application serves the page
and the net, and the websocket is answered by the test (Playwright's route_web_socket) with the
server's messages, so each case puts the page in the state it checks without running SUMO. (The
experimenter's console: test_browser_console.py.)

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import contextlib
import json
import time

import httpx
import pytest

from tests.browser import chromium_executable
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.live.session import station_end, station_texts

from .conftest import tiny_config
from .test_browser import CHROMIUM_ARGS
from .test_driver_view import (
    Server,
    assert_sky_and_road,
    canvas_pixels,
    scene_on,
    show,
    start_driving,
    wait_until,
)

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


class Station:
    """The served study and a browser: `open` gives a new participant's station page."""

    def __init__(self, browser, address: str, study: LiveStudy, net_path) -> None:
        self.browser, self.address, self.study, self.net_path = browser, address, study, net_path

    @contextlib.contextmanager
    def open(self, width: int = 1280, height: int = 800, phone: bool = False):
        """(page, socket): a new participant's station at width x height (as a phone's browser lays
        pages out: `phone`), its socket the test's."""
        created = httpx.post(f"{self.address}/api/participants", json={},
                             headers={"Authorization": f"Bearer {self.study.experimenter_token}"}).json()
        context = self.browser.new_context(viewport={"width": width, "height": height}, is_mobile=phone,
                                           has_touch=phone, device_scale_factor=2 if phone else 1)
        page = context.new_page()
        sockets: list = []
        page.route_web_socket("**/ws", lambda ws: sockets.append(ws))
        page.goto(self.address + created["link"])
        deadline = time.monotonic() + 30
        while not sockets:
            assert time.monotonic() < deadline, "the station opened no websocket"
            page.wait_for_timeout(50)
        try:
            yield page, sockets[0]
        finally:
            context.close()


@contextlib.contextmanager
def served_station(tmp_path):
    """A `Station`: a study of 32 participants in tmp_path, served, and Chromium."""
    from playwright.sync_api import sync_playwright

    from trustroute.app.nets import net_for

    study = LiveStudy(tiny_config(tmp_path, participants=32), tmp_path / "study", ServerOptions()).open()
    server = Server(study)
    server.start()
    deadline = time.monotonic() + 30
    while not server.server.started:
        assert time.monotonic() < deadline, "the live application did not start"
        time.sleep(0.05)
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            yield Station(browser, f"http://127.0.0.1:{server.port}", study, net_for(study.context.town))
            browser.close()
    finally:
        server.stop()
        study.close()


def station_fixture(folder: str):
    """A test module's `station` fixture: a `served_station` of its own, in a folder `folder`."""
    @pytest.fixture(scope="module", name="station")
    def served(tmp_path_factory):
        with served_station(tmp_path_factory.mktemp(folder)) as station:
            yield station
    return served


station = station_fixture("station")


def box(page, selector: str) -> dict:
    return page.locator(selector).bounding_box()


@pytest.mark.parametrize(("width", "height"), [(1280, 800), (1024, 640)])
def test_the_prompt_and_the_trust_buttons_fit_the_window_beside_the_view(station, width, height, tmp_path):
    frame, _ = scene_on(station.net_path)
    with station.open(width, height) as (page, socket):
        start_driving(page, socket, "driver")
        socket.send(json.dumps(frame))
        socket.send(json.dumps({"type": "road", "index": 1, "incident": None, "takeover": False,
                                "performance": None, "t": 10.0, "prompt": {"episode_id": "x", "road": 1}}))
        page.locator("#prompt").wait_for(state="visible")
        wait_until(page, "document.getElementById('speed').textContent.includes('km/h')")
        page.screenshot(path=str(tmp_path / f"prompt-{width}x{height}.png"))
        for selector in ("#prompt", "#toggle", "#trust button >> nth=6", "#brake"):
            shown = box(page, selector)
            assert shown["y"] >= 0 and shown["y"] + shown["height"] <= height, (selector, shown)
        assert page.evaluate("document.documentElement.scrollHeight") <= height   # nothing to scroll to
        assert box(page, "#scene")["width"] >= 0.6 * min(width, 960)   # the view is not shrunk away


def overlaps(one: dict, other: dict) -> bool:
    return (one["x"] < other["x"] + other["width"] and other["x"] < one["x"] + one["width"]
            and one["y"] < other["y"] + other["height"] and other["y"] < one["y"] + one["height"])


# the longest notices over the view: the hand-back due, and the wheel's hold and guidance
NOTICES = [{"type": "warning", "kind": "hand_back", "distance": 90.0, "t": 10.0},
           {"type": "warning", "kind": "guide_back", "t": 10.0},
           {"type": "warning", "kind": "stopped_off_road", "t": 10.0}]


# the longest notice the page makes itself (station.js readInputs): a device ask, with the
# hand-back due beside it, as inputs.js and station.js word them
LONGEST_NOTICE = ("No device connected gives the steering or the accelerator or the brake: connect the "
                  "device that does, then click Calibrate the wheel if it is not read. Hand back before the "
                  "junction (space): the vehicle waits for you.")
SET_NOTICE = "(text) => { document.getElementById('incident').textContent = text; }"


@pytest.mark.parametrize(("width", "height", "phone"),
                         [(1280, 720, False), (1024, 600, False), (640, 480, False), (400, 800, True)])
def test_a_notice_over_the_view_is_whole_and_clear_of_the_mini_map(station, width, height, phone, tmp_path):
    """Each long notice over the view, and the longest the page makes, within the view left of the
    mini-map and above the dashboard, its text within its box, down to a 640 x 480 window."""
    frame, _ = scene_on(station.net_path)
    with station.open(width, height, phone) as (page, socket):
        start_driving(page, socket, "driver")
        socket.send(json.dumps(frame))
        wait_until(page, "document.getElementById('speed').textContent.includes('km/h')")
        for notice in [*NOTICES, {"kind": "longest"}]:
            if notice["kind"] == "longest":
                page.evaluate(SET_NOTICE, LONGEST_NOTICE)
            else:
                socket.send(json.dumps(notice))
            wait_until(page, "document.getElementById('incident').textContent.length > 0")
            page.wait_for_timeout(100)
            page.screenshot(path=str(tmp_path / f"notice-{width}-{notice['kind']}.png"))
            shown, scene, mini = box(page, "#incident"), box(page, "#scene"), box(page, "#view")
            text = page.locator("#incident").inner_text()
            assert not overlaps(shown, mini), (notice["kind"], text, shown, mini)
            assert not overlaps(shown, box(page, "#dash")), (notice["kind"], text, shown)
            right = scene["x"] + scene["width"] + 1
            assert scene["x"] <= shown["x"] and shown["x"] + shown["width"] <= right, notice["kind"]
            # its text within its box: none of it runs out of it, under the mini-map or off the window
            fits = "(e => e.scrollWidth <= e.clientWidth)(document.getElementById('incident'))"
            assert page.evaluate(fits), (notice["kind"], text)


# A road's lane that bends: 100 m east, then 100 m north (its end is the junction).
BEND = [[0, 0], [100, 0], [100, 100]]
REMAINING = """async ([shape, points]) => {
  const { remaining } = await import("/static/next_turn.js");
  return points.map(([x, y]) => remaining(shape, x, y));
}"""
NEXT_TURN = """async ([frame, edges]) => (await import("/static/next_turn.js")).nextTurn(frame, edges)"""


def test_the_distance_to_the_junction_falls_steadily_along_the_road(station):
    """Measured from the car's projection on the lane, along the lane: driving on, the distance
    only falls (it grew, then jumped, measured from the nearest vertex of the lane's shape)."""
    along = [(x, 1.5) for x in range(0, 100, 5)] + [(98.5, y) for y in range(0, 101, 5)]
    with station.open() as (page, _):
        distances = page.evaluate(REMAINING, [BEND, along])
        expected = [200 - x for x, _ in along[:20]] + [100 - y for _, y in along[20:]]
        assert distances == pytest.approx(expected, abs=1.6)
        assert all(later <= earlier for earlier, later in zip(distances, distances[1:], strict=False))
        edges = {"a": BEND, "b": [[100, 100], [0, 100]]}   # at the end of the bend: a left turn
        frame = {"x": 40.0, "y": 1.0, "road": "a", "route": ["a", "b"]}
        assert page.evaluate(NEXT_TURN, [frame, edges]) == {"turn": "left", "text": "Turn left in 160 m"}
        assert page.evaluate(NEXT_TURN, [{**frame, "route": ["a"]}, edges])["text"] == "Junction in 160 m"
        inside = {**frame, "road": ":j_0"}   # in the junction, the turn under way: nothing to say
        assert page.evaluate(NEXT_TURN, [inside, edges]) == {"turn": None, "text": ""}


def test_the_driving_hint_goes_once_the_frames_are_on_autopilot(station):
    """After a hand-back, a frame still marked manual (sent before the switch) may set the hint
    again: the first frame on autopilot takes it away."""
    frame, _ = scene_on(station.net_path)
    u, v = frame["road"].split("-")
    oncoming = {**frame, "mode": "manual", "lane": f"{v}-{u}_0"}
    with station.open() as (page, socket):
        start_driving(page, socket, "driver")
        socket.send(json.dumps({"type": "mode", "mode": "manual", "t": 10.0}))
        socket.send(json.dumps(oncoming))
        hint = page.locator("#hint")
        wait_until(page, "document.getElementById('hint').textContent.includes('oncoming lane')")
        socket.send(json.dumps({"type": "mode", "mode": "auto", "t": 10.2}))
        socket.send(json.dumps({**oncoming, "t": 10.2}))   # the last frame before the switch
        socket.send(json.dumps({**frame, "t": 10.4}))
        wait_until(page, "document.getElementById('mode').textContent === 'AUTOPILOT'")
        wait_until(page, "!document.getElementById('road').textContent")   # the autopilot's frame is shown
        assert hint.inner_text() == ""


def test_you_reported_is_said_on_the_servers_acknowledgement_and_not_into_the_next_drive(station):
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        received: list[dict] = []
        socket.on_message(lambda text: received.append(json.loads(text)))
        start_driving(page, socket, "driver")
        socket.send(json.dumps(frame))
        wait_until(page, "document.getElementById('speed').textContent.includes('km/h')")
        page.keyboard.press("5")
        deadline = time.monotonic() + 10
        while not any(m["type"] == "trust" for m in received):
            assert time.monotonic() < deadline, received
            page.wait_for_timeout(50)
        assert page.locator("#reported").inner_text() == ""   # sent, not yet accepted (it may be refused)
        socket.send(json.dumps({"type": "reported", "value": 5, "prompt": None}))
        wait_until(page, "document.getElementById('reported').textContent === 'You reported 5.'")
        # this drive's own episode_start (it comes once its SUMO runs) keeps a report made meanwhile
        socket.send(json.dumps({"type": "episode_start", "episode_id": "x", "trust": 4}))
        socket.send(json.dumps({**frame, "speed": 5.0}))
        wait_until(page, "document.getElementById('speed').textContent === '18 km/h'")
        assert page.locator("#reported").inner_text() == "You reported 5."
        socket.send(json.dumps({"type": "episode_start", "episode_id": "y", "trust": 4}))   # the next drive
        wait_until(page, "document.getElementById('reported').textContent === ''")


def test_a_withdrawn_participant_is_told_so_and_has_nothing_left_to_press(station, tmp_path):
    with station.open() as (page, socket):
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        socket.send(state_message("ready", trial=0, episode_id=None, next_episode="x"))
        page.locator("#ready-step").wait_for(state="visible")
        # the server's withdrawal (harness/live/app.py revoke_stale): told, then closed with 1008
        socket.send(json.dumps({"type": "revoked", "detail": "withdrawn from the study"}))
        socket.close(code=1008, reason="withdrawn")
        error = page.locator("#error")
        error.filter(has_text="You have withdrawn from the study").wait_for()
        assert "your data has been deleted" in error.inner_text() and "revoked" not in error.inner_text()
        assert page.locator("#ready-step").is_hidden()
        assert page.locator("button:enabled").count() == 0
        page.screenshot(path=str(tmp_path / "withdrawn.png"))
    # opened again without the session's cookie (withdrawn, or a browser that never had it): a page
    # that says what to do, not the API's JSON
    page = station.browser.new_page()
    response = page.goto(f"{station.address}/station")
    assert response.status == 403
    assert "link the experimenter gave you" in page.locator("#message").inner_text()
    assert "{" not in page.locator("body").inner_text()
    page.screenshot(path=str(tmp_path / "no-cookie.png"))
    page.close()


EGO_GREEN = (46, 125, 50)   # map_view.js: the ego on autopilot


def ego_pixels(page) -> int:
    """How many pixels of the mini-map's canvas are the ego's colour."""
    import numpy as np

    pixels = canvas_pixels(page, "view")
    return int((np.abs(pixels - np.array(EGO_GREEN)) <= 12).all(axis=-1).sum())


@pytest.mark.parametrize(("width", "height", "phone"), [(1280, 800, False), (400, 800, True)])
def test_the_own_car_is_seen_on_the_mini_map_and_a_phone_shows_the_station_whole(
        station, width, height, phone, tmp_path):
    frame, _ = scene_on(station.net_path)
    with station.open(width, height, phone) as (page, socket):
        start_driving(page, socket, "driver")
        socket.send(json.dumps({**frame, "speed": 13.9}))
        socket.send(json.dumps({"type": "road", "index": 1, "incident": None, "takeover": False,
                                "performance": None, "t": 10.0, "prompt": {"episode_id": "x", "road": 1}}))
        wait_until(page, "document.getElementById('speed').textContent === '50 km/h'")
        wait_until(page, "document.getElementById('view').getContext('2d').getImageData(0, 0, 1, 1).data[3]")
        page.screenshot(path=str(tmp_path / f"station-{width}.png"))
        ratio = page.evaluate("window.devicePixelRatio")
        # the car 16 x 8 CSS pixels, its white outline and heading aside (at the mini-map's scale it
        # was 2 or 3 pixels)
        assert ego_pixels(page) >= 50 * ratio**2
        assert page.evaluate("window.innerWidth") == width   # laid out for the window, not a desktop's
        assert page.evaluate("document.documentElement.scrollWidth") <= width   # nothing sticks out
        scene, mini = box(page, "#scene"), box(page, "#view")
        assert mini["width"] <= 0.3 * scene["width"] + 1
        for selector in ("#mode", "#speed", "#turn-text", "#prompt"):
            shown = box(page, selector)
            right = scene["x"] + scene["width"] + 1
            assert scene["x"] <= shown["x"] and shown["x"] + shown["width"] <= right, selector


@pytest.mark.parametrize(("width", "phone"), [(400, True), (400, False), (420, False), (510, False)])
def test_the_driver_view_draws_the_road_in_a_narrow_window(station, width, phone, tmp_path):
    """The ground and the road lie centimetres apart; drawn by depth, software WebGL gave the
    ground's large triangles depths nearer than the road's at some canvas sizes (a 400 or 510 px
    window's among them) and the view showed grass where the road is. Drawn in the order of their
    levels, the road shows at every width."""
    frame, _ = scene_on(station.net_path)
    with station.open(width, 800, phone) as (page, socket):
        start_driving(page, socket, "driver")
        pixels = show(page, socket, frame)
        page.screenshot(path=str(tmp_path / f"narrow-{width}-{phone}.png"))
        shown = box(page, "#driver")   # drawn at its displayed size (one pixel per CSS pixel)
        assert pixels.shape[:2] == (round(shown["height"]), round(shown["width"]))
        assert_sky_and_road(pixels, frame)


def state_message(phase: str, **changes) -> str:
    """The server's `state` message for participant 0 of one trial, in `phase` (its texts for the
    station by the server's rule, `station_texts`, unless `changes` give them)."""
    message = {"type": "state", "participant": 0, "label": "", "phase": phase, "paused_by": None,
               "warm_up": None, "trial": 1, "trials": 1, "episode_id": "x", "next_episode": None,
               "mode": "auto", "road": None, "reports": 0, "takeovers": 0, "done": [], "last_error": None,
               "questionnaire": None, **changes}
    texts = station_texts(phase, message["trial"], message["trials"], message["warm_up"] == "pending")
    return json.dumps({"station": texts, **message})


GOAL = {"type": "episode_end", "satisfied": True, "end_reason": "goal", "junctions": 3, "takeovers": 0}


def end_message(end: dict, trial: int = 1, trials: int = 1, warm_up: bool = False, **changes) -> str:
    """The server's message of the end of a drive (`end`, the episode's message, for episode "x"),
    with what the station says of it by the server's rule, `station_end`, unless `changes` give it."""
    message = {"episode_id": "x", **end, **changes}
    return json.dumps({"station": station_end(message, trial, trials, warm_up), **message})


DRIVING = ("toggle", "accelerate", "brake", "pull-out", "pull-in")


def enabled(page) -> set[str]:
    return {control for control in DRIVING if page.locator(f"#{control}").is_enabled()}


def test_the_driving_controls_work_only_while_the_drive_runs(station):
    """Before the vehicle is ready, while the drive is paused, and (accelerating) while the vehicle
    stops for the hand-back, the buttons are disabled and their keys send nothing; the trust
    buttons work while the drive runs, not while it is paused or over."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        received: list[dict] = []
        socket.on_message(lambda text: received.append(json.loads(text)))

        def sent(kind: str) -> list[dict]:
            page.wait_for_timeout(300)   # what a key would send has arrived by then
            return [message for message in received if message["type"] == kind]

        start_driving(page, socket, "driver")   # the vehicle getting ready: no frame yet
        page.locator("#overlay-text").filter(has_text="getting ready").wait_for()
        assert enabled(page) == set()
        page.keyboard.press("Space")
        assert sent("takeover") == []
        socket.send(json.dumps(frame))
        wait_until(page, "!document.getElementById('toggle').disabled")
        assert enabled(page) == {"toggle"}
        socket.send(json.dumps({"type": "mode", "mode": "manual", "t": 10.0}))
        wait_until(page, "document.getElementById('mode').textContent === 'MANUAL'")
        assert enabled(page) == set(DRIVING)
        assert page.locator("#trust button:enabled").count() == 7
        page.keyboard.down("ArrowUp")   # accelerating when the hand-back falls due: let go at once
        socket.send(json.dumps({"type": "warning", "kind": "hand_back", "distance": 100.0, "t": 11.0}))
        wait_until(page, "document.getElementById('accelerate').disabled")
        assert enabled(page) == set(DRIVING) - {"accelerate"}
        assert [message["pedal"] for message in sent("drive")] == ["accelerate", "release"]
        page.keyboard.up("ArrowUp")
        page.keyboard.press("ArrowUp")
        assert [message["pedal"] for message in sent("drive")] == ["accelerate", "release"]
        socket.send(state_message("paused", paused_by="experimenter", mode="manual"))
        page.locator("#overlay-text").filter(has_text="Paused by the experimenter").wait_for()
        assert enabled(page) == set() and page.locator("#trust button:enabled").count() == 0
        for key in ("Space", "ArrowDown", "ArrowLeft"):
            page.keyboard.press(key)
        assert sent("hand_back") == [] and sent("steer") == [] and len(sent("drive")) == 2
        socket.send(state_message("driving", mode="manual"))
        wait_until(page, "!document.getElementById('toggle').disabled")
        assert enabled(page) == set(DRIVING) - {"accelerate"}
        page.keyboard.press("Space")
        assert len(sent("hand_back")) == 1
        socket.send(json.dumps({"type": "mode", "mode": "auto", "t": 12.0}))
        socket.send(end_message({**GOAL, "takeovers": 1}))
        wait_until(page, "document.getElementById('toggle').disabled")   # the drive is over
        assert enabled(page) == set() and page.locator("#trust button:enabled").count() == 0
        page.keyboard.press("Space")
        assert sent("takeover") == []


# A gamepad in the browser's standard mapping (the left stick steers, the right trigger is the
# accelerator, A takes over and hands back), set from the test through window.pad.
PARAGRAPHS = ["You are about to drive in a simulated study.", "You may take over at any time.",
              "You may stop at any time: your data is then deleted."]
CONSENT = f"{PARAGRAPHS[0]}\n\n{PARAGRAPHS[1]}\n \n{PARAGRAPHS[2]}\n"   # a blank line may hold spaces


def test_the_consent_is_shown_in_paragraphs_and_can_be_declined(station, tmp_path):
    """Each block of the consent text (blank lines between them) is a paragraph set apart from the
    next; *I do not agree* sends the refusal, and the server's closing ("declined") leaves a page
    saying that nothing was recorded and nothing to press."""
    with station.open(800, 800) as (page, socket):
        received: list[dict] = []
        socket.on_message(lambda text: received.append(json.loads(text)))
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": CONSENT, "view": "driver"}))
        socket.send(state_message("consent", trial=0, episode_id=None, warm_up="pending"))
        page.locator("#consent-step").wait_for(state="visible")
        assert page.locator("#status").inner_text() == ""   # no drive is named before the consent
        paragraphs = page.locator("#consent-text p")
        assert paragraphs.all_inner_texts() == PARAGRAPHS
        shown = [paragraphs.nth(i).bounding_box() for i in range(3)]
        for above, below in zip(shown, shown[1:], strict=False):
            assert below["y"] - (above["y"] + above["height"]) >= 10   # px between paragraphs
        page.screenshot(path=str(tmp_path / "consent.png"))
        page.locator("#decline").click()
        deadline = time.monotonic() + 10
        while not any(message["type"] == "consent" and message["agree"] is False for message in received):
            assert time.monotonic() < deadline, received
            page.wait_for_timeout(50)
        socket.close(code=1008, reason="declined")   # the server's answer (test_live_sessions.py)
        page.locator("#declined-step").wait_for(state="visible")
        text = page.locator("#declined-step").inner_text()
        assert "No data was recorded" in text and "close this window" in text
        assert page.locator("#consent-step").is_hidden() and page.locator("#error").inner_text() == ""
        assert page.locator("button:enabled").count() == 0
        page.screenshot(path=str(tmp_path / "declined.png"))


def test_a_completed_trial_and_the_end_of_the_study_are_said(station, tmp_path):
    """After a drive the page says it is complete (with the next one's start below), until the
    next drive starts; after the last, a page says the study is complete and may be closed."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        for trial, episode in ((1, "x"), (2, "y")):
            socket.send(state_message("driving", trial=trial, trials=2, episode_id=episode,
                                      done=["x"] if trial == 2 else []))
            socket.send(json.dumps({"type": "episode_start", "episode_id": episode, "trust": 4}))
            socket.send(json.dumps(frame))
            wait_until(page, "document.getElementById('speed').textContent.includes('km/h')")
            assert page.locator("#completed").is_hidden()
            socket.send(end_message(GOAL, trial=trial, trials=2, episode_id=episode))
            if trial == 1:
                socket.send(state_message("ready", trial=1, trials=2, episode_id=None, done=["x"]))
                page.locator("#ready-step").wait_for(state="visible")
                assert page.locator("#completed").inner_text() == "Trial 1 of 2 is complete."
                assert page.locator("#trial-text").inner_text() == "Next: trial 2 of 2."
                page.screenshot(path=str(tmp_path / "trial-complete.png"))
        socket.send(state_message("done", trial=2, trials=2, episode_id=None, done=["x", "y"]))
        page.locator("#done-step").wait_for(state="visible")
        text = page.locator("#done-step").inner_text()
        assert "The study is complete" in text and "close this window" in text
        assert page.locator("#drive-step").is_hidden() and page.locator("#completed").is_hidden()
        page.screenshot(path=str(tmp_path / "done.png"))


def test_a_page_reopened_mid_drive_shows_the_mode_the_person_is_in_and_can_hand_back(station):
    """A station reloaded (or reopened) while its person is in control: the server's state says
    `manual` (the page's `mode` events of the takeover went to the window that was closed), so the
    page shows MANUAL and its button hands back; showing AUTOPILOT, it sent a takeover the server
    refuses, and the car held for the hand-back stood there for good."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        received: list[dict] = []
        socket.on_message(lambda text: received.append(json.loads(text)))
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        # the reconnection finds the episode paused by the lost connection, then the person resumes
        socket.send(state_message("paused", paused_by="disconnect", mode="manual"))
        page.locator("#overlay-text").filter(has_text="connection was lost").wait_for()
        assert page.locator("#mode").inner_text() == "MANUAL"
        socket.send(state_message("driving", mode="manual"))
        socket.send(json.dumps({**frame, "mode": "manual"}))
        wait_until(page, "!document.getElementById('toggle').disabled")
        assert page.locator("#mode").inner_text() == "MANUAL"
        assert page.locator("#toggle").inner_text() == "Hand back (space)"
        assert enabled(page) == set(DRIVING)
        page.keyboard.press("Space")
        deadline = time.monotonic() + 10
        while not any(m["type"] in ("hand_back", "takeover") for m in received):
            assert time.monotonic() < deadline, received
            page.wait_for_timeout(50)
        assert [m["type"] for m in received if m["type"] in ("hand_back", "takeover")] == ["hand_back"]


def test_a_station_opened_during_a_disconnect_pause_shows_where_the_car_stands(station, tmp_path):
    """Opened again while the lost connection holds the drive paused, the station gets the state
    and then the drive's last frame (the server's `Session.opening`: no frame streams while
    paused) and draws it, in the view and on the mini-map, before the person resumes: the view was
    an empty grey until then, and the map empty."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        received: list[dict] = []
        socket.on_message(lambda text: received.append(json.loads(text)))
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        socket.send(state_message("paused", paused_by="disconnect"))
        socket.send(json.dumps(frame))
        page.locator("#overlay-text").filter(has_text="connection was lost").wait_for()
        wait_until(page, "Boolean(window.driverView && window.driverView.stats.pose)", seconds=15)
        assert page.evaluate("window.driverView.stats.pose") == pytest.approx(
            [frame["x"], frame["y"], frame["angle"]], abs=1e-6)
        page.screenshot(path=str(tmp_path / "reopened-paused.png"))
        assert_sky_and_road(canvas_pixels(page, "driver"), frame)
        assert ego_pixels(page) > 0   # the mini-map shows the car too
        assert page.locator("#resume").is_visible()
        assert not [m for m in received if m["type"] == "resume"]   # drawn with no resume sent
        # the resume goes on from the frame shown: the drive is not started anew ("getting ready")
        socket.send(state_message("driving"))
        wait_until(page, "document.getElementById('overlay').classList.contains('hidden')")
        assert page.evaluate("window.driverView.frames.length") == 1


def test_the_station_says_the_trial_in_the_servers_words(station):
    """The status line, the start step's sentence and the drive's completion are the state's
    `station` texts as sent (harness/live/session.py `station_texts`), not counted again by the
    page from `done` and `trial`: here they name another trial than those fields would."""
    frame, _ = scene_on(station.net_path)
    ready = {"status": "Trial 7 of 9 is next", "next": "Next: trial 7 of 9."}
    driving = {"status": "Trial 7 of 9", "next": None}
    complete = "Trial 7 of 9 is complete."
    with station.open() as (page, socket):
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        socket.send(state_message("ready", trial=0, trials=2, episode_id=None, station=ready))
        page.locator("#ready-step").wait_for(state="visible")
        assert page.locator("#status").inner_text() == ready["status"]
        assert page.locator("#trial-text").inner_text() == ready["next"]
        socket.send(state_message("driving", trial=1, trials=2, station=driving))
        socket.send(json.dumps({"type": "episode_start", "episode_id": "x", "trust": 4}))
        socket.send(json.dumps(frame))
        page.locator("#status").filter(has_text=driving["status"]).wait_for()
        socket.send(end_message(GOAL, trial=1, trials=2, station=complete))
        socket.send(state_message("ready", trial=1, trials=2, episode_id=None, done=["x"], station=ready))
        page.locator("#completed").filter(has_text=complete).wait_for()


# How a drive may end other than complete (the episode's last message, as harness/live/worker.py,
# Session.control and Session.expire have it): stopped by the experimenter, incomplete, failed.
STOPPED = [{"type": "episode_aborted", "reason": "aborted by the experimenter"},
           {"type": "episode_aborted", "reason": "incomplete: no reconnection within 120 s"},
           {"type": "episode_failed", "error": "RuntimeError: SUMO stopped"}]


@pytest.mark.parametrize("end", STOPPED, ids=["aborted", "incomplete", "failed"])
def test_a_stopped_warm_up_or_trial_is_said_in_the_servers_words(station, tmp_path, end):
    """A drive that ends without completing is said in the server's words for that drive and that
    end (its end's `station`, harness/live/session.py `station_end`), over the view that stands still
    and, as a notice, above the start of the drive run again: the warm-up's end speaks of the
    warm-up, a trial's of that trial, never of "this trial" for the warm-up."""
    frame, _ = scene_on(station.net_path)
    with station.open() as (page, socket):
        socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": "driver"}))
        for warm_up, trial, name in ((True, 0, "warm-up"), (False, 2, "trial-2")):
            pending = "pending" if warm_up else "done"
            said = json.loads(end_message(end, trial=trial, trials=4, warm_up=warm_up))["station"]
            assert ("The warm-up drive" if warm_up else "Trial 2 of 4") in said
            socket.send(state_message("driving", warm_up=pending, trial=trial, trials=4))
            socket.send(json.dumps({"type": "episode_start", "episode_id": "x", "trust": 4}))
            socket.send(json.dumps(frame))
            wait_until(page, "document.getElementById('speed').textContent.includes('km/h')")
            socket.send(end_message(end, trial=trial, trials=4, warm_up=warm_up))
            page.locator("#overlay-text").filter(has_text=said).wait_for()
            assert page.locator("#overlay-text").inner_text() == said
            assert ("trial" in said.lower()) is not warm_up
            page.screenshot(path=str(tmp_path / f"{name}-{end['type']}-view.png"))
            socket.send(state_message("ready", warm_up=pending, trial=trial - (not warm_up), trials=4,
                                      episode_id=None))
            page.locator("#ready-step").wait_for(state="visible")
            assert page.locator("#completed").inner_text() == said
            assert "stopped" in page.locator("#completed").get_attribute("class")
            assert page.locator("#error").inner_text() == ""
            page.screenshot(path=str(tmp_path / f"{name}-{end['type']}.png"))
