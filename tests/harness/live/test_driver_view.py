"""Screenshots of the driver's view in real Chromium with software WebGL (SwiftShader): the live
application serves the station and the net the ego drives (Town01, the default town, and the
imported Csömör, whose net declares no opposite-lane neighbours: the oncoming lane is found by its
place and direction); the
websocket is answered by the test (Playwright's route_web_socket) with frames that place the ego
on a lane of the net and, in one of them, a truck in the oncoming lane ahead. The canvas's pixels
are read back (toDataURL) and checked against the camera model (driver_view.js CAMERA): the sky
in the upper part, road surface in the lower half, and the truck where the projection puts it.

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import base64
import io
import json
import math
import threading
import time

import httpx
import numpy as np
import pytest

from tests.browser import chromium_executable
from trustroute.harness.live.protocol import Frame
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.live.session import station_texts
from trustroute.harness.simulation.incidents.oncoming import TRUCK_TYPE

from .conftest import tiny_config
from .test_browser import CHROMIUM_ARGS

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]

# the camera model of driver_view.js; the test checks the page uses these numbers
CAMERA = {"eyeBack": 1.9, "eyeLeft": 0.35, "eyeHeight": 1.2, "fov": 40, "near": 0.3, "far": 600}
SKY, ASPHALT, GRASS = (169, 207, 238), (74, 77, 80), (135, 169, 107)
EGO_AT, TRUCK_AHEAD = 25.0, 35.0   # m along the ego's lane; the truck's front this far ahead
TRUCK_HEIGHT = 3.4                 # SUMO's default height of the truck shape class
TRUCK_LENGTH = TRUCK_TYPE.length


class Server(threading.Thread):
    """The live application on uvicorn in this process (a thread), on a free port."""

    def __init__(self, study: LiveStudy) -> None:
        import uvicorn

        from benchmarks.bench_live import free_port
        from trustroute.harness.live.app import live_app

        super().__init__(daemon=True)
        self.port = free_port()
        self.server = uvicorn.Server(uvicorn.Config(live_app(study), host="127.0.0.1", port=self.port,
                                                    log_level="warning", lifespan="off"))

    def run(self) -> None:
        self.server.run()

    def stop(self) -> None:
        self.server.should_exit = True
        self.join(10)


CSOMOR_LIVE = """[study]
name = "csomor-view"
participants = 1
seed = 1
engine = "live"
town = "csomor"
specs = ["csomor5"]
conditions = ["free"]
"""


def town_config(town: str, tmp_path):
    if town == "town01":
        return tiny_config(tmp_path)
    from trustroute.harness.study.config import load_study_config

    (tmp_path / "live.toml").write_text(CSOMOR_LIVE)
    return load_study_config(tmp_path / "live.toml")


@pytest.fixture(scope="module", params=["town01", "csomor"])
def station(request, tmp_path_factory):
    """(page, net path): a participant's station page in Chromium with WebGL, its socket the test's,
    on each town."""
    from playwright.sync_api import sync_playwright

    from trustroute.app.nets import net_for

    tmp_path = tmp_path_factory.mktemp("driver-view")
    study = LiveStudy(town_config(request.param, tmp_path), tmp_path / "study", ServerOptions()).open()
    server = Server(study)
    server.start()
    address = f"http://127.0.0.1:{server.port}"
    deadline = time.monotonic() + 30
    while not server.server.started:
        assert time.monotonic() < deadline, "the live application did not start"
        time.sleep(0.05)
    created = httpx.post(f"{address}/api/participants", json={"label": "view"},
                         headers={"Authorization": f"Bearer {study.experimenter_token}"}).json()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            page = browser.new_context(viewport={"width": 1000, "height": 800}).new_page()
            sockets = []
            page.route_web_socket("**/ws", lambda ws: sockets.append(ws))   # answered by the test
            page.goto(address + created["link"])
            deadline = time.monotonic() + 30
            while not sockets:
                assert time.monotonic() < deadline, "the station opened no websocket"
                page.wait_for_timeout(50)
            yield page, sockets[0], net_for(study.context.town)
            browser.close()
    finally:
        server.stop()
        study.close()


def lane_pose(lane, offset: float) -> tuple[float, float, float]:
    """(x, y, SUMO angle) at `offset` metres along a sumolib lane."""
    import sumolib

    x, y = sumolib.geomhelper.positionAtShapeOffset(lane.getShape(), offset)
    ahead = sumolib.geomhelper.positionAtShapeOffset(lane.getShape(), offset + 1.0)
    return x, y, math.degrees(math.atan2(ahead[0] - x, ahead[1] - y)) % 360


def oncoming_lane(net, lane):
    """The lane of the road's other direction beside `lane`'s left: its declared neighbour, else the
    car lane of another edge whose centre line passes about a lane's width to the left of `lane`'s
    middle, running the other way (imported nets declare no neighbours)."""
    if lane.getNeigh() is not None:
        return net.getLane(lane.getNeigh())
    import sumolib

    middle = lane.getLength() / 2
    x, y, angle = lane_pose(lane, middle)
    heading, width = math.radians(angle), lane.getWidth()
    left = (x - math.cos(heading) * width, y + math.sin(heading) * width)
    best = None
    for other, distance in net.getNeighboringLanes(*left, r=lane.getWidth()):
        if other.getEdge() is lane.getEdge() or not other.allows("passenger"):
            continue
        offset, _ = sumolib.geomhelper.polygonOffsetAndDistanceToPoint(left, other.getShape())
        other_angle = lane_pose(other, min(offset, other.getLength() - 1.0))[2]
        if abs((other_angle - angle) % 360 - 180) < 10 and (best is None or distance < best[1]):
            best = (other, distance)
    return best[0] if best else None


def scene_on(net_path) -> tuple[dict, list]:
    """A frame of the ego on a straight lane of the net with an oncoming lane, and the truck's
    entry: its front TRUCK_AHEAD metres ahead in the oncoming lane, facing the ego."""
    import sumolib

    net = sumolib.net.readNet(str(net_path))
    for edge in sorted(net.getEdges(), key=lambda e: e.getID()):
        lanes = [lane for lane in edge.getLanes() if lane.allows("passenger")]
        if not lanes or lanes[0].getLength() < 120:
            continue
        lane = lanes[0]   # the rightmost car lane
        x, y, angle = lane_pose(lane, EGO_AT)
        far_x, far_y, far_angle = lane_pose(lane, EGO_AT + TRUCK_AHEAD + TRUCK_LENGTH)
        if abs((far_angle - angle + 180) % 360 - 180) > 1.0:
            continue   # a straight stretch, so the projection's box is the truck's
        oncoming = oncoming_lane(net, lanes[-1])
        if oncoming is None:
            continue
        # the truck's front TRUCK_AHEAD metres ahead of the ego's, along the oncoming lane
        heading = math.radians(angle)
        ahead = (x + math.sin(heading) * TRUCK_AHEAD, y + math.cos(heading) * TRUCK_AHEAD)
        along, _ = sumolib.geomhelper.polygonOffsetAndDistanceToPoint(ahead, oncoming.getShape())
        if along <= 0.0 or along + TRUCK_LENGTH >= oncoming.getLength():
            continue
        tx, ty, tangle = lane_pose(oncoming, along)
        if abs((tangle - angle) % 360 - 180) > 1.0:
            continue
        frame = {"type": "frame", "t": 10.0, "x": x, "y": y, "angle": angle, "speed": 0.0,
                 "road": edge.getID(), "lane": lane.getID(), "mode": "auto",
                 "junction": edge.getToNode().getID(), "length": 5.0, "width": 1.8, "signals": 0,
                 "route": [edge.getID()], "vehicles": [], "persons": [], "held": False}
        truck = [tx, ty, tangle, "oncoming", 0.0, 7, TRUCK_LENGTH, TRUCK_TYPE.width, TRUCK_HEIGHT, "truck", 8]
        Frame.model_validate({**frame, "vehicles": [truck]})   # the server's frame, as the protocol has it
        return frame, truck
    raise AssertionError(f"{net_path} has no straight road with an oncoming lane")


def project(frame: dict, points, width: int, height: int) -> np.ndarray:
    """Pixel (column, row) of SUMO points (x, y, height) seen by the camera model from the ego."""
    heading = math.radians(frame["angle"])
    forward = np.array([math.sin(heading), math.cos(heading)])
    left = np.array([-math.cos(heading), math.sin(heading)])
    eye = np.array([frame["x"], frame["y"]]) - CAMERA["eyeBack"] * forward + CAMERA["eyeLeft"] * left
    focal = (height / 2) / math.tan(math.radians(CAMERA["fov"]) / 2)
    out = []
    for x, y, z in points:
        relative = np.array([x, y]) - eye
        depth, aside = relative @ forward, relative @ left
        assert depth > CAMERA["near"]
        rise = z - CAMERA["eyeHeight"]
        out.append((width / 2 - focal * aside / depth, height / 2 - focal * rise / depth))
    return np.array(out)


def truck_box(truck: list) -> list:
    x, y, angle, _, _, _, length, width, height, *_ = truck
    heading = math.radians(angle)
    forward = np.array([math.sin(heading), math.cos(heading)])
    left = np.array([-math.cos(heading), math.sin(heading)])
    front = np.array([x, y])
    return [(*(front - along * length * forward + side * width / 2 * left), z)
            for along in (0, 1) for side in (-1, 1) for z in (0.3, height)]


def show(page, socket, frame: dict) -> np.ndarray:
    """The canvas's pixels (rows, columns, RGB) once the view has rendered `frame`."""
    frames = page.evaluate("window.driverView.stats.frames")
    for _ in range(3):
        socket.send(json.dumps(frame))
        page.wait_for_timeout(60)
    # the view draws only when its picture changes: once all three have arrived, it has drawn the
    # newest and found the picture at rest
    wait_until(page, f"window.driverView.stats.settled === {frames + 3}")
    pose = page.evaluate("window.driverView.stats.pose")
    assert pose == pytest.approx([frame["x"], frame["y"], frame["angle"]], abs=1e-6)
    return canvas_pixels(page, "driver")


def canvas_pixels(page, canvas: str) -> np.ndarray:
    """The pixels (rows, columns, RGB) of the page's canvas whose id is `canvas`."""
    from PIL import Image

    data = page.evaluate(f"document.getElementById('{canvas}').toDataURL('image/png')")
    image = Image.open(io.BytesIO(base64.b64decode(data.split(",", 1)[1]))).convert("RGB")
    return np.asarray(image).astype(int)


def wait_until(page, expression: str, seconds: float = 60.0) -> None:
    """Poll an expression in the page (evaluated by the driver, outside the page's CSP)."""
    deadline = time.monotonic() + seconds
    while not page.evaluate(expression):
        assert time.monotonic() < deadline, f"never true: {expression}"
        page.wait_for_timeout(50)


def near(pixels: np.ndarray, colour, tolerance: int = 14) -> np.ndarray:
    return (np.abs(pixels - np.array(colour)) <= tolerance).all(axis=-1)


def start_driving(page, socket, view: str) -> None:
    """The server's messages that put the station in a drive with `view` ("driver" or "map")."""
    socket.send(json.dumps({"type": "welcome", "participant": 0, "consent": "", "view": view}))
    socket.send(json.dumps({"type": "state", "participant": 0, "label": "view", "phase": "driving",
                            "paused_by": None, "warm_up": None, "trial": 1, "trials": 1, "episode_id": "x",
                            "next_episode": None, "mode": "auto", "road": None, "reports": 0, "takeovers": 0,
                            "done": [], "last_error": None,
                            "station": station_texts("driving", 1, 1, False)}))
    socket.send(json.dumps({"type": "episode_start", "episode_id": "x", "trust": 4}))
    if view == "driver":
        wait_until(page, "Boolean(window.driverView && window.driverView.net)")


def assert_sky_and_road(pixels: np.ndarray, frame: dict) -> None:
    """The view of `frame` (the ego on a straight lane, nothing else about) as the camera model
    draws it: sky in the upper part, road and ground in the lower half, and the ego's lane 13 m
    ahead where the camera puts it."""
    rows, columns, _ = pixels.shape
    colours, counts = np.unique(pixels.reshape(-1, 3), axis=0, return_counts=True)
    assert (counts > 0.005 * rows * columns).sum() >= 4, "the canvas is blank"   # sky, grass, road, kerb
    assert near(pixels[: rows // 5], SKY).mean() > 0.9, "no sky in the upper part"
    lower = pixels[rows // 2:]
    assert near(lower, ASPHALT).mean() > 0.15, "no road surface in the lower half"
    assert near(lower, GRASS).mean() > 0.05, "no ground beside the road"
    heading = math.radians(frame["angle"])
    ahead = (frame["x"] + 13 * math.sin(heading), frame["y"] + 13 * math.cos(heading), 0.0)
    column, row = project(frame, [ahead], columns, rows)[0]
    assert near(pixels[int(row), int(column)], ASPHALT, 20), "the lane ahead is not where the camera looks"


def test_the_driver_view_shows_sky_road_and_an_oncoming_truck_where_the_camera_says(station):
    page, socket, net_path = station
    start_driving(page, socket, "driver")
    assert page.evaluate("window.driverView.stats.camera") == CAMERA
    frame, truck = scene_on(net_path)

    empty = show(page, socket, frame)
    assert_sky_and_road(empty, frame)
    rows, columns, _ = empty.shape

    with_truck = show(page, socket, {**frame, "vehicles": [truck]})
    corners = project(frame, truck_box(truck), columns, rows)
    (c0, r0), (c1, r1) = corners.min(axis=0), corners.max(axis=0)
    assert c1 < columns / 2, "the oncoming lane is to the left"
    inner = (slice(int(r0 + 0.2 * (r1 - r0)), int(r1 - 0.2 * (r1 - r0))),
             slice(int(c0 + 0.2 * (c1 - c0)), int(c1 - 0.2 * (c1 - c0))))
    changed = (np.abs(with_truck[inner] - empty[inner]).sum(axis=-1) > 30).mean()
    assert changed > 0.9, f"the truck covers {changed:.0%} of where the camera model puts it"
    outside = np.ones(with_truck.shape[:2], bool)
    outside[int(r0) - 3: int(r1) + 4, max(int(c0) - 3, 0): int(c1) + 4] = False
    moved = (np.abs(with_truck - empty).sum(axis=-1) > 30) & outside
    assert moved.mean() < 0.002, "the truck is drawn where the camera model does not put it"


# the large map's scale (station.js MAP_SCALE, pixels per metre) and colours (map_view.js)
MAP_SCALE = 3
MAP_ROAD, MAP_GROUND = (111, 111, 111), (223, 232, 216)


def map_pixels(page, socket, frame: dict) -> np.ndarray:
    """The map canvas's pixels (rows, columns, RGB) once it has drawn `frame` with the net: the
    frame is sent until the page shows its speed (each frame here has its own) on a map drawn
    to its corner (nothing is drawn before the net has come)."""
    shown = f"{frame['speed'] * 3.6:.0f} km/h"
    drawn = "document.getElementById('view').getContext('2d').getImageData(0, 0, 1, 1).data[3] === 255"
    deadline = time.monotonic() + 60
    while not (page.evaluate("document.getElementById('speed').textContent") == shown
               and page.evaluate(drawn)):
        assert time.monotonic() < deadline, "the map never drew the frame"
        socket.send(json.dumps(frame))
        page.wait_for_timeout(100)
    return canvas_pixels(page, "view")


def on_map(pixels: np.ndarray, frame: dict, x: float, y: float) -> np.ndarray:
    """The map's pixel at net point (x, y), the frame's ego at the canvas's centre."""
    rows, columns, _ = pixels.shape
    return pixels[int(round(rows / 2 - (y - frame["y"]) * MAP_SCALE)),
                  int(round(columns / 2 + (x - frame["x"]) * MAP_SCALE))]


def far_lane(net, frame: dict, beyond: float):
    """A car lane of another road at least 80 m long whose point 20 m along is more than `beyond`
    metres from the frame's ego in x or y."""
    for edge in sorted(net.getEdges(), key=lambda e: e.getID()):
        for lane in edge.getLanes():
            if not lane.allows("passenger") or lane.getLength() < 80 or edge.getID() == frame["road"]:
                continue
            x, y, _ = lane_pose(lane, 20.0)
            if max(abs(x - frame["x"]), abs(y - frame["y"])) > beyond:
                return lane
    raise AssertionError(f"no car lane more than {beyond} m from the ego")


def test_the_map_shows_the_lanes_under_the_ego_wherever_it_drives(station):
    """The large map ("map" view) draws the net's lanes from a layer a few times its size around
    the ego, drawn once and copied at every frame: a lane is road-coloured where the ego drives,
    there and again after a jump past the layer's reach (the layer drawn anew), and ground away
    from any road."""
    import sumolib

    page, socket, net_path = station
    start_driving(page, socket, "map")
    net = sumolib.net.readNet(str(net_path))
    frame, _ = scene_on(net_path)
    width, height = 640, 480   # the map canvas (station.js setView)
    far = far_lane(net, frame, max(width, height) / MAP_SCALE)
    x, y, angle = lane_pose(far, 20.0)
    jumped = {**frame, "x": x, "y": y, "angle": angle, "road": far.getEdge().getID(), "lane": far.getID(),
              "junction": far.getEdge().getToNode().getID(), "route": [], "speed": 10.0}
    for shown, along in (({**frame, "route": [], "speed": 5.0}, EGO_AT), (jumped, 20.0)):
        pixels = map_pixels(page, socket, shown)
        assert pixels.shape[:2] == (height, width)
        ahead = lane_pose(net.getLane(shown["lane"]), along + 12.0)   # 12 m ahead of the ego
        assert near(on_map(pixels, shown, ahead[0], ahead[1]), MAP_ROAD, 20), (shown["lane"], "no road ahead")
        steps = range(-60, 61, 12)
        away = next(((shown["x"] + dx, shown["y"] + dy) for dx in steps for dy in steps
                     if not net.getNeighboringLanes(shown["x"] + dx, shown["y"] + dy, r=12)), None)
        assert away is not None, "no point of the map 12 m from every lane"
        assert near(on_map(pixels, shown, *away), MAP_GROUND, 6), "no ground off the road"
