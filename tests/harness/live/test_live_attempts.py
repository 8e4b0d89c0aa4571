"""The order actually run: an incomplete trial moves to the end of the participant's plan, that
order survives a restart, every attempt is a row of the attempts table, and `analyze`'s order
effects use the positions the trials were run at."""

from __future__ import annotations

import json
import time

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from trustroute.analysis.study.analysis import study_analysis
from trustroute.analysis.study.order import run_order
from trustroute.core.dataset import read_attempts, read_episodes, read_manifest
from trustroute.core.errors import InputError
from trustroute.harness.live.app import live_app
from trustroute.harness.live.attempts import AttemptLog
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions

from .conftest import consenting_participant, experimenter, serving, tiny_config
from .test_live_episode import receive_until

START = {"event": "start", "utc": "2026-01-01T00:00:00Z", "participant": 0, "episode_id": "p00000-phi1-free",
         "warm_up": False, "planned_position": 0}
END = {"event": "end", "utc": "2026-01-01T00:01:00Z", "participant": 0, "episode_id": "p00000-phi1-free",
       "outcome": "done", "reason": None}


def leave_mid_trial(study: LiveStudy) -> str:
    """A participant created, who consents, starts their first trial and goes away: it becomes
    incomplete. Its episode id."""
    with TestClient(live_app(study)) as client:
        headers = experimenter(study)
        with consenting_participant(client, study) as (station, _):
            receive_until(station, lambda m: m.get("phase") == "ready")
            station.send_json({"type": "start"})
            first = receive_until(station, lambda m: m["type"] == "episode_start")["episode_id"]
            receive_until(station, lambda m: m["type"] == "frame")
        deadline = time.monotonic() + 30
        while (progress := client.get("/api/participants/0", headers=headers).json())["phase"] != "ready":
            assert time.monotonic() < deadline, progress
            time.sleep(0.05)
    assert progress["last_error"].startswith("incomplete")
    return first


@pytest.mark.slow
@pytest.mark.wallclock
def test_an_incomplete_trial_runs_last_across_a_restart_and_analyze_uses_the_order_run(tmp_path):
    config = tiny_config(tmp_path, participants=1, specs=("phi1", "phi2"))
    study_dir = tmp_path / "study"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1.0, resume_within=0.2, warm_up=False)).open()
    try:
        first = leave_mid_trial(study)
        planned = [task.episode_id for task in study.tasks_of(0)]
        assert planned[0] == first
        assert [task.episode_id for task in study.sessions[0].tasks] == [planned[1], first]
    finally:
        study.close()
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0, warm_up=False)).open()   # a restart
    try:
        assert [task.episode_id for task in study.sessions[0].tasks] == [planned[1], first]
        assert study.sessions[0].progress()["next_episode"] == planned[1]
        token = study.replace_token(0, "test: the scripted participant's own token")
        with serving(study) as (host, port):
            player = ScriptedParticipant(config, 0)
            player.tasks = player.tasks[1:]   # no warm-up on this server
            run_scripted(f"ws://{host}:{port}/ws", token, player, 120)
        assert [episode["episode_id"] for episode in player.episodes] == [planned[1], first]
    finally:
        study.close()
    attempts = read_attempts(study_dir)
    columns = ["episode_id", "attempt", "sequence", "planned_position", "run_position", "outcome"]
    rows = [tuple(None if pd.isna(value) else value for value in row)
            for row in attempts[columns].astype(object).itertuples(index=False, name=None)]
    assert rows == [(first, 1, 1, 0, None, "incomplete"), (planned[1], 1, 2, 1, 0, "done"),
                    (first, 2, 3, 0, 1, "done")]
    assert attempts["reason"].iloc[0].startswith("incomplete") and attempts["ended_utc"].notna().all()
    episodes = read_episodes(study_dir)
    run = run_order(study_dir, read_manifest(study_dir), episodes).set_index("episode_id")["position"]
    assert run.to_dict() == {planned[1]: 0, first: 1}
    trust = episodes.set_index("episode_id")["mean_reported_trust"]
    assert trust[planned[1]] != trust[first]   # (so the order table tells the two orders apart)
    order = study_analysis(study_dir, resamples=200).order.set_index("position")
    assert order.loc[1, "mean_trust"] == pytest.approx(trust[planned[1]])   # the trial run first
    assert order.loc[2, "mean_trust"] == pytest.approx(trust[first])


def _journal(tmp_path, text: str) -> AttemptLog:
    log = AttemptLog(tmp_path, "live")
    log.path.parent.mkdir(parents=True)
    log.path.write_text(text)
    return log


def test_an_append_a_crash_cut_short_is_left_out_and_the_next_append_starts_a_clean_line(tmp_path):
    log = _journal(tmp_path, json.dumps(START) + "\n" + json.dumps(END)[:30])
    assert log.records() == [START]
    log.append(END)
    assert log.path.read_text() == json.dumps(START) + "\n" + json.dumps(END) + "\n"
    assert [row["outcome"] for row in log.rows()] == ["done"]


def test_a_whole_last_record_without_its_newline_is_kept(tmp_path):
    log = _journal(tmp_path, json.dumps(START))
    assert log.records() == [START]
    log.append(END)
    assert log.records() == [START, END]


@pytest.mark.parametrize(("line", "place", "problem"), [
    ('{"partic', "line 2 column 2", "not valid JSON"),
    ('{"participant": 0}', "line 2", "not an attempt record"),
    (json.dumps({k: v for k, v in END.items() if k != "participant"}), "line 2 key 'participant'", "missing"),
    (json.dumps({**END, "participant": "zero"}), "line 2 key 'participant'", 'unexpected value "zero"'),
])
def test_a_bad_line_before_the_last_is_one_error_naming_the_line(tmp_path, line, place, problem):
    log = _journal(tmp_path, "\n".join([json.dumps(START), line, json.dumps(END), ""]))
    with pytest.raises(InputError) as refused:
        log.rows()
    assert refused.value.one_line().startswith(f"{log.path}: {place}: {problem}")
