"""The README's screenshots (docs/img/), made again on the default town in headless Chromium.

    .venv/bin/python docs/screenshots.py [report] [replay] [--demo DIR] [--out docs/img]
    .venv/bin/python docs/screenshots.py --rrd FILE OUT.png [--wait SECONDS]

- `report`: `trustroute demo` (SUMO engine, default town; resumes a finished demo in DIR) and its
  `report.html` at 1400 x 2000 pixels: `report.png`.
- `replay`: the demo's episode `p00002-phi1-aware` replayed into a recording, served by
  `rerun --serve-web` on 127.0.0.1, opened in Rerun's web viewer: `rerun-replay.png`.
- `--rrd FILE OUT.png`: any recording in the web viewer (e.g. `rerun-city.png`, the recipe in
  docs/replay-and-report.md).

With no name, both. Chromium is Debian's (`/usr/bin/chromium`), driven by Playwright. The Rerun
web viewer is WebAssembly drawing with WebGL: it runs on SwiftShader (software, no GPU) and gets
real time to draw before the capture (`--wait`). Every address is a loopback one.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
FLAGS = ["--no-sandbox", "--disable-gpu", "--use-gl=angle", "--use-angle=swiftshader",
         "--enable-unsafe-swiftshader", "--disable-background-networking", "--disable-component-update"]
REPLAYED_EPISODE = "p00002-phi1-aware"
REPORT_SIZE = (1400, 2000)
VIEWER_SIZE = (1600, 1000)


def capture(url: str, out: Path, size: tuple[int, int], wait: float = 0.0) -> None:
    """A screenshot of `url` in a `size` window, `wait` seconds after it has loaded."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            page.goto(url, wait_until="load", timeout=120_000)
            page.wait_for_timeout(wait * 1000)
            page.screenshot(path=str(out))
        finally:
            browser.close()
    print(f"wrote {out}")


def trustroute(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "trustroute", *args], check=True, cwd=REPO)


def report_screenshot(demo: Path, out_dir: Path) -> None:
    trustroute("demo", "--out", str(demo), "--quiet")
    capture((demo / "report.html").resolve().as_uri(), out_dir / "report.png", REPORT_SIZE)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _wait_for_port(port: int, seconds: float = 60.0) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.5)
    raise SystemExit(f"nothing listens on 127.0.0.1:{port} after {seconds:.0f} s")


def recording_screenshot(rrd: Path, out: Path, wait: float) -> None:
    """`rrd` served by `rerun --serve-web` on loopback ports and captured in its web viewer."""
    web, grpc = _free_port(), _free_port()
    rerun = shutil.which("rerun", path=str(Path(sys.executable).parent)) or "rerun"
    # `rerun` is rerun-sdk's Python launcher, which runs the viewer binary as its child: the server
    # gets a process group of its own, and the whole group is stopped (the launcher alone would
    # leave the binary serving, and rendering, after the capture).
    server = subprocess.Popen([rerun, "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web),
                               "--port", str(grpc), str(rrd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        _wait_for_port(web)
        _wait_for_port(grpc)
        source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
        capture(f"http://127.0.0.1:{web}/?url={source}", out, VIEWER_SIZE, wait)
    finally:
        _stop_group(server)


def _stop_group(process: subprocess.Popen) -> None:
    """SIGTERM to the process's group, then SIGKILL if it has not ended within 30 s."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(process.pid, signal.SIGTERM)
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()


def replay_screenshot(demo: Path, out_dir: Path, wait: float) -> None:
    if not (demo / "manifest.json").is_file():
        trustroute("demo", "--out", str(demo), "--quiet")
    with tempfile.TemporaryDirectory() as scratch:
        rrd = Path(scratch) / "replay.rrd"
        trustroute("replay", str(demo), REPLAYED_EPISODE, "--rrd", str(rrd))
        recording_screenshot(rrd, out_dir / "rerun-replay.png", wait)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", metavar="{report,replay}",
                        help="which screenshots (default: both)")
    parser.add_argument("--demo", type=Path, default=REPO / "out" / "demo", help="the demo's study directory")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "img", help="where the PNGs go")
    parser.add_argument("--wait", type=float, default=45.0, help="seconds the web viewer gets to draw")
    parser.add_argument("--rrd", nargs=2, type=Path, metavar=("FILE", "OUT.png"),
                        help="capture one recording in the web viewer instead")
    args = parser.parse_args()
    if args.rrd:
        recording_screenshot(args.rrd[0].resolve(), args.rrd[1], args.wait)
        return
    names = args.names or ["report", "replay"]
    if set(names) - {"report", "replay"}:
        parser.error(f"unknown screenshot names {sorted(set(names) - {'report', 'replay'})}")
    if "report" in names:
        report_screenshot(args.demo.resolve(), args.out)
    if "replay" in names:
        replay_screenshot(args.demo.resolve(), args.out, args.wait)


if __name__ == "__main__":
    main()
