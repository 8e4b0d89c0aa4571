"""The scripted participant: a synthetic driver that takes part in a live study over the websocket.

It speaks the participant's protocol (harness/live/protocol.py) and nothing else: it consents,
starts each trial with its true trust, takes over when its driver model says so at the moment an
incident comes into view, and after each road moves its trust on what it observed (incident,
takeover, the AV's performance) and reports it every `report_every` roads, all with the planned
episode's driver (the participant's model, the task's Generator: harness/study/runner.py's
`run_planned_episode`). It drives the live path end to end without a person: the tests and the
benchmark use it. `ScriptedParticipant.respond` is the logic (message in, replies out);
`run_scripted` connects it to a server.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from trustroute.harness.study.config import StudyConfig
from trustroute.harness.study.plan import EpisodeTask, plan_episodes


@dataclass
class ScriptedParticipant:
    """Participant `participant` of `config`, played by its synthetic drivers."""

    config: StudyConfig
    participant: int
    lockstep: bool = False   # the episodes wait for every answer: they run as headless ones do
    tasks: list[EpisodeTask] = field(default_factory=list)
    driver: Any = None   # the current trial's SyntheticDriver
    finished: bool = False
    acted_on: tuple = ()
    errors: list[dict] = field(default_factory=list)
    episodes: list[dict] = field(default_factory=list)
    takeovers: int = 0
    reports: int = 0

    def __post_init__(self) -> None:
        from trustroute.harness.live.server import warm_up_task

        trials = sorted((t for t in plan_episodes(self.config) if t.participant == self.participant),
                        key=lambda t: t.position)
        self.tasks = [warm_up_task(self.config, self.participant), *trials]

    def new_driver(self, task: EpisodeTask):
        from trustroute.harness.study.context import study_context
        from trustroute.participants.synthetic_driver import SyntheticDriver

        model = study_context(self.config).driver_model(task.participant)
        return SyntheticDriver(model, task.driver_rng(), report_accuracy=self.config.report_accuracy)

    def respond(self, message: dict) -> list[dict]:
        """The replies to one server message."""
        kind = message.get("type")
        if kind == "state":
            return self.on_state(message)
        if kind == "incident" and self.driver is not None:
            if self.driver.decides_takeover(message["kind"]):
                self.takeovers += 1
                return [{"type": "takeover"}]
            if self.lockstep:
                return [{"type": "pass"}]
        elif kind == "road" and self.driver is not None:
            self.driver.move_trust(message["incident"], message["takeover"], message["performance"])
            if message["prompt"]:
                self.reports += 1
                return [{"type": "trust", "value": int(self.driver.report_trust())}]
        elif kind == "warning" and message["kind"] == "hand_back":
            return [{"type": "hand_back"}]   # the rule of the study: hand back before the junction
        elif kind == "episode_end":
            self.episodes.append(message)
            self.driver = None
        elif kind == "error":
            self.errors.append(message)
        return []

    def on_state(self, state: dict) -> list[dict]:
        key = (state["phase"], tuple(state["done"]))
        if key == self.acted_on:   # the same state again (a reply to a report, say): nothing new
            return []
        self.acted_on = key
        if state["phase"] == "consent":
            return [{"type": "consent", "agree": True, "client": "scripted", "lockstep": self.lockstep}]
        if state["phase"] == "done":
            self.finished = True
        elif state["phase"] == "ready":
            task = next(t for t in self.tasks if t.episode_id == state["next_episode"])
            self.driver = self.new_driver(task)
            return [{"type": "start", "trust": int(self.driver.trust)}]
        return []


def run_scripted(url: str, token: str, participant: ScriptedParticipant, timeout: float = 600.0,
                 stop_after: int | None = None) -> ScriptedParticipant:
    """Connect `participant` to the websocket at `url` (ws://HOST:PORT/ws) with its participant
    token and play until every trial is done (or `stop_after` episodes ended); returns it."""
    from websockets.sync.client import connect

    headers = {"Authorization": f"Bearer {token}"}
    with connect(url, additional_headers=headers, open_timeout=timeout) as socket:
        while not participant.finished:
            if stop_after is not None and len(participant.episodes) >= stop_after:
                break
            for reply in participant.respond(json.loads(socket.recv(timeout=timeout))):
                socket.send(json.dumps(reply))
    return participant
