"""Manual driving in a live episode, through the websocket: a scripted participant drives every
road by hand (takeover, accelerator, hand-back) and passes an obstacle through the oncoming lane
when it pulls out; while the person is in control and has not pulled out, SUMO does not pass the
obstacle on its own: the ego waits behind it."""

from __future__ import annotations

import pandas as pd
import pytest
from fastapi.testclient import TestClient

from trustroute.core.dataset import read_incidents, read_kinematics
from trustroute.harness.live.app import live_app
from trustroute.harness.live.scripted import ScriptedParticipant
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.parts import read_part

from .conftest import tiny_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


def play_in(client: TestClient, study: LiveStudy, player: ScriptedParticipant) -> ScriptedParticipant:
    """A new participant of `study`, played by `player` to the end through the websocket of
    `client` (a TestClient of the study's app)."""
    headers = {"Authorization": f"Bearer {study.experimenter_token}"}
    token = client.post("/api/participants", json={}, headers=headers).json()["token"]
    with client.websocket_connect("/ws", headers={"Authorization": f"Bearer {token}"}) as socket:
        while not player.finished:
            for reply in player.respond(socket.receive_json()):
                socket.send_json(reply)
    return player


def play(tmp_path, player: ScriptedParticipant, pace: float = 20.0) -> ScriptedParticipant:
    """One participant's session (no warm-up) at `pace`, played to the end through the websocket."""
    study = LiveStudy(player.config, tmp_path / "study", ServerOptions(pace=pace, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            return play_in(client, study, player)
    finally:
        study.close()


def obstacle_roads(study_dir) -> list[tuple[str, float, float, pd.DataFrame]]:
    """(road, its ticks on the road, its ticks on the oncoming road) of every obstacle road, while
    its obstacle stood."""
    incidents = read_incidents(study_dir)
    ticks = read_kinematics(study_dir)
    ticks["edge"] = ticks["lane"].str.rsplit("_", n=1).str[0]
    found = []
    for row in incidents[incidents["incident"] == "obstacle"].itertuples():
        u, v = row.directed_road.split("-")
        during = ticks[(ticks["episode_id"] == row.episode_id) & (ticks["time"] >= row.injected_time)
                       & (ticks["time"] <= row.removed_time)]
        found.append((row.directed_road, during[during["edge"] == row.directed_road],
                      during[during["edge"] == f"{v}-{u}"]))
    return found


def test_a_scripted_participant_passes_an_obstacle_by_hand_through_the_oncoming_lane(tmp_path):
    config = tiny_config(tmp_path, participants=1, specs=("phi2",))
    # Pace 5, as below. At pace 20 the takeover sent as each road opens has under a second of the
    # wall clock to reach the episode before the autopilot reaches the obstacle, and a frame stands
    # for 0.8 s of driving: a takeover could land during the autopilot's pull-out, or the frame
    # back in the own lane be missed before the road ends, and the manual excursions into the
    # oncoming lane then differ from the passes the person counted.
    player = play(tmp_path, ScriptedParticipant(config, 0, by_hand=True), pace=5.0)
    study_dir = tmp_path / "study"
    assert player.finished and player.passes >= 1
    assert [e for e in player.errors if e["code"] != "out_of_order"] == []
    excursions = [(road, oncoming) for road, _, oncoming in obstacle_roads(study_dir) if len(oncoming)]
    # A pass the person starts is theirs to the end: every tick of it in the oncoming lane is manual.
    # (Where the hand-back warning came before the obstacle was in reach, the person handed back
    # first and the autopilot passed it: every tick of that excursion is the autopilot's.)
    by_hand = [road for road, oncoming in excursions if "manual" in set(oncoming["mode"])]
    assert len(by_hand) == player.passes
    for road, oncoming in excursions:
        assert set(oncoming["mode"]) in ({"manual"}, {"auto"}), road
    events = read_part(study_dir / "parts" / f"{config_episode(config)}.zip").summary["live"]["events"]
    kinds = [(e["type"], e.get("pedal") or e.get("lane")) for e in events]
    assert {("steer", "oncoming"), ("drive", "accelerate"), ("drive", "release")} <= set(kinds)


def test_in_control_without_a_pull_out_the_ego_waits_behind_the_obstacle(tmp_path):
    config = tiny_config(tmp_path, participants=1, specs=("phi2",))
    # Pace 5: the takeover sent as the road opens must reach the episode before the autopilot
    # reaches the obstacle and pulls out itself, about a second of the wall clock at pace 10: in
    # the suite, beside Chromium and the CPU-bound lane, it arrived later than that once in a few
    # runs (the autopilot's pull-out, then the person's takeover in the oncoming lane).
    player = play(tmp_path, ScriptedParticipant(config, 0, by_hand=True, pull_out=False), pace=5.0)
    assert player.finished and player.passes == 0
    roads = obstacle_roads(tmp_path / "study")
    assert roads
    for road, own, oncoming in roads:
        waiting = own[(own["mode"] == "manual") & (own["speed"] < 0.1)]
        assert len(waiting), road   # it stood still behind the obstacle while the person drove
        assert set(oncoming["mode"]) <= {"auto"}, road   # and passed it after the hand-back
        assert oncoming["time"].min() > waiting["time"].max(), road


def config_episode(config) -> str:
    from trustroute.harness.study.plan import plan_episodes

    (task,) = plan_episodes(config)
    return task.episode_id
