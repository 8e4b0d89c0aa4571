"""The driver's view in a browser: how fast it draws and how much the stream costs.

Starts `trustroute live` at pace 1 (wall-clock time) with one participant whose station is
Debian's Chromium, headless, with software WebGL (SwiftShader: no GPU is used), and drives the
trial on autopilot. Measured over WINDOW wall seconds once the first frame has arrived:
- the rate at which the page draws the driver's view (requestAnimationFrame callbacks that
  rendered, from `window.driverView.stats.renders`: at most one per frame received while the
  frames stream, driver_view.js), against the display rate Chromium gives a headless page (rAF
  callbacks counted by a probe script in the same window);
- the frames received per second (`stats.frames`) and the websocket's bytes per second to the
  participant (every server message, counted by a Playwright websocket listener);
- the server's CPU time per wall second (the server and its episode process, from /proc).
With `[live] driving = "continuous"` and a virtual wheel (a script replacing
`navigator.getGamepads`, read in the standard mapping), on a trial of WHEEL_SPEC (a 53 m start road,
then Town01's H-L, whose 320 m straight after its corner is long enough to drive the whole
measurement by hand before its junction): 20 m into that straight, the page takes over, holds
about CRUISE m/s with the accelerator and the benchmark measures the latency from turning the wheel
to the first drawn frame whose ego heading has turned (by more than 0.2°), in the page with
performance.now() (LATENCY_SAMPLES pulses of PULSE_STEER, each undone, the rest between them
steering back to the straight's heading: without it the car drifts off the road, where it is
stopped), and, over the same wall seconds, the server's CPU time per wall second (server and
episode process) and the websocket's bytes per second to the participant while the person drives.
The load average before and after each part is reported: the machine may be shared.
"""

from __future__ import annotations

import math
import os
import statistics
import tempfile
import time
from pathlib import Path

import httpx

from benchmarks.bench_live import start_live_server

CONFIG = """[study]
name = "bench-driver-view"
participants = 1
seed = 1
engine = "live"
specs = ["phi1"]
conditions = ["free"]
"""
WINDOW = 20.0   # wall seconds measured
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--ignore-gpu-blocklist", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
COUNTS = "[window.driverView.stats.renders, window.driverView.stats.frames, window.rafProbe]"
LATENCY_SAMPLES = 20
CRUISE = 8.0    # m/s the page holds while the wheel is measured
PULSE_STEER = 0.15   # the wheel's turn in a pulse (of full lock): a clear turn that stays in the lane
# one trial: a short start road (no takeover there), then H-L, an oncoming truck's road of 444 m
WHEEL_SPEC = 'name = "benchwheel"\nstart = "I-H"\nformula = "F v1"\n\n[states]\nv1 = ["H-L"]\n'
WHEEL = """
window.wheel = { steer: 0, throttle: 0, brake: 0, button: false };
// the person's foot: about CRUISE m/s on the accelerator, from the newest frame's speed
window.cruise = (speed) => setInterval(() => {
  const frames = window.driverView ? window.driverView.frames : [];
  if (!frames.length) return;
  const now = frames[frames.length - 1].frame.speed;
  window.wheel.throttle = now < speed ? 0.4 : 0;
  window.wheel.brake = now > speed + 1 ? 0.3 : 0;
}, 50);
navigator.getGamepads = () => [{ id: "virtual", index: 0, connected: true, mapping: "standard",
  timestamp: performance.now(), axes: [window.wheel.steer, 0, 0, 0],
  buttons: Array.from({ length: 17 }, (_, i) => {
    const value = i === 7 ? window.wheel.throttle : i === 6 ? window.wheel.brake
      : i === 0 && window.wheel.button ? 1 : 0;
    return { pressed: value > 0.5, touched: value > 0, value };
  }) }];
"""
# one pulse: the wheel turned at t0; the first animation frame whose drawn heading differs from
# the heading at t0 ends it; the wheel is turned back as long to undo the turn
PULSE = """async ([steer, reference]) => {
  const view = window.driverView;
  const start = view.stats.pose[2];
  const t0 = performance.now();
  window.wheel.steer = steer;
  const latency = await new Promise((resolve) => {
    const check = () => {
      const turned = Math.abs(((view.stats.pose[2] - start + 540) % 360) - 180);
      if (turned > 0.2) resolve(performance.now() - t0);
      else if (performance.now() - t0 > 3000) resolve(null);
      else requestAnimationFrame(check);
    };
    requestAnimationFrame(check);
  });
  window.wheel.steer = -steer;
  await new Promise((resolve) => setTimeout(resolve, (latency || 0) + 50));
  // the rest between pulses keeps the lane: the wheel steers the drawn heading back to the road's
  const until = performance.now() + 700;
  await new Promise((resolve) => {
    const keep = () => {
      const error = ((reference - view.stats.pose[2] + 540) % 360) - 180;
      window.wheel.steer = Math.max(-0.2, Math.min(0.2, 0.05 * error));
      if (performance.now() < until) requestAnimationFrame(keep);
      else { window.wheel.steer = 0; resolve(); }
    };
    requestAnimationFrame(keep);
  });
  return latency;
}"""
RAF_PROBE = "window.rafProbe = 0; (function tick() { window.rafProbe += 1; requestAnimationFrame(tick); })();"


def tree_cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of `pid` and its children (the episode processes)."""
    ticks = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(entry.name) == pid or int(fields[1]) == pid:
            total += (int(fields[11]) + int(fields[12])) / ticks
    return total


def wait_in_page(page, expression: str, seconds: float) -> None:
    """Poll `expression` in the page until it is true (the station's CSP refuses the eval that
    Playwright's wait_for_function needs)."""
    deadline = time.monotonic() + seconds
    while not page.evaluate(expression):
        if time.monotonic() > deadline:
            raise TimeoutError(f"not true within {seconds} s: {expression}")
        page.wait_for_timeout(50)


def longest_segment(lane: str) -> tuple[tuple[float, float], tuple[float, float]]:
    """The longest straight piece of `lane` of the paper's town's net (sumolib)."""
    import sumolib

    from trustroute.app.towns import build_town_net

    shape = sumolib.net.readNet(str(build_town_net(None).path)).getLane(lane).getShape()
    return max(zip(shape, shape[1:], strict=False), key=lambda piece: math.dist(*piece))


def measure(workdir: Path) -> dict:
    from playwright.sync_api import sync_playwright

    config_path = workdir / "view.toml"
    config_path.write_text(CONFIG)
    process, address, token = start_live_server(config_path, workdir / "study", "--pace", "1", "--no-warm-up")
    try:
        headers = {"Authorization": f"Bearer {token}"}
        link = httpx.post(f"http://{address}/api/participants", json={}, headers=headers).json()["link"]
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_context(viewport={"width": 1000, "height": 800}).new_page()
            received = []
            page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: received.append(
                (time.perf_counter(), len(payload if isinstance(payload, bytes) else payload.encode())))))
            page.goto(f"http://{address}{link}")
            page.locator("#agree").click()
            page.locator("#start-trust button", has_text="4").click()
            page.locator("#speed").filter(has_text="km/h").wait_for(timeout=120_000)
            page.evaluate(RAF_PROBE)
            before = page.evaluate(COUNTS)
            cpu_before, started = tree_cpu_seconds(process.pid), time.perf_counter()
            page.wait_for_timeout(WINDOW * 1000)
            after = page.evaluate(COUNTS)
            elapsed = time.perf_counter() - started
            cpu = tree_cpu_seconds(process.pid) - cpu_before
            browser.close()
    finally:
        process.kill()
        process.wait()
    sent = sum(size for at, size in received if started <= at <= started + elapsed)
    return {"renders_per_s": (after[0] - before[0]) / elapsed,
            "frames_per_s": (after[1] - before[1]) / elapsed,
            "raf_per_s": (after[2] - before[2]) / elapsed, "bytes_per_s": sent / elapsed,
            "server_cpu_per_s": cpu / elapsed, "window_s": elapsed}


def measure_latency(workdir: Path) -> dict:
    from playwright.sync_api import sync_playwright

    (workdir / "benchwheel.toml").write_text(WHEEL_SPEC)
    config_path = workdir / "wheel.toml"
    config_path.write_text(CONFIG.replace('name = "bench-driver-view"', 'name = "bench-wheel"')
                           .replace('specs = ["phi1"]', 'specs = ["benchwheel.toml"]')
                           + '\n[live]\ndriving = "continuous"\n')
    straight = longest_segment("H-L_0")
    load_before = os.getloadavg()[0]
    process, address, token = start_live_server(config_path, workdir / "wheel", "--pace", "1", "--no-warm-up")
    try:
        headers = {"Authorization": f"Bearer {token}"}
        link = httpx.post(f"http://{address}/api/participants", json={}, headers=headers).json()["link"]
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
            page = browser.new_context(viewport={"width": 1000, "height": 800}).new_page()
            received = []
            page.on("websocket", lambda ws: ws.on("framereceived", lambda payload: received.append(
                (time.perf_counter(), len(payload if isinstance(payload, bytes) else payload.encode())))))
            page.add_init_script(WHEEL)
            page.goto(f"http://{address}{link}")
            page.locator("#agree").click()
            page.locator("#start-trust button", has_text="4").click()
            # on H-L itself: a takeover still on I-H (the station shows H-L once its junction is
            # chosen) is held at I-H's end, and the car would stand for every pulse
            (ax, ay), (bx, by) = straight
            reference = math.degrees(math.atan2(bx - ax, by - ay)) % 360
            # on H-L's long straight, 20 m into it: a takeover still on I-H (the station shows H-L
            # once its junction is chosen) is held at I-H's end, and H-L's first part ends in a
            # right-angle corner
            length = math.dist((ax, ay), (bx, by))
            into = (f"((window.driverView.stats.pose[0] - {ax}) * {bx - ax} + "
                    f"(window.driverView.stats.pose[1] - {ay}) * {by - ay}) / {length}")
            wait_in_page(page, "(window.driverView?.frames.at(-1)?.frame.lane || '').startsWith('H-L_') && "
                         f"{into} > 20", 180)
            page.evaluate("window.wheel.button = true")
            page.locator("#mode").filter(has_text="MANUAL").wait_for(timeout=30_000)
            page.evaluate(f"window.wheel.button = false; window.cruise({CRUISE})")
            wait_in_page(page, f"window.driverView.frames.at(-1).frame.speed > {CRUISE - 1}", 30)
            cpu_before, started = tree_cpu_seconds(process.pid), time.perf_counter()
            latencies = [page.evaluate(PULSE, [PULSE_STEER if i % 2 else -PULSE_STEER, reference])
                         for i in range(LATENCY_SAMPLES)]
            elapsed = time.perf_counter() - started
            cpu = (tree_cpu_seconds(process.pid) - cpu_before) / elapsed
            still_manual = page.locator("#mode").inner_text() == "MANUAL"
            browser.close()
    finally:
        process.kill()
        process.wait()
    sent = sum(size for at, size in received if started <= at <= started + elapsed)
    return {"latencies": [value for value in latencies if value is not None],
            "missed": sum(value is None for value in latencies), "server_cpu_per_s": cpu,
            "bytes_per_s": sent / elapsed, "window_s": elapsed, "manual_throughout": still_manual,
            "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)]}


def run() -> list[dict]:
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as directory:
        m = measure(Path(directory))
        load_after = os.getloadavg()[0]
        wheel = measure_latency(Path(directory))
    latencies = sorted(wheel["latencies"])
    return [{"name": "driver_view_frame_rate", "renders_per_s": round(m["renders_per_s"], 1),
             "raf_per_s": round(m["raf_per_s"], 1), "frames_received_per_s": round(m["frames_per_s"], 1),
             "window_s": round(m["window_s"], 1), "renderer": "SwiftShader (software WebGL)",
             "load_average": [round(load, 2), round(load_after, 2)], "cpus": os.cpu_count()},
            {"name": "driver_view_stream", "bytes_per_s": round(m["bytes_per_s"]),
             "server_cpu_seconds_per_s": round(m["server_cpu_per_s"], 3), "pace": 1.0},
            {"name": "driver_view_wheel_latency", "samples": len(latencies), "missed": wheel["missed"],
             "median_ms": round(statistics.median(latencies), 1) if latencies else None,
             "p95_ms": round(latencies[min(len(latencies) - 1, math.ceil(0.95 * len(latencies)) - 1)], 1)
             if latencies else None, "target_ms": 100, "pace": 1.0,
             "manual_throughout": wheel["manual_throughout"], "load_average": wheel["load_average"]},
            {"name": "driver_view_wheel_participant", "window_s": round(wheel["window_s"], 1),
             "server_cpu_seconds_per_s_driving": round(wheel["server_cpu_per_s"], 3),
             "bytes_per_s_driving": round(wheel["bytes_per_s"]), "sumo_step_s": 0.05}]
