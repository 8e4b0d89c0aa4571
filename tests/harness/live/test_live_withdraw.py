"""Withdrawal: a participant's drives, warm-ups and rows leave every consolidated table, the
deletion is audited with checksums, `analyze` reads what is left, and a re-run is refused unless
the participant is readmitted."""

from __future__ import annotations

import json
import threading
import time

import httpx
import pytest
from click.testing import CliRunner

from tests.cli import assert_one_line_error, run_cli
from tests.lock_holder import another_process_holds
from trustroute.core.dataset import read_attempts, read_episodes, read_kinematics, read_roads
from trustroute.core.errors import InputError
from trustroute.harness.cli import cli
from trustroute.harness.live import session as live_session
from trustroute.harness.live.protocol import Consent, Start
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.live.session import withdrawn_refusal
from trustroute.harness.live.withdraw import sha256_of

from .conftest import experimenter, serving, tiny_config


@pytest.mark.slow
@pytest.mark.wallclock
def test_withdraw_then_analyze(tmp_path, capsys):
    config = tiny_config(tmp_path, participants=2)
    study_dir = tmp_path / "study"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0)).open()
    try:
        with serving(study) as (host, port):
            tokens = [study.create_participant()[1] for _ in range(2)]
            for p, token in enumerate(tokens):
                run_scripted(f"ws://{host}:{port}/ws", token, ScriptedParticipant(config, p), 120)
            assert sorted(read_episodes(study_dir)["participant"]) == [0, 1]
            mine = sorted(path for path in study_dir.rglob("p00001-*") if path.is_file())
            assert {path.parent.name for path in mine} == {"parts"}   # the trial's and the warm-up's
            checksums = {str(path.relative_to(study_dir)): sha256_of(path) for path in mine}
            headers = {"Authorization": f"Bearer {study.experimenter_token}"}
            url = f"http://{host}:{port}/api/participants/1/withdraw"
            assert httpx.post(url, json={}, headers=headers).status_code == 422   # no confirmation
            done = httpx.post(url, json={"confirm": True, "reason": "asked by phone"}, headers=headers)
            assert done.status_code == 200 and done.json()["removed"] == len(mine) == 2
            again = httpx.post(url, json={"confirm": True}, headers=headers)
            assert again.status_code == 409
            link = httpx.post(f"http://{host}:{port}/api/participants/1/link", headers=headers)
            assert link.status_code == 409   # no new link: a re-run is refused
            me = httpx.get(f"http://{host}:{port}/api/me", headers={"Authorization": f"Bearer {tokens[1]}"})
            assert me.status_code == 403
    finally:
        study.close()
    assert not any(path.exists() for path in mine)
    for table in (read_episodes(study_dir), read_roads(study_dir), read_kinematics(study_dir)):
        assert not table["episode_id"].str.startswith("p00001-").any() and len(table)
    assert set(read_attempts(study_dir)["participant"]) == {0}
    audit = [json.loads(line) for line in (study_dir / "live" / "withdrawals.jsonl").read_text().splitlines()]
    assert len(audit) == 1 and audit[0]["participant"] == 1 and audit[0]["reason"] == "asked by phone"
    assert {entry["path"]: entry["sha256"] for entry in audit[0]["removed"]} == checksums
    assert audit[0]["tables_after"]["episodes.parquet"] == sha256_of(study_dir / "episodes.parquet")
    assert audit[0]["tables_before"]["episodes.parquet"] != audit[0]["tables_after"]["episodes.parquet"]
    registry = json.loads((study_dir / "live" / "participants.json").read_text())["participants"]
    assert set(registry["1"]) == {"withdrawn", "withdrawn_utc"}   # no label, no token digest

    analyzed = CliRunner().invoke(cli, ["analyze", str(study_dir), "--json", "--no-report"])
    assert analyzed.exit_code == 0, analyzed.output
    assert sum(cell["n"] for cell in json.loads(analyzed.output)["cells"]) == 1

    code, _, err = run_cli(capsys, "withdraw", str(study_dir), "p00001")   # the dataset's id of 1
    assert code == 2 and "withdrawn already" in err and err.count("\n") == 1
    code, _, err = run_cli(capsys, "withdraw", str(study_dir), "7")
    assert code == 2 and "no participant 7" in err
    reopened = LiveStudy(config, study_dir, ServerOptions(pace=1000.0)).open()
    try:
        assert reopened.sessions[1].phase == "withdrawn" and 1 not in reopened.credentials.participants
        code, _, err = run_cli(capsys, "withdraw", str(study_dir), "0")   # the server holds the lock
        assert code == 2 and "in use" in err
    finally:
        reopened.close()
    code, out, _ = run_cli(capsys, "withdraw", str(study_dir), "1", "--readmit")
    assert code == 0 and "readmitted" in out
    readmitted = LiveStudy(config, study_dir, ServerOptions(pace=1000.0)).open()
    try:
        assert readmitted.sessions[1].phase == "consent"
        readmitted.replace_token(1, "test: a new link")   # the console's new link lets them in again
    finally:
        readmitted.close()


BAD_REGISTRIES = {   # (registry, place, problem)
    "record not an object": ('{"participants": {"0": "alice"}}', "participants.0", "expected an object"),
    "index not an integer": ('{"participants": {"zero": {}}}', "participants.zero",
                             "not a participant's index"),
    "order not a list": ('{"participants": {"0": {"order": 5}}}', "participants.0.order",
                         "expected a list of episode ids"),
}


@pytest.mark.parametrize("kind", sorted(BAD_REGISTRIES))
@pytest.mark.parametrize("readmit", [False, True])
def test_a_malformed_registry_is_one_line_naming_the_key(kind, readmit, tmp_path, capsys):
    text, place, problem = BAD_REGISTRIES[kind]
    registry = tmp_path / "study" / "live" / "participants.json"
    registry.parent.mkdir(parents=True)
    registry.write_text(text)
    code, _, err = run_cli(capsys, "withdraw", str(tmp_path / "study"), "0" if readmit else "5",
                           *(["--readmit"] if readmit else []))
    assert_one_line_error(code, err, f"{registry}: {place}: {problem}", "restore it from a backup")
    assert registry.read_text() == text


@pytest.mark.parametrize("kind", sorted(BAD_REGISTRIES))
def test_the_station_reads_the_registry_with_the_same_checks(kind, tmp_path):
    from trustroute.harness.study.resume import mark_study_dir

    text, place, problem = BAD_REGISTRIES[kind]
    config = tiny_config(tmp_path)
    mark_study_dir(tmp_path / "study", config, config.content_hash)   # the study's folder, as served
    registry = tmp_path / "study" / "live" / "participants.json"
    registry.parent.mkdir(parents=True)
    registry.write_text(text)
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=1000.0))
    with pytest.raises(InputError) as refused:
        study.open()
    assert f"{registry}: {place}: {problem}" in refused.value.one_line()


def _unconsolidated(tmp_path, journal: str):
    """A live study of two participants before its first consolidation: a part each, the journal."""
    study = tmp_path / "study"
    (study / "live").mkdir(parents=True)
    (study / "parts").mkdir()
    (study / "live" / "participants.json").write_text(
        '{"participants": {"0": {"label": "a", "consented": true}, "1": {"label": "b", "consented": true}}}')
    for participant in (0, 1):
        (study / "parts" / f"p0000{participant}-phi1-free.zip").write_bytes(b"a part")
    (study / "live" / "attempts.jsonl").write_text(journal)
    return study


def _attempt(participant: int) -> str:
    return json.dumps({"event": "start", "utc": "2026-01-01T00:00:00Z", "participant": participant,
                       "episode_id": f"p0000{participant}-phi1-free", "warm_up": False,
                       "planned_position": 0})


def test_a_journal_whose_last_append_was_cut_short_withdraws_like_the_station_reads_it(tmp_path, capsys):
    study = _unconsolidated(tmp_path, f"{_attempt(0)}\n{_attempt(1)}\n{_attempt(0)[:12]}")
    code, _, err = run_cli(capsys, "withdraw", str(study), "0")
    assert code == 0, err
    assert sorted(path.name for path in (study / "parts").iterdir()) == ["p00001-phi1-free.zip"]
    assert (study / "live" / "attempts.jsonl").read_text() == _attempt(1) + "\n"
    assert set(read_attempts(study)["participant"]) == {1}
    audit = json.loads((study / "live" / "withdrawals.jsonl").read_text())
    assert audit["participant"] == 0
    assert [entry["path"] for entry in audit["removed"]] == ["parts/p00000-phi1-free.zip"]


@pytest.mark.parametrize("bad", ['{"partic', '{"participant": 0}'])
def test_a_bad_journal_line_is_refused_before_anything_is_deleted(bad, tmp_path, capsys):
    study = _unconsolidated(tmp_path, f"{_attempt(0)}\n{bad}\n{_attempt(1)}\n")
    before = {str(p.relative_to(study)): p.read_bytes() for p in study.rglob("*") if p.is_file()}
    code, _, err = run_cli(capsys, "withdraw", str(study), "0")
    journal = study / "live" / "attempts.jsonl"
    assert_one_line_error(code, err, f"{journal}: line 2", "restore it from a backup")
    after = {str(p.relative_to(study)): p.read_bytes() for p in study.rglob("*") if p.is_file()}
    assert after == {**before, "study.lock": after["study.lock"]}


def test_a_withdrawal_while_a_trial_starts_waits_for_the_start(tmp_path, monkeypatch):
    """A start holds the participant's session while its episode process spawns, then journals
    the attempt (the study's lock); a withdrawal meanwhile takes the same two locks in the same
    order, so it waits for the start and then stops the episode (the spawn is slowed here so the
    withdrawal comes inside it)."""
    spawn = live_session.start_episode_process

    def slow_spawn(*args, **kwargs):
        time.sleep(0.3)
        return spawn(*args, **kwargs)

    monkeypatch.setattr(live_session, "start_episode_process", slow_spawn)
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions(pace=1.0)).open()
    participant = study.create_participant()[0]
    session = study.sessions[participant]
    session.handle(Consent(type="consent", agree=True))
    starting = threading.Thread(target=session.handle, args=(Start(type="start"),), daemon=True)
    withdrawing = threading.Thread(target=study.withdraw, args=(participant,), daemon=True)
    starting.start()
    time.sleep(0.1)
    withdrawing.start()
    starting.join(10), withdrawing.join(10)
    hung = starting.is_alive() or withdrawing.is_alive()
    if not hung:   # (a hung study cannot be closed: its locks are held for good)
        study.close()
    assert not hung, "the start and the withdrawal wait for each other"
    assert session.phase == "withdrawn" and participant in study.withdrawn
    assert session.process is not None and not session.process.is_alive()


def test_a_withdrawn_participants_label_is_gone_at_once(tmp_path):
    """The console shows a withdrawn participant without their label while the server runs, as
    the registry keeps none."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = {"Authorization": f"Bearer {study.experimenter_token}"}
            created = client.post("/api/participants", json={"label": "Ada L."}, headers=headers)
            assert created.status_code == 200
            withdrawn = client.post("/api/participants/0/withdraw", json={"confirm": True}, headers=headers)
            assert withdrawn.status_code == 200
            state = client.get("/api/participants/0", headers=headers).json()
            assert (state["phase"], state["label"]) == ("withdrawn", "")
            assert "Ada" not in client.get("/api/participants", headers=headers).text
    finally:
        study.close()


def test_the_console_commands_for_a_withdrawn_participant_are_refused_saying_why(tmp_path):
    """Pause, resume, abort and a new link for a withdrawn participant: each refused (409) with
    the one line that says they have withdrawn, not a phase name to decode."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            assert client.post("/api/participants", json={}, headers=headers).status_code == 200
            assert client.post("/api/participants/0/withdraw", json={"confirm": True},
                               headers=headers).status_code == 200
            for action in ("pause", "resume", "abort"):
                refused = client.post("/api/participants/0/control", json={"action": action}, headers=headers)
                assert refused.status_code == 409
                assert refused.json()["detail"] == {"type": "error", "code": "out_of_order",
                                                    "detail": f"no {action}: {withdrawn_refusal(0)}"}
            link = client.post("/api/participants/0/link", headers=headers)
            assert link.status_code == 409
            assert link.json()["detail"]["detail"] == f"no link: {withdrawn_refusal(0)}"
            assert client.get("/api/participants/0", headers=headers).json()["phase"] == "withdrawn"
    finally:
        study.close()


def test_withdraw_json_is_the_audit_entry_with_the_files_it_wrote(tmp_path, capsys):
    study = _unconsolidated(tmp_path, f"{_attempt(0)}\n{_attempt(1)}\n")
    code, out, err = run_cli(capsys, "withdraw", str(study), "p00000", "--json")
    assert code == 0, err
    answer = json.loads(out)
    audit = study / "live" / "withdrawals.jsonl"
    entry = json.loads(audit.read_text())
    assert answer["participant"] == 0 and answer == {**entry, "paths": answer["paths"]}
    assert answer["paths"] == {"audit": str(audit), "registry": str(study / "live" / "participants.json"),
                               "study": str(study)}
    code, out, err = run_cli(capsys, "withdraw", str(study), "0", "--readmit", "--json")
    assert code == 0, err
    assert set(json.loads(out)["paths"]) == {"audit", "registry"}


def test_a_withdrawal_names_the_package_exported_before_that_still_holds_them(tmp_path, capsys):
    """A package written by `trustroute export` before the withdrawal is outside the study, where
    the withdrawal cannot delete their data: the command, and the audit, say which package and the
    participant's code in it, so the researcher replaces it; a key file of the single-package form
    ({"package", "pseudonyms"}, no time) is read as that one package's entry."""
    study = _unconsolidated(tmp_path, f"{_attempt(0)}\n{_attempt(1)}\n")
    package = tmp_path / "shared-package"
    (study / "export-key.json").write_text(json.dumps({"pseudonyms": {"0": 417, "1": 902},
                                                      "package": str(package)}))
    code, out, err = run_cli(capsys, "withdraw", str(study), "1")
    assert code == 0, err
    assert f"{package}, still holds their data as participant 902: export the study again" in out
    entry = json.loads((study / "live" / "withdrawals.jsonl").read_text())
    assert entry["exported"] == [{"package": str(package), "written_utc": None, "participant": 902}]
    (study / "export-key.json").write_text(json.dumps({"pseudonyms": [1], "package": str(package)}))
    code, out, err = run_cli(capsys, "withdraw", str(study), "0")
    assert_one_line_error(code, err, "export-key.json", "pseudonyms", "restore it from a backup")
    assert (study / "parts" / "p00000-phi1-free.zip").exists()   # refused before anything is deleted


def test_a_console_withdrawal_answers_with_the_packages_that_still_hold_them(tmp_path):
    """Withdrawn from the console, the answer names the packages exported before that hold the
    participant, as the audit entry does, and carries the command's line that says so."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app
    from trustroute.harness.study.export import KEY_FILE, write_export_keys

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    package = tmp_path / "shared-package"
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            for _ in range(2):
                assert client.post("/api/participants", json={}, headers=headers).status_code == 200
            write_export_keys(study.study_dir, [], package, {0: 417, 1: 902})
            withdraw = "/api/participants/{}/withdraw"
            answer = client.post(withdraw.format(1), json={"confirm": True}, headers=headers).json()
            entry = json.loads((study.study_dir / "live" / "withdrawals.jsonl").read_text())
            assert answer["exported"] == entry["exported"]
            assert [held["participant"] for held in entry["exported"]] == [902]
            assert answer["line"].startswith("participant 1 withdrawn: 0 files removed")
            assert f"{package} (written {entry['exported'][0]['written_utc']}), still holds their data as " \
                   "participant 902: export the study again" in answer["line"]
            (study.study_dir / KEY_FILE).unlink()   # no package holds participant 0
            alone = client.post(withdraw.format(0), json={"confirm": True}, headers=headers).json()
            assert alone["exported"] == [] and "still holds" not in alone["line"]
    finally:
        study.close()


UNREADABLE = {   # a file the withdrawal reads: (its path in the study, its text, the refusal's start, fix)
    "key file": ("export-key.json", json.dumps({"pseudonyms": [1], "package": "/shared"}),
                 "pseudonyms: expected participant number -> code", "restore it from a backup"),
    "manifest": ("manifest.json", "{", "line 1 column 2: not valid JSON", "fix the JSON syntax"),
    "journal": ("live/attempts.jsonl", '{"partic\n', "line 1 column 2: not valid JSON",
                "restore it from a backup"),
    "answers": ("live/questionnaires/p00000-before-study-trust.json", "{}",
                "scale: not a submitted questionnaire's answers", "restore it from a backup"),
}


@pytest.mark.parametrize("damaged", list(UNREADABLE))
def test_an_unreadable_file_refuses_a_console_withdrawal_before_anything_changes(damaged, tmp_path):
    """Everything the withdrawal reads (the key file, the manifest, the journal, the answers) is read
    before the withdrawal begins: a file that cannot be read refuses it with the one line naming
    the file, the place and the fix, and the participant stays as they were (their link opens
    their station, their session is not withdrawn); once it is mended, the withdrawal goes through."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    name, text, problem, fix = UNREADABLE[damaged]
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    path = study.study_dir / name
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with TestClient(live_app(study)) as client:
            link = client.post("/api/participants", json={}, headers=experimenter(study)).json()["token"]
            registry = study.registry_path().read_text()
            path.write_text(text)
            refused = client.post("/api/participants/0/withdraw", json={"confirm": True},
                                  headers=experimenter(study))
            assert refused.status_code == 409, refused.text
            detail = refused.json()["detail"]["detail"]
            assert detail.startswith(f"{path}: {problem}") and fix in detail and "\n" not in detail
            assert study.sessions[0].phase == "consent" and 0 not in study.withdrawn
            assert study.registry_path().read_text() == registry
            assert not (study.study_dir / "live" / "withdrawals.jsonl").exists()
            assert client.post("/api/claim", json={"token": link}).status_code == 200   # the link still opens
            assert client.get("/api/me").json()["participant"] == 0
            path.unlink()
            assert client.post("/api/participants/0/withdraw", json={"confirm": True},
                               headers=experimenter(study)).status_code == 200
            assert study.sessions[0].phase == "withdrawn"
    finally:
        study.close()


def _issue_while_paused(study, client, issue: str, meanwhile):
    """`issue` ("claim": the participant's link opened; "link": the console's new link) for
    participant 0, paused where the server is about to issue the token (LiveStudy.replace_token
    entered) while `meanwhile()` runs to its end on this thread; the issuing request's response."""
    real, reached, go, responses = study.replace_token, threading.Event(), threading.Event(), []

    def paused(*args, **kwargs):
        if not reached.is_set():   # (the issuing request's call; `meanwhile`'s go on)
            reached.set()
            go.wait(10)
        return real(*args, **kwargs)

    link = client.post("/api/participants", json={}, headers=experimenter(study)).json()["token"]
    request = (("/api/claim", {"json": {"token": link}}) if issue == "claim" else
               ("/api/participants/0/link", {"headers": experimenter(study)}))
    study.replace_token = paused
    issuing = threading.Thread(target=lambda: responses.append(client.post(request[0], **request[1])))
    issuing.start()
    try:
        assert reached.wait(10), "the request did not reach the token's issue"
        meanwhile(link)
    finally:
        go.set()
        issuing.join(10)
        study.replace_token = real
    return responses[0]


@pytest.mark.parametrize("issue, refusal", [("claim", 403), ("link", 409)])
def test_no_token_is_issued_once_a_withdrawal_has_begun(issue, refusal, tmp_path):
    """A link claimed, or a new link issued, at the instant of a withdrawal: the withdrawal comes
    between the request's checks and the token's issue, and the request is refused; the withdrawn
    participant has no token and nothing authenticates as them."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    withdrawals = []
    try:
        with TestClient(live_app(study)) as client:
            def withdraw(_link):
                withdrawals.append(client.post("/api/participants/0/withdraw", json={"confirm": True},
                                               headers=experimenter(study)))

            response = _issue_while_paused(study, client, issue, withdraw)
            assert withdrawals[0].status_code == 200, withdrawals[0].text
            assert response.status_code == refusal, response.text
            assert study.credentials.participants == {}   # no token of the withdrawn participant
            assert client.get("/api/me").status_code == 403   # (no cookie was set either)
            registry = json.loads(study.registry_path().read_text())["participants"]
            assert set(registry["0"]) == {"withdrawn", "withdrawn_utc"}
            assert not (study.study_dir / "live" / "tokens.jsonl").exists()   # no token was replaced
    finally:
        study.close()


def test_a_link_claimed_twice_at_once_gives_one_token(tmp_path):
    """Two browsers claim the same link at once: the one that comes second to the token's issue
    is refused (the link is spent), and the first one's token stays the participant's."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    first = []
    try:
        with TestClient(live_app(study)) as client, TestClient(live_app(study)) as other:
            def claim_first(link):
                first.append(other.post("/api/claim", json={"token": link}))

            late = _issue_while_paused(study, client, "claim", claim_first)
            assert first[0].status_code == 200 and late.status_code == 403, (first[0].text, late.text)
            assert other.get("/api/me").json()["participant"] == 0   # the first claim's cookie
            assert client.get("/api/me").status_code == 403
    finally:
        study.close()


def test_a_withdrawal_closes_the_station_of_a_claimed_link(tmp_path):
    """A withdrawal after a link was claimed revokes the claimed token: the station opened with it
    is told and closed (code 1008, reason "withdrawn"), and the token authenticates no more."""
    from fastapi.testclient import TestClient
    from starlette.websockets import WebSocketDisconnect

    from trustroute.harness.live.app import POLICY_VIOLATION, live_app

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            link = client.post("/api/participants", json={}, headers=experimenter(study)).json()["token"]
            assert client.post("/api/claim", json={"token": link}).status_code == 200
            with client.websocket_connect("/ws") as station:   # the claimed token, in the cookie
                station.receive_json(), station.receive_json()
                withdrawn = client.post("/api/participants/0/withdraw", json={"confirm": True},
                                        headers=experimenter(study))
                assert withdrawn.status_code == 200
                assert station.receive_json() == {"type": "revoked", "detail": "withdrawn from the study"}
                with pytest.raises(WebSocketDisconnect) as closed:
                    station.receive_json()
                assert (closed.value.code, closed.value.reason) == (POLICY_VIOLATION, "withdrawn")
            assert client.get("/api/me").status_code == 403 and study.credentials.participants == {}
    finally:
        study.close()


def test_a_withdrawal_while_a_run_holds_the_study_says_to_use_the_console(tmp_path, capsys):
    # a live server holds the study: its console withdraws; --out means nothing to `withdraw`
    study = _unconsolidated(tmp_path, f"{_attempt(0)}\n{_attempt(1)}\n")
    with another_process_holds(study) as pid:
        code, out, err = run_cli(capsys, "withdraw", str(study), "p00000")
        assert_one_line_error(code, err, str(study), f"in use by pid {pid}", "live console")
        assert "--out" not in err and out == ""
    assert not (study / "live" / "withdrawals.jsonl").exists()
