"""A whole live session in a real browser: Debian's Chromium driven by Playwright against
`trustroute live` (a subprocess) and real SUMO. The experimenter creates a participant on the
console; the participant consents, drives the warm-up and the four trials (φ1/φ2 × aware/free)
from the station, takes over, passes an obstacle by hand through the oncoming lane and reports
trust; then `trustroute analyze` and `trustroute fit` read the study directory like any study.

The test never skips: without Chromium it fails and says how to install it. No browser is ever
downloaded (Playwright drives the system's Chromium)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from trustroute.core.dataset import read_episodes, read_incidents, read_kinematics, read_roads
from trustroute.harness.study.parts import read_part

from .test_live_restart import start_server

pytestmark = pytest.mark.slow

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
SCREENSHOT = Path(__file__).resolve().parents[3] / "docs" / "img" / "live-station.png"
CONFIG = """[study]
name = "browser-live"
participants = 1
seed = 3
engine = "live"
specs = ["phi1", "phi2"]
conditions = ["aware", "free"]
report_every = 1
"""
TIMEOUT_MS = 180_000


def chromium() -> str:
    if not (Path(CHROMIUM).is_file() or shutil.which("chromium")):
        pytest.fail("Chromium is missing: install Debian's package (apt-get install -y chromium); "
                    "the browser test never downloads a browser")
    return CHROMIUM if Path(CHROMIUM).is_file() else str(shutil.which("chromium"))


def create_participant(browser, address: str, token: str) -> str:
    """The experimenter's console: log in with the token, create a participant, read its link."""
    console = browser.new_context().new_page()
    console.goto(f"http://{address}/login?token={token}")
    assert console.url.endswith("/console")   # the token left the address bar
    console.fill("#label", "browser")
    console.click("#create")
    link = console.locator("#created")
    link.wait_for(state="visible")
    text = link.inner_text()
    console.locator("#participants tr").first.wait_for()
    assert "browser" in console.locator("#participants").inner_text()
    return text[text.index("http"):].split()[0]


def drive_trial(page, first: bool) -> None:
    from playwright.sync_api import expect

    """One drive from the ready step: trust 5 starts it; on the first trial the participant takes
    over, passes the obstacle by hand, reports trust, then hands back before the junction."""
    page.locator("#start-trust button", has_text="5").click()
    page.locator("#drive-step").wait_for(state="visible")
    if first:
        expect(page.locator("#speed")).to_contain_text("km/h")
        page.keyboard.press("Space")
        expect(page.locator("#mode")).to_have_text("MANUAL", timeout=TIMEOUT_MS)
        page.keyboard.press("6")
        expect(page.locator("#reported")).to_contain_text("6")
        expect(page.locator("#incident")).to_contain_text("Hand back", timeout=TIMEOUT_MS)
        SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SCREENSHOT), full_page=True)
        page.keyboard.press("Space")
        expect(page.locator("#mode")).to_have_text("AUTOPILOT", timeout=TIMEOUT_MS)
    else:
        page.keyboard.press("3")
    expect(page.locator("#ready-step:visible, #done-step:visible")).to_have_count(1, timeout=TIMEOUT_MS)


def test_a_whole_session_in_chromium_is_read_by_analyze_and_fit(tmp_path):
    from playwright.sync_api import sync_playwright

    executable = chromium()
    config_path = tmp_path / "browser.toml"
    config_path.write_text(CONFIG)
    study_dir = tmp_path / "study"
    process, address, token = start_server(str(config_path), study_dir, pace=20.0)
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
            try:
                link = create_participant(browser, address, token)
                page = browser.new_context(viewport={"width": 760, "height": 900}).new_page()
                page.set_default_timeout(60_000)
                page.goto(link)
                assert page.url.endswith("/station")
                page.locator("#agree").click()
                page.locator("#ready-step").wait_for(state="visible")
                assert "warm-up" in page.locator("#trial-text").inner_text()
                drive_trial(page, first=False)   # the warm-up
                for trial in range(4):
                    drive_trial(page, first=trial == 0)
                page.locator("#done-step").wait_for(state="visible")
            finally:
                browser.close()
    finally:
        process.kill()
        process.wait()
    check_the_study_directory(study_dir, tmp_path)


def check_the_study_directory(study_dir: Path, tmp_path: Path) -> None:
    from click.testing import CliRunner

    from trustroute.harness.cli import cli

    episodes = read_episodes(study_dir)
    assert len(episodes) == 4 and list(episodes["participant"].unique()) == [0]
    assert sorted(zip(episodes["spec"], episodes["condition"], strict=True)) == [
        ("phi1", "aware"), ("phi1", "free"), ("phi2", "aware"), ("phi2", "free")]
    assert episodes["satisfied"].notna().all()
    assert int(episodes["takeovers"].sum()) >= 1
    roads = read_roads(study_dir)
    assert roads["takeover"].any()
    assert set(roads["reported_trust"].dropna().astype(int)) >= {6}
    kinematics = read_kinematics(study_dir)
    assert "manual" in set(kinematics["mode"])
    incidents = read_incidents(study_dir)
    assert incidents["takeover_start"].notna().any()
    events = [event for episode_id in episodes["episode_id"]
              for event in read_part(study_dir / "parts" / f"{episode_id}.zip").summary["live"]["events"]]
    assert {"takeover", "hand_back", "trust"} <= {event["type"] for event in events}

    result = CliRunner().invoke(cli, ["analyze", str(study_dir), "--json", "--no-report"])
    assert result.exit_code == 0, result.output
    analysis = json.loads(result.output)
    assert analysis["engine"] == "live"
    assert sorted((c["spec"], c["condition"], c["n"]) for c in analysis["cells"]) == [
        ("phi1", "aware", 1), ("phi1", "free", 1), ("phi2", "aware", 1), ("phi2", "free", 1)]
    fit_path = tmp_path / "fit.json"
    fitted = CliRunner().invoke(cli, ["fit", str(study_dir), "--out", str(fit_path), "--json"])
    assert fitted.exit_code == 0, fitted.output
    assert fit_path.is_file()
