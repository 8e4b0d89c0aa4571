"""The scripted participant: a synthetic driver that takes part in a live study over the websocket.

It speaks the participant's protocol (harness/live/protocol.py) and nothing else: it consents,
starts each trial with its true trust, takes over when its driver model says so at the moment an
incident comes into view, and after each road moves its trust on what it observed (incident,
takeover, the AV's performance) and reports it every `report_every` roads, all with the planned
episode's driver (the participant's model, the task's Generator: harness/study/runner.py's
`run_planned_episode`). It drives the live path end to end without a person: the tests and the
benchmark use it. With `by_hand` it drives every road by hand instead (a takeover as each road opens, a
brief press of the accelerator, a pull-out into the oncoming lane when an obstacle comes into view,
the hand-back on the warning): the manual-driving path of the station, without a person. In
control after a takeover it passes an obstacle ahead through the oncoming lane, as a synthetic
driver's manual driving style does in a headless episode.
`ScriptedParticipant.respond` is the logic (message in, replies out);
`run_scripted` connects it to a server.

In lockstep it keeps within the server's flood limit: `respond` waits before returning replies
that would exceed a client-side token bucket kept well inside the server's
(harness/live/protocol.py BURST, RATE). The episode waits for every answer there, so waiting
loses nothing, while an answer refused as a flood would stall it; a refusal in lockstep is
therefore raised (`LockstepRefused`) rather than waited on. Outside lockstep it answers at once,
as a person does (the episode drives on meanwhile, and a late takeover or hand-back would come
too late), except its trust reports: those keep within the same bucket, since each names the
prompt it answers and lands on that road whenever it comes, while at a fast pace (the tests'
1000) a whole trial's reports come within a second and the server would refuse most of them,
the last road's too, whose answer the trial's end then waits for in vain (`final_report_seconds`).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

from trustroute.harness.live.protocol import BURST, RATE, TokenBucket
from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.context import StudyContext, study_context
from trustroute.harness.study.plan import EpisodeTask, plan_episodes
from trustroute.networks.road import Road

# The client's own limit: half the server's burst and 80 % of its rate, so that messages sent
# apart but read back to back by the server (a busy event loop) still fit the server's bucket.
CLIENT_BURST = BURST // 2
CLIENT_RATE = 0.8 * RATE
PING_SECONDS = 20.0   # a ping after this long without a message (the server's idle timeout is longer)


class LockstepRefused(RuntimeError):
    """The server refused an answer that a lockstep episode waits for."""


def client_bucket() -> TokenBucket:
    return TokenBucket(burst=CLIENT_BURST, rate=CLIENT_RATE)


@dataclass
class ScriptedParticipant:
    """Participant `participant` of `config`, played by its synthetic drivers."""

    config: StudyConfig
    participant: int
    lockstep: bool = False   # the episodes wait for every answer: they run as headless ones do
    by_hand: bool = False    # drive every road by hand (not with lockstep)
    pull_out: bool = True    # by hand: pass an obstacle through the oncoming lane (else wait
                             # behind it and hand back)
    mode: str = "auto"
    pedal: str = "release"
    passing: bool = False            # by hand: pulled out to pass an obstacle
    pass_lane: str | None = None     # the oncoming lane it was seen in
    warned: bool = False
    passes: int = 0                  # obstacles passed by hand
    tasks: list[EpisodeTask] = field(default_factory=list)
    driver: Any = None   # the current trial's SyntheticDriver
    finished: bool = False
    acted_on: tuple = ()
    errors: list[dict] = field(default_factory=list)
    bucket: TokenBucket = field(default_factory=client_bucket)
    sleep: Any = time.sleep
    episodes: list[dict] = field(default_factory=list)
    takeovers: int = 0
    reports: int = 0

    def __post_init__(self) -> None:
        from trustroute.harness.live.server import warm_up_task

        trials = sorted((t for t in plan_episodes(self.config) if t.participant == self.participant),
                        key=lambda t: t.position)
        self.tasks = [warm_up_task(self.config, self.participant), *trials]

    @cached_property
    def context(self) -> StudyContext:
        """The study's context, built once for this participant's drivers (it plays in a process of
        its own, or beside the server: either way it holds its own)."""
        return study_context(self.config)

    def new_driver(self, task: EpisodeTask):
        from trustroute.app.drivers import synthetic_driver

        model = self.context.driver_model(task.participant)
        return synthetic_driver(model, task.driver_rng(), report_accuracy=self.config.report_accuracy)

    def respond(self, message: dict) -> list[dict]:
        """The replies to one server message, each counted against the client's flood limit; in
        lockstep, and for a trust report, no faster than that limit allows."""
        replies = self.replies_to(message)
        for reply in replies:
            if self.lockstep or reply["type"] == "trust":
                while (wait := self.bucket.seconds_to_next()) > 0.0:
                    self.sleep(wait)
            self.bucket.take()
        return replies

    def replies_to(self, message: dict) -> list[dict]:
        kind = message.get("type")
        if message.get("predicted"):
            return []   # a frame between steps: it acts on the simulation's state only
        if kind == "state":
            return self.on_state(message)
        if self.by_hand and kind in ("road", "mode", "frame", "warning"):
            return self.drive_by_hand(message) + (self.report_on(message) if kind == "road" else [])
        if kind in ("mode", "frame") and not self.lockstep:
            return self.pass_when_in_control(message)
        if kind == "incident" and self.driver is not None:
            if self.driver.decides_takeover(message["kind"]):
                self.takeovers += 1
                return [{"type": "takeover"}]
            if self.lockstep:
                return [{"type": "pass"}]
        elif kind == "road":
            return self.report_on(message)
        elif kind == "warning" and message["kind"] == "hand_back":
            return [{"type": "hand_back"}]   # the rule of the study: hand back before the junction
        elif kind == "episode_end":
            self.episodes.append(message)
            self.driver = None
        elif kind == "error":
            self.errors.append(message)
            if self.lockstep and message.get("code") == "rate_limited":
                raise LockstepRefused(f"the server refused a lockstep answer: {message}")
        return []

    def report_on(self, road: dict) -> list[dict]:
        """The driver's trust moves on what the road showed; a report when the road prompts."""
        if self.driver is None:
            return []
        self.driver.move_trust(road["incident"], road["takeover"], road["performance"])
        if not road["prompt"]:
            return []
        self.reports += 1
        return [{"type": "trust", "value": int(self.driver.report_trust()), "prompt": road["prompt"]}]

    def drive_by_hand(self, message: dict) -> list[dict]:
        """Take over as each road opens; once in control, a brief press of the accelerator; an
        obstacle in view: pull out, and hand back once past it (back in the own lane after the
        oncoming one), or without `pull_out` hand back once stopped behind it (with it too once
        stopped there after the hand-back warning, the pull-out not begun); otherwise hand back on
        the warning. A pass is counted for every stay in the oncoming lane while in control, one the
        autopilot began included (the takeover landed during its pull-out)."""
        kind = message["type"]
        if kind == "mode":
            self.mode = message["mode"]
            if self.mode == "manual":
                self.pedal = "accelerate"
                return [{"type": "drive", "pedal": "accelerate"}]
        elif kind == "road":
            if self.pass_lane is not None:
                self.passes += 1   # the road ended before a frame showed the ego back in its lane
            self.passing = self.warned = False
            self.pass_lane = None
            if self.mode == "auto":
                self.takeovers += 1
                return [{"type": "takeover"}]
        elif kind == "warning":
            self.warned = True
            if not self.passing and self.mode == "manual":
                return [{"type": "hand_back"}]
        elif kind == "frame" and self.mode == "manual":
            return self.manual_frame(message)
        return []

    def pass_when_in_control(self, message: dict) -> list[dict]:
        """In control after a takeover (not driving by hand): an obstacle ahead in the lane is
        passed through the oncoming lane, as the synthetic driver's manual driving style passes it
        in a headless episode (a live episode leaves that pull-out to the person)."""
        if message["type"] == "mode":
            self.mode, self.passing = message["mode"], False
            return []
        if self.mode != "manual" or self.passing:
            return []
        if obstacle_ahead(message):
            self.passing = True
            return [{"type": "steer", "lane": "oncoming"}]
        return []

    def manual_frame(self, frame: dict) -> list[dict]:
        replies = []
        if self.pedal == "accelerate":
            self.pedal = "release"
            replies.append({"type": "drive", "pedal": "release"})
        road = frame["road"]
        parsed = Road.parse_or_none(road)
        reverse = None if parsed is None else parsed.reverse.id   # None matches no edge
        edge = frame["lane"].rsplit("_", 1)[0]
        obstacle = obstacle_ahead(frame)
        if obstacle and not self.passing:
            self.passing = True
            if self.pull_out:
                replies.append({"type": "steer", "lane": "oncoming"})
        elif self.passing and frame["speed"] < 0.1 and (
                not self.pull_out or self.warned and self.pass_lane is None):
            # it waits behind the obstacle (without a pull-out, or with one not begun when the
            # ego stands for the hand-back short of the junction): the autopilot is to pass it
            self.passing = False
            replies.append({"type": "hand_back"})
        elif edge == reverse and (self.passing or self.pull_out):
            # in the oncoming lane; not passing yet where the takeover landed during the
            # autopilot's pull-out: the pass is the person's to finish from there
            self.passing, self.pass_lane = True, frame["lane"]
        elif self.passing and self.pass_lane is not None and edge == road:
            self.passing, self.pass_lane = False, None
            self.passes += 1
            replies.append({"type": "hand_back"})
        return replies

    def on_state(self, state: dict) -> list[dict]:
        shown = state.get("questionnaire") or {}
        key = (state["phase"], tuple(state["done"]),
               *(shown.get(part) for part in ("name", "placement", "trial")))
        if key == self.acted_on:   # the same state again (a reply to a report, say): nothing new
            return []
        self.acted_on = key
        if state["phase"] == "questionnaire":
            return [self.answer_questionnaire(shown)]
        if state["phase"] == "consent":
            return [{"type": "consent", "agree": True, "client": "scripted", "lockstep": self.lockstep}]
        if state["phase"] == "done":
            self.finished = True
        elif state["phase"] == "ready":
            task = next(t for t in self.tasks if t.episode_id == state["next_episode"])
            self.driver, self.mode = self.new_driver(task), "auto"
            return [{"type": "start", "trust": int(self.driver.trust)}]
        return []


    def answer_questionnaire(self, questionnaire: dict) -> dict:
        """Every item at the scale point nearest its middle: the scripted participant has no model
        of questionnaire answers; it answers so that the session goes on (the figures of these
        answers mean nothing)."""
        scale = questionnaire["scale"]
        middle = scale["min"] + round((scale["max"] - scale["min"]) / scale["step"] / 2) * scale["step"]
        return {"type": "answers", "questionnaire": questionnaire["name"],
                "answers": {item["id"]: middle for item in questionnaire["items"]}}


def obstacle_ahead(frame: dict) -> bool:
    """Whether the frame shows an obstacle in the ego's lane ahead."""
    return any(kind == "obstacle" and in_lane_ahead(frame, x, y) for x, y, _, kind, *_ in frame["vehicles"])


def in_lane_ahead(frame: dict, x: float, y: float, reach: float = 80.0) -> bool:
    """Whether (x, y) is within `reach` metres ahead of the ego in its lane (as the station sees
    an obstacle ahead)."""
    heading = math.radians(frame["angle"])   # SUMO's angle: clockwise from north
    ahead = (x - frame["x"]) * math.sin(heading) + (y - frame["y"]) * math.cos(heading)
    aside = (x - frame["x"]) * math.cos(heading) - (y - frame["y"]) * math.sin(heading)
    return 0.0 < ahead < reach and abs(aside) < 4.0


def run_scripted(url: str, token: str, participant: ScriptedParticipant, timeout: float = 600.0,
                 stop_after: int | None = None) -> ScriptedParticipant:
    """Connect `participant` to the websocket at `url` (ws://HOST:PORT/ws) with its participant
    token and play until every trial is done (or `stop_after` episodes ended); returns it."""
    from websockets.sync.client import connect

    headers = {"Authorization": f"Bearer {token}"}
    with connect(url, additional_headers=headers, open_timeout=timeout) as socket:
        silent_since = sent_at = time.monotonic()
        while not participant.finished:
            if stop_after is not None and len(participant.episodes) >= stop_after:
                break
            # the server closes a socket that has sent nothing for its idle time, however much it
            # receives (a trial on autopilot streams frames and asks nothing): a ping keeps it open
            if time.monotonic() - sent_at > PING_SECONDS:
                socket.send(json.dumps({"type": "ping"}))
                sent_at = time.monotonic()
            try:
                message = socket.recv(timeout=PING_SECONDS)
            except TimeoutError:
                if time.monotonic() - silent_since > timeout:
                    raise
                continue
            silent_since = time.monotonic()
            for reply in participant.respond(json.loads(message)):
                socket.send(json.dumps(reply))
                sent_at = time.monotonic()
    return participant
