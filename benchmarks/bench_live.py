"""Live studies (harness/live): what a person at the station gets from `trustroute live`.

Against a real server (`trustroute live` as a subprocess on 127.0.0.1, at wall-clock pace 1) and
real SUMO, with 1, 4 and 8 participants driving at once (each its own episode process), each a
websocket client speaking the participant protocol (consent, start, takeover, hand-back):

- `live_input_latency`: a key press to the vehicle's mode change, measured at the client: from
  sending `takeover` (or `hand_back`) to receiving the `mode` event, which the episode sends from
  the very SUMO step that switched the vehicle's driving style. Median and p95 in ms (target
  <= 100 ms); participant 0 toggles every 0.5 s once past the start road.
- `live_frame_rate`: frames received per wall second per participant over the measuring window
  (the server streams at most 25 per second; the station needs >= 20): the minimum and the mean
  over participants.
- `live_memory_per_participant`: the resident memory of the server and its processes (the
  episodes) while the participants drive, less the idle server's, per participant (MiB).

One JSON object per line per participant count.
"""

from __future__ import annotations

import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

COUNTS = (1, 4, 8)
WINDOW = 12.0           # wall seconds of driving measured
TOGGLE_EVERY = 0.5      # wall seconds between participant 0's takeovers and hand-backs
CONFIG = """[study]
name = "bench-live"
participants = 8
seed = 1
engine = "live"
specs = ["phi1"]
conditions = ["free"]
"""


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def start_live_server(config_path: Path | str, study_dir: Path, *options: str,
                      wait: float = 120.0) -> tuple[subprocess.Popen, str, str]:
    """(process, address, experimenter token) of `trustroute live CONFIG --out STUDY_DIR OPTIONS`
    on a free port of 127.0.0.1, once it serves (RuntimeError if it does not within `wait` s)."""
    port = free_port()
    command = [sys.executable, "-m", "trustroute.harness.cli", "live", str(config_path), "--out",
               str(study_dir), "--port", str(port), *options]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    token = ""
    for line in process.stdout:
        if line.startswith("experimenter token: "):
            token = line.split(": ", 1)[1].strip()
            break
    if not token:
        raise RuntimeError("the live server printed no experimenter token")
    address = f"127.0.0.1:{port}"
    deadline = time.monotonic() + wait
    # one client for the polling: each `httpx.get` builds a TLS context (about 25 ms of CPU)
    with httpx.Client(timeout=2) as client:
        while True:
            try:
                client.get(f"http://{address}/api/participants")
                return process, address, token
            except httpx.TransportError:
                if time.monotonic() > deadline or process.poll() is not None:
                    raise RuntimeError("the live server did not start") from None
                time.sleep(0.1)


def tree_rss_mib(pid: int) -> float:
    """Resident memory of `pid` and every process below it (MiB)."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parents[int(entry.name)] = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
    tree, frontier = {pid}, [pid]
    while frontier:
        parent = frontier.pop()
        children = [child for child, of in parents.items() if of == parent and child not in tree]
        tree.update(children)
        frontier.extend(children)
    total = 0
    for member in tree:
        try:
            for line in (Path("/proc") / str(member) / "status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1])
        except OSError:
            continue
    return total / 1024


class Client(threading.Thread):
    """One participant: consents, starts its trial, counts frames over the window; the prober
    (participant 0) also toggles takeover / hand-back and times each mode change."""

    def __init__(self, address: str, token: str, probe: bool) -> None:
        super().__init__(daemon=True)
        self.address, self.token, self.probe = address, token, probe
        self.window_start = 0.0
        self.frames: list[float] = []
        self.latencies: list[float] = []
        self.error: str | None = None

    def run(self) -> None:
        try:
            self.play()
        except Exception as exc:  # reported in the result, never hidden
            self.error = f"{type(exc).__name__}: {exc}"

    def play(self) -> None:
        from websockets.sync.client import connect

        headers = {"Authorization": f"Bearer {self.token}"}
        with connect(f"ws://{self.address}/ws", additional_headers=headers) as ws:
            ws.send(json.dumps({"type": "consent", "agree": True, "client": "scripted"}))
            ws.send(json.dumps({"type": "start", "trust": 4}))
            self.sent_at: float | None = None
            self.wanted, self.first_road, self.mode, self.last_toggle = "", None, "auto", 0.0
            while True:
                message = json.loads(ws.recv(timeout=60))
                if not self.on_message(message, time.perf_counter(), ws):
                    return

    def toggle(self, ws, wanted: str) -> None:
        self.wanted = wanted
        ws.send(json.dumps({"type": "takeover" if wanted == "manual" else "hand_back"}))
        self.sent_at = time.perf_counter()

    def on_message(self, message: dict, now: float, ws) -> bool:
        """Handle one server message; False once the window is over or the episode ended."""
        kind = message["type"]
        if kind == "frame":
            self.window_start = self.window_start or now   # each participant from its first frame
            if now > self.window_start + WINDOW:
                return False
            self.frames.append(now)
            self.first_road = self.first_road or message["road"]
            past_start = message["road"] != self.first_road
            if self.probe and self.sent_at is None and past_start and now - self.last_toggle >= TOGGLE_EVERY:
                self.toggle(ws, "manual" if self.mode == "auto" else "auto")
        elif kind == "mode":
            self.mode = message["mode"]
            if self.sent_at is not None and self.mode == self.wanted:
                self.latencies.append((now - self.sent_at) * 1000)
                self.sent_at, self.last_toggle = None, now
        elif kind == "warning" and self.mode == "manual" and self.sent_at is None:
            self.toggle(ws, "auto")   # the study's rule: hand back before the junction
        return kind not in ("episode_end", "episode_failed")


def measure(count: int, workdir: Path) -> dict:
    config_path = workdir / f"live{count}.toml"
    config_path.write_text(CONFIG)
    process, address, token = start_live_server(config_path, workdir / f"study{count}", "--pace", "1",
                                                "--no-warm-up")
    try:
        idle = tree_rss_mib(process.pid)
        headers = {"Authorization": f"Bearer {token}"}
        tokens = [httpx.post(f"http://{address}/api/participants", json={}, headers=headers).json()["token"]
                  for _ in range(count)]
        clients = [Client(address, t, probe=i == 0) for i, t in enumerate(tokens)]
        for client in clients:
            client.start()
        time.sleep(WINDOW / 2 + 5)   # every episode process started and driving
        driving = tree_rss_mib(process.pid)
        for client in clients:
            client.join(WINDOW + 120)
    finally:
        process.kill()
        process.wait()
    rates = [len(c.frames) / WINDOW for c in clients]
    latencies = sorted(clients[0].latencies)
    return {"participants": count, "idle_mib": idle, "driving_mib": driving, "rates": rates,
            "latencies": latencies, "errors": [c.error for c in clients if c.error]}


def percentile(values: list[float], q: float) -> float | None:
    if not values:
        return None
    return statistics.quantiles(values, n=100, method="inclusive")[q - 1] if len(values) > 1 else values[0]


def run() -> list[dict]:
    results = []
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as directory:
        for count in COUNTS:
            m = measure(count, Path(directory))
            results.append({
                "name": "live_input_latency", "participants": count, "samples": len(m["latencies"]),
                "median_ms": round(statistics.median(m["latencies"]), 1) if m["latencies"] else None,
                "p95_ms": round(percentile(m["latencies"], 95), 1) if m["latencies"] else None,
                "target_ms": 100, "load_average": round(load, 2), "errors": m["errors"]})
            results.append({
                "name": "live_frame_rate", "participants": count, "window_s": WINDOW,
                "min_fps": round(min(m["rates"]), 1), "mean_fps": round(statistics.mean(m["rates"]), 1),
                "streamed_fps": 25, "needed_fps": 20})
            results.append({
                "name": "live_memory_per_participant", "participants": count,
                "idle_server_mib": round(m["idle_mib"], 1), "driving_mib": round(m["driving_mib"], 1),
                "mib_per_participant": round((m["driving_mib"] - m["idle_mib"]) / count, 1)})
    return results
