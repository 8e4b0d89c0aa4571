"""Every trust report on the road it answers, none dropped: a person-like participant answers each
prompt a little after it comes (the next road is open by then, or the car has arrived), over the
websocket of a served study; the roads table holds each answer on the prompt's own road."""

from __future__ import annotations

import json
import time

import pandas as pd
import pytest

from trustroute.core.dataset import read_roads
from trustroute.harness.live.scripted import ScriptedParticipant, run_scripted
from trustroute.harness.live.server import LiveStudy, ServerOptions

from .conftest import serving, tiny_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


def answer(road: int) -> int:
    return 1 + road % 7


def drive_like_a_person(url: str, token: str, delay: float, timeout: float = 120.0) -> dict[str, dict]:
    """Consent, start every drive, answer each prompt `delay` wall seconds after it came, and one
    report outside any prompt per drive. {episode id: {road index: answer}} of every prompt."""
    from websockets.sync.client import connect

    answered: dict[str, dict[int, int]] = {}
    due: list[tuple[float, dict]] = []
    deadline = time.monotonic() + timeout
    with connect(url, additional_headers={"Authorization": f"Bearer {token}"}) as socket:
        while time.monotonic() < deadline:
            while due and due[0][0] <= time.monotonic():
                socket.send(json.dumps(due.pop(0)[1]))
            try:
                message = json.loads(socket.recv(timeout=0.02))
            except TimeoutError:
                continue
            kind = message["type"]
            if kind == "state" and message["phase"] == "consent":
                socket.send(json.dumps({"type": "consent", "agree": True}))
            elif kind == "state" and message["phase"] == "ready":
                socket.send(json.dumps({"type": "start", "trust": 4}))
            elif kind == "state" and message["phase"] == "done":
                return answered
            elif kind == "episode_start":
                due.append((time.monotonic() + delay / 2, {"type": "trust", "value": 7}))   # no prompt
            elif kind == "road" and message["prompt"]:
                prompt = message["prompt"]
                answered.setdefault(prompt["episode_id"], {})[prompt["road"]] = answer(prompt["road"])
                due.append((time.monotonic() + delay, {"type": "trust", "value": answer(prompt["road"]),
                                                        "prompt": prompt}))
    raise AssertionError("the participant did not finish in time")


def reported_by_road(study_dir) -> dict[str, dict[int, int]]:
    roads = read_roads(study_dir)
    found: dict[str, dict[int, int]] = {}
    for row in roads.itertuples():
        if not pd.isna(row.reported_trust):
            found.setdefault(row.episode_id, {})[int(row.index)] = int(row.reported_trust)
    return found


# (pace, wall seconds to answer): a person answers 2 simulated seconds after the prompt, as at a
# person's pace (1) 2 s later, and 14 at pace 20, late enough that the car is on the next road or
# has arrived. Pace 4 keeps the drive to about 13 s of wall time (at pace 1, a minute of waiting);
# the station at a person's pace is driven by tests/harness/live/test_browser_wheel.py.
@pytest.mark.parametrize(("pace", "delay"), [(4.0, 0.5), (20.0, 0.7)])
def test_every_answer_is_on_its_own_road_at_any_pace(tmp_path, pace, delay):
    config = tiny_config(tmp_path, participants=1)
    options = ServerOptions(pace=pace, warm_up=False, final_report_seconds=10.0)
    study = LiveStudy(config, tmp_path / "study", options).open()
    try:
        with serving(study) as (host, port):
            _, token = study.create_participant()
            answered = drive_like_a_person(f"ws://{host}:{port}/ws", token, delay, timeout=600.0)
    finally:
        study.close()
    assert answered and all(len(prompts) >= 2 for prompts in answered.values())
    assert reported_by_road(tmp_path / "study") == answered


def test_the_scripted_participants_reports_are_on_their_roads(tmp_path):
    config = tiny_config(tmp_path, participants=1, specs=("phi1", "phi2"))
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=1000.0, warm_up=False)).open()
    sent: dict[str, dict[int, int]] = {}

    class Recording(ScriptedParticipant):
        def report_on(self, road: dict) -> list[dict]:
            replies = super().report_on(road)
            for reply in replies:
                sent.setdefault(reply["prompt"]["episode_id"], {})[reply["prompt"]["road"]] = reply["value"]
            return replies

    try:
        with serving(study) as (host, port):
            _, token = study.create_participant()
            participant = Recording(config, 0)
            participant.tasks = participant.tasks[1:]   # no warm-up on this server
            run_scripted(f"ws://{host}:{port}/ws", token, participant, 120)
    finally:
        study.close()
    assert len(sent) == 2 and reported_by_road(tmp_path / "study") == sent


def test_a_report_on_a_prompt_never_asked_is_refused(tmp_path):
    """A report may name a prompt of this episode that has been asked (however late), or none; one
    naming a road not asked about (a road to come, or none of the route's) is `out_of_order` and
    reaches no episode."""
    from fastapi.testclient import TestClient

    from trustroute.harness.live.app import live_app

    from .test_live_episode import receive_until

    config = tiny_config(tmp_path, participants=1)
    study = LiveStudy(config, tmp_path / "study", ServerOptions(pace=20.0, warm_up=False)).open()
    headers = {"Authorization": f"Bearer {study.create_participant()[1]}"}
    try:
        with TestClient(live_app(study)) as client, client.websocket_connect("/ws", headers=headers) as ws:
            ws.send_json({"type": "consent", "agree": True})
            ws.send_json({"type": "start", "trust": 4})
            episode = receive_until(ws, lambda m: m["type"] == "episode_start")["episode_id"]

            def refused(road: int) -> dict:
                prompt = {"episode_id": episode, "road": road}
                ws.send_json({"type": "trust", "value": 7, "prompt": prompt})
                return receive_until(ws, lambda m: m["type"] == "error")

            assert refused(50)["code"] == "out_of_order"
            prompt = receive_until(ws, lambda m: m["type"] == "road" and m["prompt"])["prompt"]
            ahead = refused(prompt["road"] + 1)
            assert ahead["code"] == "out_of_order" and f"road {prompt['road'] + 1}" in ahead["detail"]
            ws.send_json({"type": "trust", "value": 2, "prompt": prompt})
            ws.send_json({"type": "ping"})
            assert receive_until(ws, lambda m: m["type"] in ("pong", "error"))["type"] == "pong"
            assert study.sessions[0].reports == 1
    finally:
        study.close()
