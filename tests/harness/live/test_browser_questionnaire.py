"""The Jian et al. trust questionnaire after each trial, answered in a real browser (Debian's
Chromium) at the station; `trustroute analyze` prints its scores and Cronbach's alpha."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from click.testing import CliRunner

from tests.browser import chromium_executable
from trustroute.core.dataset import read_questionnaires
from trustroute.harness.cli import cli

from .test_browser import CHROMIUM_ARGS, TIMEOUT_MS, answer_prompt, create_participant
from .test_live_restart import start_server

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]
SCREENSHOT = "questionnaire.png"
CONFIG = """[study]
name = "browser-questionnaire"
participants = 1
seed = 3
engine = "live"
specs = ["phi1", "phi2"]
conditions = ["free"]
report_every = 1

[questionnaires]
after_each_trial = ["jian"]
"""


def answer_jian(page, trial: int, screenshot) -> None:
    """Every item: 2, 3, 4, 2, ... after the first trial, two points higher after the second."""
    from playwright.sync_api import expect

    page.locator("#questionnaire-step").wait_for(state="visible", timeout=TIMEOUT_MS)
    expect(page.locator("#questionnaire-title")).to_contain_text("Jian")
    items = page.locator("#questionnaire-form fieldset")
    expect(items).to_have_count(12)
    submit = page.locator("#questionnaire-submit")
    for index in range(12):
        expect(submit).to_be_disabled()
        items.nth(index).locator(f"input[value='{2 + 2 * trial + index % 3}']").check()
    if screenshot is not None:
        page.screenshot(path=str(screenshot), full_page=True)
    submit.click()


def test_the_jian_questionnaire_after_each_trial_in_chromium(tmp_path):
    from playwright.sync_api import sync_playwright

    config_path = tmp_path / "questionnaire.toml"
    config_path.write_text(CONFIG)
    study_dir = tmp_path / "study"
    process, address, token = start_server(str(config_path), study_dir, 20.0)
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
            link = create_participant(browser, address, token)
            page = browser.new_context(viewport={"width": 640, "height": 480}).new_page()
            page.set_default_timeout(60_000)
            page.goto(link)
            page.wait_for_url("**/station")
            page.locator("#agree").click()
            page.locator("#ready-step").wait_for(state="visible")
            page.locator("#start-trust button", has_text="5").click()   # the warm-up
            page.locator("#drive-step").wait_for(state="visible")
            while not page.locator("#ready-step:visible").count():
                answer_prompt(page)
                time.sleep(0.05)
            for trial in range(2):
                page.locator("#start-trust button", has_text="5").click()
                page.locator("#drive-step").wait_for(state="visible")
                deadline = time.monotonic() + TIMEOUT_MS / 1000
                while not page.locator("#questionnaire-step:visible").count():
                    assert time.monotonic() < deadline, page.locator("body").inner_text()
                    answer_prompt(page)
                    time.sleep(0.05)
                answer_jian(page, trial, tmp_path / SCREENSHOT if trial == 0 else None)
                page.locator("#ready-step:visible, #done-step:visible").wait_for()
            page.locator("#done-step").wait_for(state="visible")
            browser.close()
    finally:
        process.kill()
        process.wait()
    answers = read_questionnaires(study_dir)
    assert len(answers) == 24 and set(answers["questionnaire"]) == {"jian"}
    assert answers["episode_id"].nunique() == 2 and set(answers["placement"]) == {"after_each_trial"}
    first = answers[answers["episode_id"] == answers["episode_id"].iloc[0]].sort_values("item_index")
    assert first["value"].tolist() == [2.0 + i % 3 for i in range(12)]
    printed = CliRunner().invoke(cli, ["analyze", str(study_dir), "--no-report"])
    assert printed.exit_code == 0, printed.output
    assert "Questionnaire scores per condition" in printed.output and "Cronbach's alpha" in printed.output
    result = json.loads(CliRunner().invoke(cli, ["analyze", str(study_dir), "--json", "--no-report"]).output)
    (jian,) = result["questionnaires"]
    assert (jian["questionnaire"], jian["condition"], jian["responses"]) == ("jian", "free", 2)
    # alpha through the item covariances, on the answers turned where reversed (items 1-5)
    given = [2 + 2 * trial + np.arange(12) % 3 for trial in (0, 1)]
    turned = [[8 - v if i < 5 else v for i, v in enumerate(values)] for values in given]
    covariance = np.cov(np.array(turned, dtype=float), rowvar=False)
    v, c = np.mean(np.diag(covariance)), covariance[~np.eye(12, dtype=bool)].mean()
    assert jian["cronbach_alpha"] == pytest.approx(12 * c / (v + 11 * c))
