"""The experimenter's console in real Chromium: kept usable by keyboard, telling a lost login in
words, and showing a withdrawn participant as withdrawn, with nothing to press.

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import re

import httpx
import pytest

from .test_browser_station import served_station

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


@pytest.fixture(scope="module")
def station(tmp_path_factory):
    with served_station(tmp_path_factory.mktemp("console")) as served:
        yield served


def experimenter(station) -> dict:
    return {"Authorization": f"Bearer {station.study.experimenter_token}"}


def open_console(station):
    """(context, page): a console logged in with a fresh console link."""
    made = httpx.post(f"{station.address}/api/login-link", headers=experimenter(station)).json()
    context = station.browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.goto(station.address + made["link"])
    return context, page


def new_participant(station) -> int:
    created = httpx.post(f"{station.address}/api/participants", json={}, headers=experimenter(station))
    return created.json()["participant"]


def buttons(page, participant: int) -> list[str]:
    return page.locator(f'#participants tr[data-participant="{participant}"] button').all_inner_texts()


def test_the_console_keeps_the_keyboards_focus_and_says_how_to_log_in_again(station, tmp_path):
    context, page = open_console(station)
    last = [new_participant(station) for _ in range(2)][-1]
    pause = page.locator(f'#participants tr[data-participant="{last}"] button', has_text="pause")
    pause.focus()
    page.evaluate("window.kept = document.activeElement")
    page.wait_for_timeout(2500)   # the table is refreshed every second
    assert page.evaluate("document.activeElement === window.kept && window.kept.isConnected")
    page.keyboard.press("Tab")   # on to the next control of the same participant, by keyboard
    assert page.evaluate("document.activeElement.textContent") == "resume"
    assert page.evaluate("document.activeElement.closest('tr').dataset.participant") == str(last)
    context.clear_cookies()   # as after a restart: the server no longer knows this console
    page.locator("#error").filter(has_text="no longer logged in").wait_for()
    assert "new console link" in page.locator("#error").inner_text()
    page.screenshot(path=str(tmp_path / "logged-out.png"))
    response = page.reload()
    assert response.status == 401 and "new console link" in page.locator("#message").inner_text()
    page.screenshot(path=str(tmp_path / "console-refused.png"))
    context.close()


def test_a_withdrawn_participants_row_says_so_and_offers_nothing_to_press(station, tmp_path):
    """Withdrawn from the console, the participant's row loses its buttons (the server refuses
    them: tests/harness/live/test_live_withdraw.py) and says what the withdrawal did; another
    participant's row keeps all of them, and a console opened afterwards shows the row the same."""
    context, page = open_console(station)
    withdrawn, other = new_participant(station), new_participant(station)
    row = page.locator(f'#participants tr[data-participant="{withdrawn}"]')
    row.locator("button", has_text="withdraw").wait_for()
    assert buttons(page, withdrawn) == ["pause", "resume", "abort", "new link", "withdraw"]
    page.once("dialog", lambda dialog: dialog.accept())
    row.locator("button", has_text="withdraw").click()
    phase = row.locator("td", has_text=re.compile("^withdrawn$"))
    phase.wait_for()
    for _ in range(2):   # a console opened before the withdrawal, then one opened after it
        assert buttons(page, withdrawn) == []
        cells = row.locator("td").all_inner_texts()
        assert cells[:3] == [str(withdrawn), "", "withdrawn"] and len(cells) == 4
        assert "Withdrawn from the study" in cells[3] and "deleted" in cells[3]
        assert buttons(page, other) == ["pause", "resume", "abort", "new link", "withdraw"]
        assert page.locator("#error").inner_text() == ""
        page.screenshot(path=str(tmp_path / "console-withdrawn.png"))
        page.reload()
        phase.wait_for()
        page.locator(f'#participants tr[data-participant="{other}"] button').first.wait_for()
    context.close()
