"""A hand-back answering the episode's warning is never refused. The server checks a hand-back
against the mode the episode last told it of (harness/live/session.py), so in the step a takeover
comes within the warning's distance of the road's end, the mode must reach the session before the
warning does: a participant who answers the warning at once, before the server has read the next
message from the episode, would otherwise be refused, and the ego would wait short of the
junction for a hand-back that no longer comes. Nor is a hand-back that comes a moment after the
episode's own at the commit point: it is done already, and acknowledged as such."""

from __future__ import annotations

import pytest

from trustroute.harness.live.protocol import MessageError, parse_client_message
from trustroute.harness.live.session import Session
from trustroute.harness.live.worker import LiveOptions, RemoteDriver
from trustroute.harness.simulation.episode import COMMIT_DISTANCE
from trustroute.harness.simulation.manual_driving import WARN_DISTANCE
from trustroute.harness.study.context import study_context
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_planned_episode

from .conftest import tiny_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]


class Relay:
    """The episode's pipe with the server's reader on the other end: each message the episode
    sends goes to the session as it is sent, and each control the session tells the episode is
    read from here. The participant answers within the session's push, so a warning is answered
    before the reader takes the message after it: the closest the two can come."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self.controls: list[dict] = []   # told by the session, for the episode to read
        self.sent: list[dict] = []       # sent by the episode
        self.answered: list[dict] = []   # the warnings the participant answered
        session.connection, session.push = SessionEnd(self.controls), self.participant

    # the episode's end
    def send(self, message: dict) -> None:
        self.sent.append(message)
        self.session.on_episode_message(message)

    def poll(self, timeout: float = 0.0) -> bool:
        return bool(self.controls)

    def recv(self) -> dict:
        return self.controls.pop(0)

    def participant(self, message: dict) -> None:
        if message["type"] == "warning" and message["kind"] == "hand_back":
            self.answered.append(message)
            self.session.handle(parse_client_message('{"type": "hand_back"}'))   # refused: MessageError


class SessionEnd:
    """The session's end of the pipe (Session.tell): a control is queued for the episode."""

    def __init__(self, controls: list[dict]) -> None:
        self.controls = controls

    def send(self, control: dict) -> None:
        self.controls.append(control)


def running_episode(tmp_path, study, relay_type):
    """(config, task, session, relay, driver) of one participant's first episode, its session
    driving it, the participant's side `relay_type` (a Relay)."""
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    session = Session(study, task.participant, [task], consented=False)
    session.phase, session.task = "driving", task   # the session of the running episode
    relay = relay_type(session)
    driver = RemoteDriver(relay, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, client="scripted"),
                          episode_id=task.episode_id)
    return config, task, session, relay, driver


def test_a_takeover_near_the_road_end_reaches_the_session_before_its_warning(tmp_path):
    config, task, session, relay, driver = running_episode(tmp_path, None, Relay)
    taken: list[str] = []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        # the takeover is asked for inside the warning's distance, well before the commit point
        room = sumo.lane.getLength(ego.lane) - ego.lane_position if ego.road == road else 0.0
        if not taken and mode == "auto" and COMMIT_DISTANCE + 40.0 < room < WARN_DISTANCE - 20.0:
            taken.append(road)
            session.handle(parse_client_message('{"type": "takeover"}'))

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver)
    (warning,) = relay.answered
    manual = next(m for m in relay.sent if m["type"] == "mode" and m["mode"] == "manual")
    assert warning["t"] == manual["t"]   # warned in the step the takeover was applied
    assert relay.sent.index(manual) < relay.sent.index(warning)
    assert [e["type"] for e in driver.events] == ["takeover", "hand_back"]
    ticks = record.kinematics
    first_manual = ticks["time"][ticks["mode"] == "manual"].min()
    back = ticks["time"][(ticks["mode"] == "auto") & (ticks["time"] > first_manual)].min()
    assert back - first_manual <= 2.0   # handed back at once, not held short of the junction


class NoStudy:
    """The study of a session run without a server: no trial of it is done yet."""

    def is_done(self, task) -> bool:
        return False


class LateParticipant(Relay):
    """A participant who does not answer the warning but hands back a moment after the episode has
    handed back on its own (their hand-back crosses the episode's mode change on the way)."""

    def __init__(self, session: Session) -> None:
        super().__init__(session)
        self.replies: list[list[dict]] = []   # the server's replies to each hand-back

    def participant(self, message: dict) -> None:
        if message["type"] == "mode" and message["mode"] == "auto":
            for _ in range(2):   # the late hand-back, then the same again
                try:
                    self.replies.append(self.session.handle(parse_client_message('{"type": "hand_back"}')))
                except MessageError as exc:
                    self.replies.append([exc.reply])


def test_a_hand_back_just_after_the_episodes_own_is_done_not_refused(tmp_path):
    config, task, session, relay, driver = running_episode(tmp_path, NoStudy(), LateParticipant)
    taken: list[str] = []

    def observe(sumo, ego, mode, road):
        # a takeover applied in the next step, too close to the commit point to stop before it (the
        # hold brakes at 3 m/s^2), but not in the step that reaches it (that one is carried to the
        # next road): the episode hands back at the commit point
        room = sumo.lane.getLength(ego.lane) - ego.lane_position if ego.road == road else 0.0
        ahead = room - COMMIT_DISTANCE - ego.speed   # before the commit point after this step and the next
        if not taken and mode == "auto" and ego.speed > 8.0 and 2.0 < ahead < 8.0:
            taken.append(road)
            session.handle(parse_client_message('{"type": "takeover"}'))
        driver.observe(sumo, ego, mode, road)

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver)
    modes = [(m["mode"], m["t"]) for m in relay.sent if m["type"] == "mode"]
    assert [mode for mode, _ in modes] == ["manual", "auto"]
    late, again = relay.replies
    assert [(reply["type"], reply.get("mode")) for reply in late] == [("state", "auto")]   # done, no error
    assert [reply.get("code") for reply in again] == ["out_of_order"]   # asked twice: out of order
    assert [e["type"] for e in driver.events] == ["takeover"]   # the episode was told nothing more
    (row,) = record.incidents[record.incidents["takeover"]].to_dict("records")
    assert (row["takeover_start"], row["takeover_end"]) == (modes[0][1], modes[1][1])


class EndingStudy(NoStudy):
    """The study of a session run without a server, without questionnaires, whose trials are done
    when their episode ends."""

    questionnaires: dict[str, list] = {"before": [], "after_each_trial": [], "end": []}
    study_dir = None

    def __init__(self) -> None:
        self.done: set[str] = set()

    def is_done(self, task) -> bool:
        return task.episode_id in self.done

    def attempt_ended(self, task, message: dict) -> None:
        pass

    def episode_finished(self, task) -> None:
        self.done.add(task.episode_id)


def answers(session: Session, kind: str) -> list[dict]:
    """The server's replies to a participant's `kind` message (its error, when refused)."""
    try:
        return session.handle(parse_client_message(f'{{"type": "{kind}"}}'))
    except MessageError as exc:
        return [exc.reply]


@pytest.mark.parametrize("end", [
    {"type": "episode_end", "episode_id": "", "satisfied": True, "end_reason": "goal", "junctions": 3,
     "takeovers": 1},
    {"type": "episode_aborted", "episode_id": "", "reason": "aborted by the experimenter"},
    {"type": "episode_failed", "episode_id": "", "error": "SUMO stopped"},
])
@pytest.mark.parametrize("switched_back", [False, True])
def test_a_hand_back_after_the_drive_has_ended_is_done_not_refused(tmp_path, end, switched_back):
    """A person in control whose drive ends (at its goal, aborted, failed) as they hand back: the
    drive's end took the car from them, so their hand-back, arriving after it, is done already and
    acknowledged with the state of the phase after the drive; so is one that crossed the junction's
    own hand-back and then the end. Asked twice, or with no takeover in the drive, it is out of
    order, as is a takeover outside a drive."""
    config = tiny_config(tmp_path, participants=1, specs=("phi1", "phi2"))
    first, second = plan_episodes(config)[:2]
    session = Session(EndingStudy(), first.participant, [first, second], consented=True)
    told: list[dict] = []

    def drive(task, takeover: bool) -> None:
        session.phase, session.task, session.asked, session.mode = "driving", task, "auto", "auto"
        session.switched_unasked, session.connection = False, SessionEnd(told)
        if takeover:
            answers(session, "takeover")
            session.on_episode_message({"type": "mode", "mode": "manual", "t": 10.0})
        if switched_back:   # the episode's own hand-back at the junction
            session.on_episode_message({"type": "mode", "mode": "auto", "t": 20.0})
        session.on_episode_message({**end, "episode_id": task.episode_id})

    drive(first, takeover=True)
    late, again, takeover = (answers(session, kind) for kind in ("hand_back", "hand_back", "takeover"))
    assert [(r["type"], r.get("phase"), r.get("mode")) for r in late] == [("state", "ready", "auto")]
    assert [reply.get("code") for reply in again + takeover] == ["out_of_order", "out_of_order"]
    assert told == [{"type": "takeover"}]   # no episode was told of the late hand-back
    drive(second, takeover=False)   # on autopilot throughout: a hand-back after it is no answer to anything
    assert [reply.get("code") for reply in answers(session, "hand_back")] == ["out_of_order"]
