"""Questionnaires in a live study: placed before the study, after each trial and at the end by the
config's [questionnaires] table, asked in that order (and again after a restart until answered),
checked, stored in questionnaires.parquet and scored by `analyze`."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner
from fastapi.testclient import TestClient

from tests.questionnaire_files import COMFORT
from trustroute.core.dataset import read_questionnaires
from trustroute.harness.cli import cli
from trustroute.harness.live.app import live_app
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config
from trustroute.participants.questionnaires import NASA_TLX

from .conftest import TINY, consenting_participant, serving
from .test_live_episode import receive_until

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]
PLACED = """
[questionnaires]
before = ["nasa_tlx"]
after_each_trial = ["jian"]
end = ["comfort.toml"]
"""


def questionnaire_config(tmp_path, participants: int = 1):
    (tmp_path / "comfort.toml").write_text(COMFORT)
    path = tmp_path / "live.toml"
    path.write_text(TINY.format(participants=participants, specs='["phi1"]') + PLACED)
    return load_study_config(path)


def test_questionnaires_are_asked_where_placed_checked_and_stored(tmp_path):
    config = questionnaire_config(tmp_path)
    study_dir = tmp_path / "study"
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            with consenting_participant(client, study) as (station, _):
                state = receive_until(station, lambda m: m.get("phase") == "questionnaire")
                shown = state["questionnaire"]
                assert (shown["name"], shown["placement"], shown["trial"]) == ("nasa_tlx", "before", None)
                assert len(shown["items"]) == 6 and "reversed" not in shown["items"][0]
                assert shown["instructions"] == NASA_TLX.instructions_for("before")   # no drive done yet
                station.send_json({"type": "start"})
                assert receive_until(station, lambda m: m["type"] == "error")["code"] == "out_of_order"
                partial = {"type": "answers", "questionnaire": "nasa_tlx", "answers": {"mental": 50}}
                station.send_json(partial)
                assert "missing" in receive_until(station, lambda m: m["type"] == "error")["detail"]
                station.send_json({"type": "answers", "questionnaire": "jian", "answers": {}})
                assert receive_until(station, lambda m: m["type"] == "error")["code"] == "out_of_order"
                answers = {item["id"]: 5 * (3 + i) for i, item in enumerate(shown["items"])}
                station.send_json({"type": "answers", "questionnaire": "nasa_tlx", "answers": answers})
                assert receive_until(station, lambda m: m["type"] == "state")["phase"] == "ready"
        assert read_questionnaires(study_dir)["value"].tolist() == [15.0, 20.0, 25.0, 30.0, 35.0, 40.0]
    finally:
        study.close()
    study = LiveStudy(config, study_dir, ServerOptions(pace=1000.0, warm_up=False)).open()   # a restart
    try:
        assert study.sessions[0].phase == "ready"   # the answered questionnaire is not asked again
        with serving(study) as (host, port):
            token = study.replace_token(0, "test: the scripted participant's token")
            player = ScriptedParticipant(config, 0)
            player.tasks = player.tasks[1:]
            run_scripted(f"ws://{host}:{port}/ws", token, player, 120)
            assert player.finished and study.sessions[0].phase == "done"
    finally:
        study.close()
    answers = read_questionnaires(study_dir)
    asked = answers.drop_duplicates(["placement", "questionnaire"])
    assert list(zip(asked["placement"], asked["questionnaire"], strict=True)) == [
        ("after_each_trial", "jian"), ("before", "nasa_tlx"), ("end", "comfort")]   # (in file-name order)
    jian = answers[answers["questionnaire"] == "jian"]
    assert len(jian) == 12 and jian["episode_id"].iloc[0] == config_trial(config)
    assert jian["reversed"].tolist() == [True] * 5 + [False] * 7
    result = CliRunner().invoke(cli, ["analyze", str(study_dir), "--json", "--no-report"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["questionnaires"]
    scores = {(row["questionnaire"], row["condition"]): row for row in rows}
    assert scores[("jian", "free")]["responses"] == 1
    assert scores[("jian", "free")]["mean_score"] == pytest.approx((5 * 4 + 7 * 4) / 12)   # the middle, 4
    withdrawn = CliRunner().invoke(cli, ["withdraw", str(study_dir), "0", "--json"])   # answers go too
    assert withdrawn.exit_code == 0, withdrawn.output
    removed = {entry["path"].split("/")[1] for entry in json.loads(withdrawn.output)["removed"]}
    assert "questionnaires" in removed and not (study_dir / "questionnaires.parquet").exists()
    assert not list((study_dir / "live" / "questionnaires").iterdir())


def config_trial(config) -> str:
    from trustroute.harness.study.plan import plan_episodes

    return plan_episodes(config)[0].episode_id


def test_an_answer_off_the_scale_is_malformed_and_the_socket_stays(tmp_path):
    """A huge number or a number a hair off a point of the scale gets a `malformed` reply; the
    connection goes on and the answers are asked again."""
    study = LiveStudy(questionnaire_config(tmp_path), tmp_path / "study", ServerOptions(warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            with consenting_participant(client, study) as (station, _):
                receive_until(station, lambda m: m.get("phase") == "questionnaire")
                rest = ',"physical":0,"temporal":0,"performance":0,"effort":0,"frustration":0}}'
                for mental in ("1" + "0" * 400, "50.0000000001"):
                    station.send_text('{"type":"answers","questionnaire":"nasa_tlx","answers":{"mental":'
                                      + mental + rest)
                    reply = receive_until(station, lambda m: m["type"] == "error")
                    assert reply["code"] == "malformed" and "not on the scale" in reply["detail"], reply
                station.send_json({"type": "ping"})
                assert receive_until(station, lambda m: m["type"] == "pong")
        assert study.sessions[0].phase == "questionnaire"
        assert not (study.study_dir / "live" / "questionnaires").exists()
    finally:
        study.close()
