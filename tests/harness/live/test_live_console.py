"""The experimenter console's actions: in every phase of a participant's session, each action the
state offers the console (`actions`, the buttons it shows) is accepted by the server, and each it
leaves out is refused with 409, saying why, and changes nothing."""

from __future__ import annotations

import itertools
import threading
import time

import pytest
from fastapi.testclient import TestClient

from trustroute.harness.live.app import live_app
from trustroute.harness.live.protocol import Consent
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.live.session import CONSOLE_ACTIONS

from .conftest import consenting_participant, experimenter, tiny_config

# every action the console has a button for, and the request each button sends
REQUESTS = {"pause": ("control", {"action": "pause"}), "resume": ("control", {"action": "resume"}),
            "abort": ("control", {"action": "abort"}), "link": ("link", None),
            "withdraw": ("withdraw", {"confirm": True})}


class Pipe:
    """The session's end of a running episode's pipe: what the session tells the episode."""

    def __init__(self) -> None:
        self.told: list[dict] = []

    def send(self, control: dict) -> None:
        self.told.append(control)


def into_phase(study: LiveStudy, participant: int, phase: str) -> None:
    """Bring a new participant's session into `phase`: as created, by their consent (agreed or not;
    with the warm-up and every trial done for "done"), by a withdrawal, or after the consent with
    an episode on a pipe of its own for "driving", "paused" (by the experimenter), "disconnected"
    (paused by the participant's disconnect) and "away" (paused by the experimenter, their station
    closed since; no SUMO) or a questionnaire shown, their station connected but in the last two."""
    session = study.sessions[participant]
    if phase in ("consent", "withdrawn"):
        if phase == "withdrawn":
            study.withdraw(participant)
        assert session.phase == phase
        return
    if phase == "done":
        study.done |= {task.episode_id for task in session.tasks}
        session.warmed_up = True
    session.handle(Consent(type="consent", agree=phase != "declined"))
    paused = phase in ("disconnected", "away")
    if phase in ("driving", "paused", "disconnected", "away", "questionnaire"):
        session.phase = "paused" if paused else phase
        session.task, session.connection = session.tasks[0], Pipe()
        session.pause_reason = {"paused": "experimenter", "disconnected": "disconnect",
                                "away": "experimenter"}.get(phase)
        session.push = None if paused else Pipe().send   # their station connected
    assert session.phase == ("paused" if paused else phase)


def test_the_console_is_offered_exactly_what_the_server_accepts_in_every_phase(tmp_path):
    cases = list(itertools.product(CONSOLE_ACTIONS, REQUESTS))
    study = LiveStudy(tiny_config(tmp_path, participants=len(cases)), tmp_path / "study",
                      ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            for phase, action in cases:
                participant = client.post("/api/participants", json={}, headers=headers).json()["participant"]
                into_phase(study, participant, phase)
                shown = client.get(f"/api/participants/{participant}", headers=headers).json()
                assert shown["phase"] == ("paused" if phase in ("disconnected", "away") else phase)
                assert set(shown["actions"]) <= set(REQUESTS), shown["actions"]
                endpoint, body = REQUESTS[action]
                address = f"/api/participants/{participant}/{endpoint}"
                answer = client.post(address, json=body, headers=headers)
                if action in shown["actions"]:
                    assert answer.status_code == 200, (phase, action, answer.text)
                else:
                    assert answer.status_code == 409, (phase, action, answer.text)
                    assert answer.json()["detail"]["detail"].startswith(f"no {action}: "), answer.text
                    after = client.get(f"/api/participants/{participant}", headers=headers).json()
                    assert after == shown, (phase, action)
    finally:
        study.close()



@pytest.mark.parametrize("paused_by, at_station, says", [
    ("disconnect", False, "paused by their disconnect: they resume it at their station"),
    ("disconnect", True, "paused by their disconnect: they resume it at their station"),
    ("experimenter", False, "is not at their station: their paused episode waits for them"),
])
def test_a_paused_episode_is_the_participants_to_resume_after_a_disconnect_or_while_they_are_away(
        paused_by, at_station, says, tmp_path):
    """Resumed by the experimenter, the car would drive with no one at the station, or (a
    disconnect's pause, the participant back) before they pressed Resume, and a disconnect's
    deadline to come back would be lifted; an abort or a withdrawal is still the experimenter's.
    The refusal says which: a participant back at their station is not said to be away."""
    study = LiveStudy(tiny_config(tmp_path, participants=1), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            headers = experimenter(study)
            client.post("/api/participants", json={}, headers=headers)
            into_phase(study, 0, "paused")
            session = study.sessions[0]
            session.pause_reason, session.push = paused_by, Pipe().send if at_station else None
            shown = client.get("/api/participants/0", headers=headers).json()
            assert "resume" not in shown["actions"] and "abort" in shown["actions"]
            answer = client.post("/api/participants/0/control", json={"action": "resume"}, headers=headers)
            assert answer.status_code == 409
            detail = answer.json()["detail"]["detail"]
            assert says in detail, detail
            away = not at_station and paused_by == "experimenter"
            assert ("not at their station" in detail) == away, detail
            told = session.connection.told
            assert (session.phase, session.pause_reason, told) == ("paused", paused_by, [])
    finally:
        study.close()


class SilentPipe(Pipe):
    """A running episode's pipe on which no message comes."""

    def recv(self) -> dict:
        threading.Event().wait()
        return {}


@pytest.fixture
def silent_episodes(monkeypatch):
    """Drives start no SUMO: each episode's process is a pipe on which nothing comes, and the test
    sends the session the episode's messages itself."""
    monkeypatch.setattr("trustroute.harness.live.session.start_episode_process",
                        lambda *args: (None, SilentPipe()))


def created(client: TestClient, study: LiveStudy):
    """The experimenter's headers, and a participant the console creates, with their session."""
    headers = experimenter(study)
    participant = client.post("/api/participants", json={}, headers=headers).json()["participant"]
    return headers, participant, study.sessions[participant]


def test_the_console_counts_the_reports_and_takeovers_of_the_drive_shown(tmp_path, silent_episodes):
    """The console shows the reports and takeovers beside the drive's episode: those of that
    drive, not of the warm-up and trials before it."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            headers, participant, session = created(client, study)
            session.handle(Consent(type="consent", agree=True))
            session.start(session.warm_up, None)
            session.on_episode_message({"type": "mode", "mode": "manual", "t": 1.0})
            session.reports += 1
            assert session.progress()["takeovers"] == 1 and session.progress()["reports"] == 1
            session.start(session.tasks[0], None)
            shown = client.get(f"/api/participants/{participant}", headers=headers).json()
            assert (shown["episode_id"], shown["reports"], shown["takeovers"]) == \
                (session.tasks[0].episode_id, 0, 0)
    finally:
        study.close()


def test_between_drives_the_state_shows_no_drive_and_says_which_trial_is_done(tmp_path, monkeypatch,
                                                                              silent_episodes):
    """The console's row follows the state: while a drive runs it shows the drive (its episode and
    road) and which trial it is ("driving 1 of 2"); once the drive has ended, no episode, mode,
    road or counts of it (the mode: autopilot), and how many trials are done ("1 of 2 done"), never
    the same "1 of 2" during the trial and after it."""
    config = tiny_config(tmp_path, specs=("phi1", "phi2"))
    study = LiveStudy(config, tmp_path / "study", ServerOptions()).open()
    monkeypatch.setattr(study, "episode_finished", lambda task: study.done.add(task.episode_id))
    drive = ("episode_id", "road", "reports", "takeovers")
    try:
        with TestClient(live_app(study)) as client:
            headers, participant, session = created(client, study)

            def shown() -> dict:
                return client.get(f"/api/participants/{participant}", headers=headers).json()

            session.handle(Consent(type="consent", agree=True))
            assert shown()["trial_status"] == "0 of 2 done"
            for task, during, after in ((session.warm_up, "driving the warm-up", "0 of 2 done"),
                                        (session.tasks[0], "driving 1 of 2", "1 of 2 done"),
                                        (session.tasks[1], "driving 2 of 2", "2 of 2 done")):
                session.start(task, None)
                session.on_episode_message({"type": "frame", "road": "A-B"})
                state = shown()
                assert (state["trial_status"], state["episode_id"], state["road"], state["mode"]) == \
                    (during, task.episode_id, "A-B", "auto")
                if task is session.tasks[1]:
                    client.post(f"/api/participants/{participant}/control", json={"action": "pause"},
                                headers=headers)
                    assert shown()["trial_status"] == "paused in 2 of 2"
                session.on_episode_message({"type": "episode_end"})
                state = shown()
                assert state["phase"] in ("ready", "done") and state["trial_status"] == after
                assert [state[field] for field in drive] == [None] * len(drive), state
                assert state["mode"] == "auto"
    finally:
        study.close()


def start_driving(station) -> None:
    """The participant's station, once ready, starts the drive and sees it driving."""
    while station.receive_json().get("phase") != "ready":
        pass
    station.send_json({"type": "start", "trust": 4})
    while station.receive_json().get("phase") != "driving":
        pass


def test_a_station_opened_during_a_disconnect_pause_is_sent_the_drives_last_frame(tmp_path, silent_episodes):
    """No frame streams while a drive is paused: a station that connects then is sent, after the
    state, the drive's newest frame (`Session.opening`), so it shows where the car stands before
    the participant resumes; without it the reopened view stayed empty until the resume."""
    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)) as client:
            with consenting_participant(client, study) as (station, participant):
                start_driving(station)
                session = study.sessions[0]
                frames = [{"type": "frame", "t": t, "road": "A-B", "x": t, "y": 0.0} for t in (1.0, 2.0)]
                for frame in frames:   # the episode's (it sends none once paused)
                    session.on_episode_message(frame)
            deadline = time.monotonic() + 10
            while session.phase != "paused":   # the closed socket paused the drive
                assert time.monotonic() < deadline, session.phase
                time.sleep(0.02)
            with client.websocket_connect("/ws", headers=participant) as station:
                assert station.receive_json()["type"] == "welcome"
                state = station.receive_json()
                assert (state["phase"], state["paused_by"]) == ("paused", "disconnect")
                station.send_json({"type": "ping"})
                assert station.receive_json() == frames[-1]
                assert station.receive_json() == {"type": "pong"}
                assert session.phase == "paused"   # shown, not resumed
    finally:
        study.close()


def test_a_station_opened_as_the_drive_ends_is_told_the_end_after_the_drives_state(tmp_path, monkeypatch,
                                                                                 silent_episodes):
    """A station that connects while the drive ends gets what it is sent first (the state) and
    what the episode pushes to it in the order they happened: the drive's state, its
    `episode_end`, then the next phase's; never the next phase's state before the end of the drive
    (the station says how the drive ended, its end's `station`, above the step the state after it
    shows).
    Here the episode's end is read the moment the new station's connection is attached."""
    from trustroute.harness.live.session import Session

    study = LiveStudy(tiny_config(tmp_path), tmp_path / "study", ServerOptions()).open()
    attach = Session.attach

    def ended_as_attached(session: Session, push):
        attached = attach(session, push)
        reader = threading.Thread(target=session.on_episode_message, args=({"type": "episode_end"},))
        reader.start()   # the episode's reader thread, as it reads the drive's end
        reader.join(10)
        return attached

    try:
        with TestClient(live_app(study)) as client:
            with consenting_participant(client, study) as (station, participant):
                start_driving(station)
                monkeypatch.setattr(Session, "attach", ended_as_attached)
                with client.websocket_connect("/ws", headers=participant) as again:
                    seen: list[tuple] = []
                    while not seen or seen[-1] != ("state", "ready"):
                        message = again.receive_json()
                        if message["type"] in ("state", "episode_end"):
                            seen.append((message["type"], message.get("phase")))
                    assert seen == [("state", "driving"), ("episode_end", None), ("state", "ready")], seen
    finally:
        study.close()


def test_the_state_says_the_trial_in_the_participants_words_too(tmp_path, silent_episodes):
    """Beside the console's `trial_status`, the state carries the station's texts (`station`):
    the status line and the start step's sentence."""
    config = tiny_config(tmp_path, specs=("phi1", "phi2"))
    study = LiveStudy(config, tmp_path / "study", ServerOptions()).open()
    try:
        with TestClient(live_app(study)):
            session = study.sessions[study.create_participant("")[0]]
            assert session.progress()["station"] == {"status": "", "next": None}
            session.handle(Consent(type="consent", agree=True))
            assert session.progress()["station"] == {
                "status": "Warm-up drive", "next": "Next: a warm-up drive, to get to know the vehicle."}
            session.start(session.warm_up, None)
            assert session.progress()["station"] == {"status": "Warm-up drive", "next": None}
            session.on_episode_message({"type": "episode_end"})
            assert session.progress()["station"] == {"status": "Trial 1 of 2 is next",
                                                     "next": "Next: trial 1 of 2."}
            session.start(session.tasks[0], None)
            session.phase = "paused"
            assert session.progress()["station"] == {"status": "Trial 1 of 2", "next": None}
    finally:
        study.close()


# Each way an episode ends (its last message, as harness/live/worker.py and Session.control and
# Session.expire have it) and what the station is told of the warm-up's end and of a trial's.
ENDS = [({"type": "episode_aborted", "reason": "aborted by the experimenter"},
         "The warm-up drive was stopped by the experimenter; it will be run again.",
         "Trial 1 of 2 was stopped by the experimenter; it will be run again."),
        ({"type": "episode_aborted", "reason": "incomplete: no reconnection within 120 s"},
         "The warm-up drive was stopped: the connection was lost for too long. It will be run again.",
         "Trial 1 of 2 was stopped: the connection was lost for too long. It will be run again."),
        ({"type": "episode_failed", "error": "RuntimeError: SUMO stopped"},
         "The warm-up drive failed for a technical reason; it will be run again.",
         "Trial 1 of 2 failed for a technical reason; it will be run again."),
        ({"type": "episode_end", "satisfied": True, "end_reason": "goal", "junctions": 3, "takeovers": 0},
         "The warm-up drive is complete.", "Trial 1 of 2 is complete.")]


@pytest.mark.parametrize(("end", "warm_up_said", "trial_said"), ENDS,
                         ids=["aborted", "incomplete", "failed", "done"])
def test_the_station_is_told_how_the_warm_up_and_each_trial_ended(tmp_path, monkeypatch, silent_episodes,
                                                                 end, warm_up_said, trial_said):
    """The episode's end reaches the station with what the station says of it (`station`), by the
    server's one rule for the drive's words: the warm-up's end names the warm-up, a trial's names
    the trial, whether the drive completed, was stopped by the experimenter, ended incomplete (no
    reconnection in time) or failed; the traceback of a failure stays on the server."""
    config = tiny_config(tmp_path, specs=("phi1", "phi2"))
    study = LiveStudy(config, tmp_path / "study", ServerOptions()).open()
    monkeypatch.setattr(study, "episode_finished", lambda task: study.done.add(task.episode_id))
    try:
        with TestClient(live_app(study)):
            session = study.sessions[study.create_participant("")[0]]
            session.handle(Consent(type="consent", agree=True))
            pushed: list[dict] = []
            session.push = pushed.append
            for task, said in ((session.warm_up, warm_up_said), (session.tasks[0], trial_said)):
                session.start(task, None)
                session.on_episode_message({**end, "episode_id": task.episode_id, "traceback": "Traceback"})
                assert pushed[-2] == {**end, "episode_id": task.episode_id, "station": said}
                assert pushed[-1]["type"] == "state" and pushed[-1]["phase"] == "ready"
                session.warmed_up = True   # whatever its end, the next drive here is the first trial
    finally:
        study.close()
