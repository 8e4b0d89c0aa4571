"""Live episodes against real SUMO: through a real uvicorn server and the websocket (the scripted
participant), paused, resumed and aborted by the experimenter, and read by `trustroute analyze`."""

from __future__ import annotations

import contextlib
import json
import threading
import time

import httpx
import pandas as pd
import pytest
import uvicorn
from fastapi.testclient import TestClient

from benchmarks.bench_live import free_port
from tests.cli import run_cli
from trustroute.core.dataset import part_path, read_episodes, read_kinematics, read_manifest, read_roads
from trustroute.harness.live.app import live_app
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions, warm_up_task
from trustroute.harness.study.parts import read_part

from .conftest import consenting_participant, experimenter, tiny_config
from .test_live_manual import play_in

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


@contextlib.contextmanager
def serving(study: LiveStudy):
    """The base address of the live study on a real uvicorn at 127.0.0.1 and a random port,
    served from a thread while the block runs."""
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(live_app(study), host="127.0.0.1", port=port,
                                           log_level="warning", lifespan="off"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 30
    while not server.started:
        assert time.monotonic() < deadline, "uvicorn did not start"
        time.sleep(0.02)
    try:
        yield f"127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(10)


@pytest.fixture
def served(live_study):
    """(study, base address) of the live study on a real uvicorn (`serving`)."""
    with serving(live_study) as address:
        yield live_study, address


def test_a_scripted_participant_drives_through_the_websocket_and_analyze_reads_it(served, tmp_path, capsys):
    study, address = served
    headers = {"Authorization": f"Bearer {study.experimenter_token}"}
    created = httpx.post(f"http://{address}/api/participants", json={"label": "scripted"}, headers=headers)
    token = created.json()["token"]
    played = run_scripted(f"ws://{address}/ws", token, ScriptedParticipant(study.config, 0), timeout=120)
    task, warm_up = study.tasks_of(0)[0], warm_up_task(study.config, 0)
    assert played.finished
    assert [e["episode_id"] for e in played.episodes] == [warm_up.episode_id, task.episode_id]
    # the warm-up drive has its part beside the dataset, not in it
    warm_up_part = read_part(part_path(study.warm_up_dir(), warm_up.episode_id))
    assert warm_up_part.summary["live"]["driver"] == "scripted"
    assert [e for e in played.errors if e["code"] != "out_of_order"] == []
    part = read_part(part_path(study.study_dir, task.episode_id))
    assert part.summary["live"]["driver"] == "scripted"
    sent = [event for event in part.summary["live"]["events"] if event["type"] == "trust"]
    assert len(sent) >= 1 and all(1 <= event["value"] <= 7 for event in sent)
    # the dataset is consolidated: the episode, its roads and every tick of its kinematics
    manifest = read_manifest(study.study_dir)
    assert manifest["engine"] == "live" and manifest["finished_episodes"] == 1
    episodes, roads = read_episodes(study.study_dir), read_roads(study.study_dir)
    assert list(episodes["episode_id"]) == [task.episode_id]
    assert int(episodes["junctions"].iloc[0]) == len(roads) - 1 == played.episodes[1]["junctions"]
    reported = roads["reported_trust"].dropna().astype(int).tolist()
    assert reported and set(reported) <= {event["value"] for event in sent}
    assert not pd.isna(roads.sort_values("index")["reported_trust"].iloc[-1])   # the last prompt's answer
    kinematics = read_kinematics(study.study_dir)
    assert len(kinematics) > 50 and set(kinematics["mode"]) <= {"auto", "manual"}
    progress = httpx.get(f"http://{address}/api/participants/0", headers=headers).json()
    assert progress["phase"] == "done" and progress["done"] == [task.episode_id]
    assert progress["warm_up"] == "done"
    download = httpx.get(f"http://{address}/api/download/episodes.parquet", headers=headers)
    assert download.status_code == 200
    assert download.content == (study.study_dir / "episodes.parquet").read_bytes()

    from click.testing import CliRunner

    from trustroute.harness.cli import cli

    result = CliRunner().invoke(cli, ["analyze", str(study.study_dir), "--json", "--no-report"])
    assert result.exit_code == 0, result.output
    analysis = json.loads(result.output)
    assert analysis["engine"] == "live"
    assert [(c["spec"], c["condition"], c["n"]) for c in analysis["cells"]] == [("phi1", "free", 1)]
    # a person has no true driver model: a live study has no "true" belief source (docs/study.md);
    # filtered with the study's driver model on the stated trust, it was shown as each driver's own
    code, out, _ = run_cli(capsys, "analyze", str(study.study_dir), "--no-report")
    assert code == 0 and "mean stated trust" in out and "true" not in out.replace("true)", "")
    code, _, err = run_cli(capsys, "analyze", str(study.study_dir), "--no-report", "--belief-source", "true")
    assert code == 2 and err.count("\n") == 1 and "needs a simulated study (this one is live" in err, err
    # the manual-driving table: one row per incident type with a takeover (assisted: the reaction only)
    incidents = pd.read_parquet(study.study_dir / "incidents.parquet")
    took = incidents[incidents["takeover"]]
    assert sum(row["takeovers"] for row in analysis["manual_driving"]) == len(took)
    assert all(row["by_wheel"] == 0 for row in analysis["manual_driving"])
    fit_path = tmp_path / "fit.json"
    fitted = CliRunner().invoke(cli, ["fit", str(study.study_dir), "--out", str(fit_path), "--json"])
    assert fitted.exit_code == 0, fitted.output
    assert fit_path.is_file()


def receive_until(socket, wanted, limit: int = 5000) -> dict:
    for _ in range(limit):
        message = socket.receive_json()
        if wanted(message):
            return message
    raise AssertionError("the awaited message never came")


def test_disconnect_pauses_resume_continues_and_the_experimenter_aborts(tmp_path):
    """At wall-clock pace the episode is still running while the test acts on it."""
    config = tiny_config(tmp_path, participants=1)
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=1.0)).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            with consenting_participant(client, study) as (station, participant):
                receive_until(station, lambda m: m.get("phase") == "ready")
                station.send_json({"type": "start", "trust": 5})
                receive_until(station, lambda m: m["type"] == "frame")
                station.send_json({"type": "trust", "value": 6})
            assert client.get("/api/participants/0", headers=headers).json()["paused_by"] == "disconnect"
            with client.websocket_connect("/ws", headers=participant) as station:
                receive_until(station, lambda m: m.get("phase") == "paused")
                station.send_json({"type": "resume"})
                receive_until(station, lambda m: m.get("phase") == "driving")
                receive_until(station, lambda m: m["type"] == "frame")
                paused = client.post("/api/participants/0/control", json={"action": "pause"}, headers=headers)
                assert paused.json()["paused_by"] == "experimenter"
                station.send_json({"type": "resume"})   # the experimenter's pause is not the participant's
                assert receive_until(station, lambda m: m["type"] == "error")["code"] == "out_of_order"
                client.post("/api/participants/0/control", json={"action": "abort"}, headers=headers)
                assert receive_until(station, lambda m: m["type"] == "episode_aborted")
                state = receive_until(station, lambda m: m["type"] == "state")
                assert state["phase"] == "ready" and state["done"] == []
        assert not part_path(study.study_dir, study.tasks_of(0)[0].episode_id).exists()
    finally:
        study.close()


def test_no_reconnection_in_time_makes_the_episode_incomplete(tmp_path):
    config = tiny_config(tmp_path, participants=1)
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=1.0, resume_within=0.3)).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            with consenting_participant(client, study) as (station, _):
                receive_until(station, lambda m: m.get("phase") == "ready")
                station.send_json({"type": "start"})
                receive_until(station, lambda m: m["type"] == "frame")
            deadline = time.monotonic() + 30
            while (progress := client.get("/api/participants/0", headers=headers).json())["phase"] != "ready":
                assert time.monotonic() < deadline, progress
                time.sleep(0.1)
            assert progress["last_error"].startswith("incomplete") and progress["done"] == []
            assert progress["next_episode"] == warm_up_task(config, 0).episode_id   # to be run again
            assert progress["warm_up"] == "pending"
        assert not part_path(study.study_dir, study.tasks_of(0)[0].episode_id).exists()
    finally:
        study.close()


def test_participants_drive_at_once_each_in_their_own_session(served):
    study, address = served
    headers = {"Authorization": f"Bearer {study.experimenter_token}"}
    tokens = [httpx.post(f"http://{address}/api/participants", json={}, headers=headers).json()["token"]
              for _ in range(2)]
    players = [ScriptedParticipant(study.config, p) for p in range(2)]
    threads = [threading.Thread(target=run_scripted, args=(f"ws://{address}/ws", token, player, 120))
               for token, player in zip(tokens, players, strict=True)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(180)
    for p, player in enumerate(players):
        assert player.finished
        assert [e["episode_id"] for e in player.episodes] == [warm_up_task(study.config, p).episode_id,
                                                              study.tasks_of(p)[0].episode_id]
    episodes = read_episodes(study.study_dir)
    assert sorted(episodes["episode_id"]) == sorted(t.episode_id for t in study.tasks)
    assert list(episodes["participant"]) == [0, 1]


def test_scripted_participants_in_lockstep_reproduce_the_headless_study(tmp_path):
    """The live path runs the headless episode code: scripted participants answering every
    decision (lockstep) give the very episodes `trustroute study` gives on the same config and
    seeds, but for the trust columns (a live episode logs the stated trust, not a hidden one)."""
    from trustroute.harness.study.runner import run_and_consolidate

    config = tiny_config(tmp_path, participants=3, specs=("phi1", "phi2"))
    run_and_consolidate(config.with_overrides(engine="sumo"), tmp_path / "headless", 1, None, progress=False,
                        echo=lambda line: None)
    study = LiveStudy(config, tmp_path / "live", ServerOptions(pace=1e4, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            for p in range(config.participants):
                play_in(client, study, ScriptedParticipant(config, p, lockstep=True))
    finally:
        study.close()
    columns = ["satisfied", "junctions", "takeovers", "end_reason", "fallback_fired", "mean_reported_trust",
               "reports", "sim_seconds"]
    headless = read_episodes(tmp_path / "headless").set_index("episode_id")[columns].sort_index()
    live = read_episodes(tmp_path / "live").set_index("episode_id")[columns].sort_index()
    assert headless.equals(live)
    assert headless["takeovers"].sum() > 0 and headless["reports"].sum() > 0   # the test has teeth
    columns = ["episode_id", "index", "directed_road", "action", "incident", "takeover", "performance",
               "reported_trust", "belief_after", "dfa_state"]
    headless_roads, live_roads = read_roads(tmp_path / "headless"), read_roads(tmp_path / "live")
    assert headless_roads[columns].astype(str).equals(live_roads[columns].astype(str))
    headless_ticks, live_ticks = read_kinematics(tmp_path / "headless"), read_kinematics(tmp_path / "live")
    assert headless_ticks.equals(live_ticks)
