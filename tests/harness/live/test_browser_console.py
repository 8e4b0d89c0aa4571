"""The experimenter's console in real Chromium: kept usable by keyboard, telling a lost login in
words, offering in each row only what the server accepts in that participant's phase, and showing
a withdrawn or declined participant as such.

Never skips: without Chromium it fails and says how to install it."""

from __future__ import annotations

import json
import re

import httpx
import pytest

from .test_browser_station import station_fixture

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


station = station_fixture("console")


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
    link = page.locator(f'#participants tr[data-participant="{last}"] button', has_text="new link")
    link.focus()
    page.evaluate("window.kept = document.activeElement")
    page.wait_for_timeout(2500)   # the table is refreshed every second
    assert page.evaluate("document.activeElement === window.kept && window.kept.isConnected")
    page.keyboard.press("Tab")   # on to the next control of the same participant, by keyboard
    assert page.evaluate("document.activeElement.textContent") == "withdraw"
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
    assert buttons(page, withdrawn) == ["new link", "withdraw"]
    page.once("dialog", lambda dialog: dialog.accept())
    row.locator("button", has_text="withdraw").click()
    phase = row.locator("td", has_text=re.compile("^withdrawn$"))
    phase.wait_for()
    for _ in range(2):   # a console opened before the withdrawal, then one opened after it
        assert buttons(page, withdrawn) == []
        cells = row.locator("td").all_inner_texts()
        assert cells[:3] == [str(withdrawn), "", "withdrawn"] and len(cells) == 4
        assert "Withdrawn from the study" in cells[3] and "deleted" in cells[3]
        assert buttons(page, other) == ["new link", "withdraw"]
        assert page.locator("#error").inner_text() == ""
        page.screenshot(path=str(tmp_path / "console-withdrawn.png"))
        page.reload()
        phase.wait_for()
        page.locator(f'#participants tr[data-participant="{other}"] button').first.wait_for()
    context.close()


def test_a_withdrawal_says_which_exported_packages_still_hold_the_participant(station, tmp_path):
    """Withdrawn from the console while a package exported before holds them (the key file written
    as `trustroute export` writes it), the console says so in the line `trustroute withdraw`
    prints: the package, when it was written and their code in it. The sentence stays through
    the table's refreshes until dismissed, and goes at the next action."""
    from trustroute.harness.live.withdraw import AUDIT, LIVE_DIR, withdrawal_line
    from trustroute.harness.study.export import KEY_FILE, read_export_keys, write_export_keys

    study_dir = station.study.study_dir
    context, page = open_console(station)
    withdrawn, other = new_participant(station), new_participant(station)
    package = tmp_path / "shared-package"
    write_export_keys(study_dir, read_export_keys(study_dir), package, {withdrawn: 417, other: 902})
    notice = page.locator("#notice")
    try:
        for participant, code in ((withdrawn, 417), (other, 902)):
            row = page.locator(f'#participants tr[data-participant="{participant}"]')
            page.once("dialog", lambda dialog: dialog.accept())
            row.locator("button", has_text="withdraw").click()
            notice.wait_for(state="visible")
            entry = json.loads((study_dir / LIVE_DIR / AUDIT).read_text().splitlines()[-1])
            assert entry["participant"] == participant and entry["exported"][0]["participant"] == code
            said = notice.locator("#notice-text").inner_text()
            assert said == withdrawal_line(study_dir, entry)
            assert f"{package} (written {entry['exported'][0]['written_utc']}), still holds their data " \
                   f"as participant {code}: export the study again and replace it wherever" in said
            page.wait_for_timeout(2500)   # the table is refreshed every second: the sentence stays
            assert notice.is_visible() and notice.locator("#notice-text").inner_text() == said
            page.screenshot(path=str(tmp_path / f"console-withdrawn-exported-{participant}.png"))
            if participant == withdrawn:
                notice.locator("button", has_text="dismiss").click()
            else:
                page.locator("#create").click()   # the next action
                page.locator("#created").filter(has_text=f"participant {other + 1}").wait_for()
            notice.wait_for(state="hidden")
        assert page.locator("#error").inner_text() == ""
    finally:
        (study_dir / KEY_FILE).unlink()
        context.close()


def test_each_row_offers_only_what_the_server_accepts_in_its_phase(station, tmp_path):
    """Not yet consented, consented, finished and declined: no row offers to pause, resume or
    abort (no episode runs); the declined row says why in place of its progress and offers only a
    new link, which asks for the consent again and brings the row back."""
    from trustroute.harness.live.protocol import Consent

    context, page = open_console(station)
    study = station.study
    waiting, ready, finished, declined = (new_participant(station) for _ in range(4))
    study.sessions[ready].handle(Consent(type="consent", agree=True))
    study.sessions[finished].warmed_up = True
    study.done |= {task.episode_id for task in study.sessions[finished].tasks}
    study.sessions[finished].handle(Consent(type="consent", agree=True))
    study.sessions[declined].handle(Consent(type="consent", agree=False))
    phases = {waiting: "consent", ready: "ready", finished: "done", declined: "declined"}
    for participant, phase in phases.items():
        row = page.locator(f'#participants tr[data-participant="{participant}"]')
        row.locator("td", has_text=re.compile(f"^{phase}$")).wait_for()
        offered = buttons(page, participant)
        assert not {"pause", "resume", "abort"} & set(offered), (phase, offered)
        expected = ["new link"] if phase == "declined" else ["new link", "withdraw"]
        assert offered == expected, (phase, offered)
    row = page.locator(f'#participants tr[data-participant="{declined}"]')
    cells = row.locator("td").all_inner_texts()
    assert cells[:3] == [str(declined), "", "declined"] and len(cells) == 5
    assert "Did not agree to take part" in cells[3] and "nothing of theirs is kept" in cells[3]
    assert page.locator("#error").inner_text() == ""
    page.screenshot(path=str(tmp_path / "console-phases.png"))
    page.once("dialog", lambda dialog: dialog.accept())
    row.locator("button", has_text="new link").click()
    row.locator("td", has_text=re.compile("^consent$")).wait_for()
    assert buttons(page, declined) == ["new link", "withdraw"]
    assert len(row.locator("td").all_inner_texts()) == 12
    context.close()


def test_a_row_offers_the_episode_controls_its_pause_allows(station):
    """An episode the experimenter paused, its participant at the station, can be resumed or
    aborted; one the participant's disconnect paused only aborted (they resume it when they come
    back). Aborting asks first, naming the drive as the row does."""
    from trustroute.harness.live.protocol import Consent

    from .test_live_console import Pipe

    context, page = open_console(station)
    study = station.study
    for paused_by, offered in (("experimenter", ["resume", "abort", "new link", "withdraw"]),
                               ("disconnect", ["abort", "new link", "withdraw"])):
        participant = new_participant(station)
        session = study.sessions[participant]
        session.handle(Consent(type="consent", agree=True))
        with session.lock:
            session.phase, session.pause_reason = "paused", paused_by
            session.task, session.connection = session.tasks[0], Pipe()
            session.push = None if paused_by == "disconnect" else Pipe().send   # their station
        row = page.locator(f'#participants tr[data-participant="{participant}"]')
        row.locator("td", has_text=f"paused ({paused_by})").wait_for()
        row.locator("button", has_text="abort").wait_for()
        assert buttons(page, participant) == offered, paused_by
        asked: list[str] = []   # the abort's confirmation names the drive in the state's words
        page.once("dialog", lambda dialog, asked=asked: (asked.append(dialog.message), dialog.dismiss()))
        row.locator("button", has_text="abort").click()
        drive = session.progress()["trial_status"]
        assert drive == "paused in 1 of 1"
        assert asked == [f"Abort participant {participant}'s drive ({drive})? It will be run again."]
    context.close()


def test_a_created_participants_label_is_cleared_and_a_refused_ones_kept(station, tmp_path):
    """After *Create participant* the label field is empty for the next participant; after a
    refused create (here: the login gone) the label typed stays, to create it again."""
    context, page = open_console(station)
    page.locator("#label").fill("alice")
    page.locator("#create").click()
    page.locator("#created").filter(has_text="participant").wait_for()
    created = int(page.locator("#created").inner_text().split(":")[0].split()[-1])
    assert station.study.sessions[created].label == "alice"
    assert page.locator("#label").input_value() == ""
    context.clear_cookies()
    page.locator("#label").fill("bob")
    page.locator("#create").click()
    page.locator("#error").filter(has_text="no longer logged in").wait_for()
    assert page.locator("#label").input_value() == "bob"
    context.close()


def test_a_row_shows_the_drive_only_while_it_runs_and_which_trial_it_is(station, tmp_path):
    """Driving a trial, the row shows its episode, road and "driving 1 of 1"; once it has ended,
    no episode or road, and "1 of 1 done": the state's words (`trial_status`), not the page's."""
    from trustroute.harness.live.protocol import Consent

    from .test_live_console import Pipe

    context, page = open_console(station)
    study = station.study
    participant = new_participant(station)
    session = study.sessions[participant]
    session.handle(Consent(type="consent", agree=True))
    task = session.tasks[0]
    with session.lock:
        session.warmed_up = True
        session.phase, session.task, session.connection = "driving", task, Pipe()
        session.frame = {"type": "frame", "road": "A-B"}
    row = page.locator(f'#participants tr[data-participant="{participant}"]')
    header = page.locator("thead th").all_inner_texts()
    column = {name: header.index(name) for name in ("trial", "episode", "road")}

    def cells() -> dict:
        texts = row.locator("td").all_inner_texts()
        return {name: texts[index] for name, index in column.items()}

    row.locator("td", has_text=re.compile("^driving 1 of 1$")).wait_for()
    assert cells() == {"trial": "driving 1 of 1", "episode": task.episode_id, "road": "A-B"}
    page.screenshot(path=str(tmp_path / "console-driving.png"))
    with session.lock:
        study.done.add(task.episode_id)
        session.phase = session.next_phase()
    row.locator("td", has_text=re.compile("^1 of 1 done$")).wait_for()
    assert cells() == {"trial": "1 of 1 done", "episode": "", "road": ""}
    page.screenshot(path=str(tmp_path / "console-done.png"))
    context.close()


def test_the_console_and_the_station_load_without_an_error_or_a_missing_resource(station, tmp_path):
    """Every resource the console, the link's page and the station ask for is served and the
    browser logs no error on loading them: nothing answers 404, the icon a browser asks for by
    itself (/favicon.ico) included. Each page is opened in a browser of its own, as a station's or
    the experimenter's is: a browser asks for a site's icon once, and remembers a missing one."""
    from tests.browser import chromium_executable

    from .test_browser import CHROMIUM_ARGS

    problems: list[str] = []
    created = httpx.post(f"{station.address}/api/participants", json={}, headers=experimenter(station)).json()
    made = httpx.post(f"{station.address}/api/login-link", headers=experimenter(station)).json()
    for link, shown in ((made["link"], "#participants tr"), (created["link"], "#consent-step")):
        launch = station.browser.browser_type.launch
        browser = launch(executable_path=chromium_executable(), args=CHROMIUM_ARGS)
        page = browser.new_page()
        page.on("console", lambda message: problems.append(f"{message.text} {message.location['url']}")
                if message.type == "error" else None)
        page.on("response", lambda response: problems.append(f"{response.status}: {response.url}")
                if response.status >= 400 else None)
        page.on("requestfailed", lambda request: problems.append(f"failed: {request.url}"))
        page.goto(station.address + link)
        page.locator(shown).first.wait_for(state="visible")
        page.wait_for_timeout(1500)   # (the icon is asked for after the page has loaded)
        browser.close()
    assert problems == []


def test_a_participants_link_opened_in_the_consoles_browser_says_where_to_open_it(station):
    """A browser logged in to the console claims no participant's link (tests/harness/live/
    test_live_security.py): the link's page says so in the server's words, and the link is unspent."""
    from trustroute.harness.live.app import CONSOLE_HERE

    context, console = open_console(station)
    console.wait_for_url("**/console")   # logged in: the cookie is set
    created = httpx.post(f"{station.address}/api/participants", json={}, headers=experimenter(station)).json()
    page = context.new_page()
    page.goto(station.address + created["link"])
    page.locator("#message").filter(has_text="another browser").wait_for()
    assert page.locator("#message").inner_text() == CONSOLE_HERE
    context.close()
    claimed = httpx.post(f"{station.address}/api/claim", json={"token": created["token"]})
    assert claimed.status_code == 200
