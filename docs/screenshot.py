"""Screenshot a page in headless Chromium after it has had real time to render (docs/ images).

    python docs/screenshot.py URL OUT.png [--wait SECONDS] [--size 1600x1000] [--click X,Y ...]

`chromium --screenshot` captures at the load event, before a WebAssembly app such as the Rerun web
viewer has drawn anything, so this drives Chromium over its DevTools protocol instead (tornado's
websocket client, installed with Dask): open the page, wait, capture. WebGL runs on SwiftShader
(software), so no GPU is needed. Only loopback addresses are used.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
]


async def _capture(ws_url: str, url: str, out: Path, wait: float, width: int, height: int,
                   clicks: list[tuple[int, int]] = ()) -> None:
    from tornado.websocket import websocket_connect

    connection = await websocket_connect(ws_url, max_message_size=256 * 1024 * 1024)
    counter = 0

    async def call(method: str, **params):
        nonlocal counter
        counter += 1
        connection.write_message(json.dumps({"id": counter, "method": method, "params": params}))
        while True:
            message = json.loads(await connection.read_message())
            if message.get("id") == counter:
                return message.get("result", {})

    await call(
        "Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1, mobile=False
    )
    await call("Page.navigate", url=url)
    await asyncio.sleep(wait)
    for x, y in clicks:  # e.g. on the Rerun viewer's time bar, to move its time cursor there
        for kind in ("mousePressed", "mouseReleased"):
            await call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)
        await asyncio.sleep(5.0)
    shot = await call("Page.captureScreenshot", format="png")
    out.write_bytes(base64.b64decode(shot["data"]))
    connection.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("url")
    parser.add_argument("out", type=Path)
    parser.add_argument("--wait", type=float, default=20.0)
    parser.add_argument("--size", default="1600x1000")
    parser.add_argument("--port", type=int, default=9333)
    parser.add_argument("--click", action="append", default=[], metavar="X,Y",
                        help="click the page at pixel X,Y after --wait (repeatable), 5 s before the capture")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    profile = tempfile.mkdtemp()
    browser = subprocess.Popen(
        [
            "chromium",
            *FLAGS,
            f"--user-data-dir={profile}",
            f"--remote-debugging-port={args.port}",
            "--remote-debugging-address=127.0.0.1",
            f"--window-size={width},{height}",
            "about:blank",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        for _ in range(60):
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{args.port}/json") as response:
                    pages = [t for t in json.load(response) if t.get("type") == "page"]
                if pages:
                    break
            except OSError:
                pass
            time.sleep(0.5)
        else:
            raise SystemExit("chromium did not start its DevTools endpoint")
        clicks = [(int(x), int(y)) for x, y in (c.split(",") for c in args.click)]
        asyncio.run(_capture(pages[0]["webSocketDebuggerUrl"], args.url, args.out, args.wait, width, height,
                             clicks))
    finally:
        browser.terminate()
        browser.wait(timeout=20)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
