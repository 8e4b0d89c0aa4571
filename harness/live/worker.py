"""One live episode in its own process: the study's episode code on SUMO, with a remote person.

libsumo runs one simulation per process, so every live episode is a process of its own
(`start_episode_process`, multiprocessing "forkserver": forked from a fork server that has imported
the episode's modules once, so nothing of the server's threads is inherited and no episode pays
Python's and the libraries' imports again).
It runs `run_planned_episode` (harness/study/runner.py) exactly as a headless study does (same
setup, policy, SUMO config, seed, the same steppable SumoEpisode and EpisodeTracker) with a
`RemoteDriver` in place of the synthetic driver. The typed drivers are the seam
(harness/simulation/drivers.py): a `RemoteDriver` is the episode's `Driver` and, at the wheel, its
`PersonControls`:

- `takeover_request(now)`, asked every step: the person's takeover (True) or hand-back (False);
- `manual_inputs()`, asked every step when they drive by hand: the pedal and pull-out they sent;
- `hand_back_warning(distance, now)`: they are still in control near the road's end (sent on,
  after the mode: the server checks the hand-back that answers it against the mode);
- `decides_takeover(kind)`, asked when an incident comes into view: False (a person's takeover
  comes through takeover_request); the view event is sent to the participant. In lockstep (the
  scripted participant only) the episode waits for its answer, `takeover` or `pass`, and
  `report_trust` for the report a prompt asks for: the episode then runs as a headless one does;
- `move_trust(...)`, when a road's observation closes: the road's event (incident, takeover,
  performance) is sent; the trust it returns is the person's latest report (their stated trust:
  the roads table's trust columns; the policy never reads them);
- `report_trust()`: None outside lockstep: each prompt names its road (`{"episode_id", "road"}` in
  the road event) and the answer names the prompt, so every answer is put on the road it answers
  once the episode ends (`with_reports`), whenever it came; the last road's prompt is answered
  after the car has arrived, so the episode's end waits for it (`await_last_answer`, up to
  `final_report_seconds`). A report outside a prompt is logged with the road open then.

This module keeps only the pipe, the pacing and the frames: the observer paces the simulation
against the wall clock (`pace` sim seconds per wall second), reads the person's controls from the
pipe, pauses while the server says so, and streams frames. Driving by hand and the hold before the
hand-back are the episode's (harness/simulation/manual_driving.py), outside lockstep: in lockstep
the episode runs as a headless one does.
With `[live] driving = "continuous"` the person drives by wheel and pedals instead: the
`wheel_driving.Wheel` hook (harness/simulation/wheel_driving.py) integrates a vehicle model and
places the ego in SUMO every step (0.05 s steps: `sumo_config`), and the frames show the model's
pose.
The part is written atomically by this process (harness/study/parts.py), its summary marked with
who drove and every control the person sent.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import pyarrow as pa

from trustroute.core.dataset import INCIDENTS_SCHEMA, table_from_rows
from trustroute.harness.live.protocol import REQUESTED_MODE, Frame
from trustroute.harness.live.view import Statics, dead_reckoned, ego_view, next_junction, surroundings
from trustroute.harness.live.warmup import run_warm_up
from trustroute.harness.simulation.drivers import NO_INPUTS, ManualInputs
from trustroute.harness.simulation.driving_style import AUTOPILOT, MANUAL
from trustroute.harness.simulation.episode import COMMIT_DISTANCE, EGO_ID, EpisodeRecord
from trustroute.harness.simulation.episode_tracker import reports_after_road
from trustroute.harness.simulation.manual_driving import RoadChain
from trustroute.harness.simulation.manual_measures import takeover_measures
from trustroute.harness.simulation.wheel_driving import Controls, Wheel

PIPE_POLL_SECONDS = 0.02   # while paced or paused: how often the pipe is checked
STATION_LEAD = 2.0         # sim s: the most the frames sent run ahead of the last the station drew
STATION_WAIT = 5.0         # wall s: a station that confirms no frame for this long is not waited for
FINAL_REPORT_SECONDS = 15.0   # wall seconds a trial's end waits for the last road's report
CONTINUOUS_STEP = 0.05     # s: SUMO's step while a person may drive by wheel (the paper's CARLA tick)


class EpisodeAborted(Exception):
    """The experimenter aborted the episode: no part is written."""


@dataclass(frozen=True)
class LiveOptions:
    pace: float = 1.0            # sim seconds per wall second (1.0: real time; tests use >> 1)
    frame_rate: float = 25.0     # frames streamed per wall second (between steps: dead-reckoned)
    client: str = "station"      # who drives: "station" (a person) or "scripted"
    report_every: int = 1        # the study's report_every: roads whose end prompts for a report
    lockstep: bool = False       # scripted only: the episode waits for its reply to every decision
    final_report_seconds: float = FINAL_REPORT_SECONDS
    driving: str = "assisted"    # [live] driving: "continuous" drives a vehicle model by wheel


class RemoteDriver:
    """The driver of a live episode, and their controls at the wheel: a person (or the scripted
    participant) across a pipe."""

    def __init__(self, connection, trust_levels: tuple[int, ...], initial_trust: int | None,
                 options: LiveOptions, clock=time.monotonic, episode_id: str = "") -> None:
        self.connection = connection
        self.levels = tuple(int(level) for level in trust_levels)
        middle = self.levels[len(self.levels) // 2]
        self._trust = initial_trust if initial_trust in self.levels else middle
        self.options = options
        self.clock = clock
        self._request: bool | None = None
        self._report: int | None = None
        self.roads = 0
        self.episode_id = episode_id
        self.prompts: list[int] = []       # the roads whose end asked for a report
        self.answers: dict[int, int] = {}  # road index -> the report that answered its prompt
        self.events: list[dict] = []       # every control received: (sim time, wall time, what)
        self.paused = False
        self.mode = "auto"
        self.sim_now = 0.0
        self.origin = (clock(), 0.0)       # (wall, sim) the pace is measured from
        self.last_frame = -float("inf")
        self.inputs = NO_INPUTS            # pedal and pull-out received since the episode last asked
        self.previous_time: float | None = None
        self.step_seconds = 0.5            # simulated seconds between the last two steps
        self.shown: dict | None = None     # the last stepped frame sent
        self.held_at = 0.0                 # the simulated time shown when paused
        self.predicted = False             # the last frame sent was dead-reckoned
        self.hurry = False                 # a control to apply at once: the next step does not wait
        self.unsettled: str | None = None  # the mode a request the episode took asks for, until observed
        self.frame_time = 0.0              # the simulated time of the last frame sent
        self.station_time: float | None = None   # of the last frame the station confirmed (`shown`)
        self.behind_since: float | None = None   # wall time the wait for the station began
        self.statics = Statics()           # the frames' handles and sizes of the objects seen
        # continuous driving (a wheel; never in lockstep): harness/simulation/wheel_driving.py
        by_wheel = options.driving == "continuous" and not options.lockstep
        self.wheel = Wheel(EGO_ID, COMMIT_DISTANCE) if by_wheel else None

    # -- the Driver and PersonControls protocols (harness/simulation/drivers.py) ----------------
    @property
    def trust(self) -> int:
        return self._trust

    @property
    def drives_by_hand(self) -> bool:
        return not self.options.lockstep

    def takeover_request(self, now: float) -> bool | None:
        request, self._request = self._request, None
        if request is False and self.wheel is not None and not self.wheel.may_hand_back:
            # the hand-back rule: back on a lane of the route first
            self.send({"type": "warning", "kind": "back_to_lane", "t": now})
            return None
        if request is not None and self.wheel is None:
            self.unsettled = MANUAL.name if request else AUTOPILOT.name
        return request

    def manual_inputs(self) -> ManualInputs:
        inputs, self.inputs = self.inputs, NO_INPUTS
        return inputs

    def drive_on(self, chain: RoadChain) -> None:
        if self.wheel is not None:
            self.wheel.chain = chain

    def hand_back_warning(self, distance: float, now: float) -> None:
        # The warning goes to a person in control only. In the step a takeover is applied it comes
        # before the observer, and the server refuses a hand-back while it has not been told of the
        # takeover: the mode goes out first, or an answer to the warning could be refused and the
        # ego would wait short of the junction for a hand-back that does not come again.
        self.announce_mode(MANUAL.name, now)
        self.send({"type": "warning", "kind": "hand_back", "distance": round(distance, 1), "t": now})

    def decides_takeover(self, incident: str) -> bool:
        self.send({"type": "incident", "kind": incident, "t": self.sim_now})
        if self.options.lockstep:
            return self.await_reply(("takeover", "pass"))["type"] == "takeover"
        return False

    def move_trust(self, incident: str, took_over: bool, performance: str = "succ") -> int:
        self.roads += 1
        prompt = None
        if reports_after_road(self.roads, self.options.report_every):
            prompt = {"episode_id": self.episode_id, "road": self.roads}
            self.prompts.append(self.roads)
        self.send({"type": "road", "index": self.roads, "incident": incident, "takeover": bool(took_over),
                   "performance": performance, "t": self.sim_now, "prompt": prompt})
        return self._trust

    def report_trust(self) -> int | None:
        """In lockstep the answer to the prompt just sent (the episode waits for it); otherwise
        None: answers go on their roads when the episode ends (`with_reports`)."""
        if not self.options.lockstep:
            return None
        if self._report is None:
            self.apply(self.await_reply(("trust",)), logged=True)
        report, self._report = self._report, None
        return report

    @property
    def awaiting_report(self) -> bool:
        """The last prompt for a report has had no answer yet."""
        return bool(self.prompts) and self.prompts[-1] not in self.answers

    def await_last_answer(self) -> None:
        """A person answers the last road's prompt after the car has arrived: the end waits for it
        (up to final_report_seconds of wall time, reading controls). Answers come in the order
        sent, so every earlier answer sent has come by then too."""
        if self.options.lockstep:
            return
        deadline = self.clock() + self.options.final_report_seconds
        while self.awaiting_report and (left := deadline - self.clock()) > 0.0:
            if self.connection.poll(min(left, PIPE_POLL_SECONDS * 5)):
                self.apply(self.connection.recv())

    def answered_road(self, prompt) -> int | None:
        """The road a report's `prompt` names, when it is one of this episode's prompts."""
        if not isinstance(prompt, dict) or prompt.get("episode_id") != self.episode_id:
            return None
        road = prompt.get("road")
        return road if road in self.prompts else None

    # -- controls from the server ---------------------------------------------------------------
    def send(self, message: dict) -> None:
        self.connection.send(message)

    def await_reply(self, wanted: tuple[str, ...]) -> dict:
        """Lockstep: the participant's reply to the event just sent, the simulation standing still
        meanwhile (other controls are applied as they come)."""
        while True:
            control = self.connection.recv()
            if control.get("type") in wanted:
                self.events.append({"t": self.sim_now, "wall": time.time(), **control})
                return control
            self.apply(control)

    def apply(self, control: dict, logged: bool = False) -> None:
        kind = str(control.get("type", ""))
        if kind == "shown":   # the pace's, not the person's: not an event
            self.station_time = float(control["t"])
            return
        if REQUESTED_MODE.get(kind) == self.mode:
            # it crossed the episode's own switch to that mode (the junction's hand-back) before the
            # server was told of it (harness/live/session.py, Session.switch): done, not an event
            return
        if kind == "trust":   # the road it answers, else (a report outside a prompt) the road open
            answered = self.answered_road(control.get("prompt"))
            control = {**control, "road": self.roads + 1 if answered is None else answered,
                       "answers_prompt": answered is not None}
            if answered is not None and int(control["value"]) in self.levels:
                self.answers[answered] = int(control["value"])
        if not logged:
            self.events.append({"t": self.sim_now, "wall": time.time(), **control})
        if kind in ("takeover", "hand_back"):
            # by wheel, SUMO steps 0.1 s: the next step comes soon enough, and no step is hurried
            # ahead of the wall clock (the view would jump)
            self._request, self.hurry = kind == "takeover", self.wheel is None
        elif kind == "trust" and int(control["value"]) in self.levels:
            self._trust = self._report = int(control["value"])
        elif kind == "drive":
            self.inputs = ManualInputs(control["pedal"], self.inputs.steer)
        elif kind == "steer":
            self.inputs = ManualInputs(self.inputs.pedal, control["lane"])
        elif kind == "control" and self.wheel is not None:
            self.wheel.controls = Controls(control["steer"], control["throttle"], control["brake"])
        elif kind == "pause":
            if not self.paused:   # the view stands where the wall clock had brought it
                self.held_at = min(self.sim_now, self.paced_sim_time())
            self.paused, self.station_time = True, None   # (a station back after it confirms anew)
        elif kind == "resume":
            self.paused = False
            self.origin = (self.clock(), self.held_at)
        elif kind == "abort":
            raise EpisodeAborted(str(control.get("reason", "aborted")))

    def announce_mode(self, mode: str, now: float) -> None:
        """Tell the server the mode the ego drives on when it changes (it checks every takeover and
        hand-back against the mode it was told last)."""
        if mode != self.mode:
            self.mode = mode
            self.send({"type": "mode", "mode": mode, "t": now})

    def read_controls(self, timeout: float) -> None:
        while self.connection.poll(timeout):
            self.apply(self.connection.recv())
            timeout = 0.0

    def observe(self, sumo, ego, mode: str, road: str) -> None:
        """Every step: the mode change out, controls in, the pace (frames between steps), a
        pause, then the step's frame: shown when the wall clock reaches the step's time. (The
        episode has applied the person's manual inputs of this step just before.)"""
        self.sim_now = ego.time
        self.announce_mode(mode, ego.time)
        if self.unsettled is not None:
            # the episode took the request but applies it at its next step (a takeover in the step a
            # road closes goes to the next road): that step is hurried too, not paced
            self.hurry |= mode != self.unsettled
            self.unsettled = None
        if self.previous_time is not None and ego.time > self.previous_time:
            self.step_seconds = ego.time - self.previous_time
        self.previous_time = ego.time
        self.read_controls(0.0)
        if self.wheel is not None:
            for event in self.wheel.step(sumo, mode == MANUAL.name, road):
                self.send({**event, "type": "warning", "kind": event["type"]})
        hurried = self.wait_for_the_wall_clock(ego.time)
        wall = self.clock()
        if hurried:   # the pace goes on from this step: no wall time is spent waiting for it again
            self.origin = (wall, ego.time)
        # a stepped frame always replaces predicted ones (they are only ever the time between
        # steps), and shows the step before a takeover or hand-back is applied
        if hurried or self.predicted or wall - self.last_frame >= self.frame_interval:
            self.last_frame, self.predicted = wall, False
            pose = self.wheel.pose if self.wheel is not None else None
            x, y, angle, speed = (ego.x, ego.y, ego.angle, ego.speed) if pose is None else \
                (round(pose.x, 2), round(pose.y, 2), round(pose.angle, 2), round(pose.speed, 2))
            self.shown = {"type": "frame", "t": ego.time, "x": x, "y": y, "angle": angle,
                          "speed": speed, "road": road, "lane": ego.lane, "mode": mode,
                          "junction": next_junction(road),
                          **surroundings(sumo, EGO_ID, ego.x, ego.y, self.statics),
                          **ego_view(sumo, EGO_ID, self.statics),
                          "held": self.wheel is not None and self.wheel.held}
            Frame.model_validate(self.shown)   # (a frame the protocol does not define is a bug here)
            self.send(self.shown)
            self.frame_time = ego.time

    def wait_for_the_wall_clock(self, step_time: float) -> bool:
        """Until the wall clock reaches the step's time at the pace, then while the station is
        behind (`station_behind`), and while paused, reading controls; a takeover or hand-back ends
        the wait (the next step applies it). True when the pace goes on from this step: after a
        takeover or hand-back, or after waiting for the station."""
        waited = False
        while True:
            wait = PIPE_POLL_SECONDS
            if self.hurry and not self.paused:
                self.hurry = False
                return True
            if not self.paused:
                remaining = self.origin[0] + (step_time - self.origin[1]) / self.options.pace - self.clock()
                if remaining > 0:
                    wait = min(wait, remaining, self.stream_between_steps(step_time))
                elif self.station_behind():
                    waited = True
                else:
                    return waited
            self.read_controls(wait)

    def station_behind(self) -> bool:
        """The station confirms the frames it draws (`shown`), and the last it confirmed is more
        than STATION_LEAD simulated seconds before the last frame sent: the simulation waits for
        it, so a slow browser does not leave the person deciding on what is long past. A station
        that confirms nothing for STATION_WAIT wall seconds is not waited for (until it confirms a
        frame again); one that never confirms (the scripted participant) never is."""
        if self.station_time is None or self.frame_time - self.station_time <= STATION_LEAD:
            self.behind_since = None
            return False
        now = self.clock()
        if self.behind_since is None:
            self.behind_since = now
        if now - self.behind_since > STATION_WAIT:
            self.station_time = self.behind_since = None
            return False
        return True

    def paced_sim_time(self) -> float:
        """The simulated time the wall clock has reached at the pace."""
        return self.origin[1] + (self.clock() - self.origin[0]) * self.options.pace

    @property
    def frame_interval(self) -> float:
        return 1.0 / self.options.frame_rate

    def stream_between_steps(self, step_time: float) -> float:
        """While the wall clock runs from the previous step's time to this one's: the previous
        step's frame dead-reckoned to the wall clock's simulated time whenever a frame is due.
        Returns the wall seconds until the next is due."""
        shown = self.shown
        if shown is None or shown["t"] < step_time - self.step_seconds - 1e-9:
            return PIPE_POLL_SECONDS   # no frame of the previous step to move on from
        wall = self.clock()
        due = self.last_frame + self.frame_interval - wall
        if due > 0.0:
            return due
        seconds = min(self.paced_sim_time(), step_time) - shown["t"]
        if seconds > 0.0:
            self.last_frame, self.predicted = wall, True
            self.send(dead_reckoned(shown, seconds))
            self.frame_time = shown["t"] + seconds
        return self.frame_interval


def with_reports(record: EpisodeRecord, answers: dict[int, int]) -> EpisodeRecord:
    """The record with each prompt's answer on the road it answers (road index -> report; the
    latest answer to a prompt counts) and no report on the other roads."""
    tables = record.tables()
    roads = tables["roads"]
    reported = [answers.get(int(index)) for index in roads.column("index").to_pylist()]
    if reported == roads.column("reported_trust").to_pylist():
        return record
    index = roads.schema.get_field_index("reported_trust")
    field = roads.schema.field(index)
    roads = roads.set_column(index, field, pa.array(reported, field.type))
    return EpisodeRecord(record.summary, roads, tables["kinematics"], tables["incidents"])


def with_manual_measures(record: EpisodeRecord, wheel: Wheel | None) -> EpisodeRecord:
    """The record with the wheel's measures of each takeover in its incidents table (null columns
    stay null without a wheel: assisted driving has only the reaction)."""
    incidents = record.tables()["incidents"]
    if wheel is None or not incidents.num_rows:
        return record
    rows = incidents.to_pylist()
    for row in rows:
        if row["takeover"] and row["takeover_start"] is not None:
            end = math.nan if row["takeover_end"] is None else row["takeover_end"]
            row.update(takeover_measures(wheel.trace, wheel.events, row["takeover_start"], end))
    tables = record.tables()
    return EpisodeRecord(record.summary, tables["roads"], tables["kinematics"],
                         table_from_rows(rows, INCIDENTS_SCHEMA))


def live_summary(summary: dict, driver: RemoteDriver) -> dict:
    """The episode summary with the live marks: who drove, and every control they sent."""
    live = {"driver": "person" if driver.options.client == "station" else "scripted",
            "pace": driver.options.pace, "events": driver.events}
    if driver.wheel is not None:   # what the person's driving led to (collisions, the oncoming lane)
        live["driving"] = driver.wheel.events
    return {**summary, "live": live}


def sumo_config(options: LiveOptions):
    """SUMO's settings of a live episode: the study's, with 0.05 s steps while a person may drive
    by wheel (the vehicle model is placed in SUMO every step)."""
    if options.driving != "continuous" or options.lockstep:
        return None
    from trustroute.harness.simulation.sumo_start import SumoConfig

    return SumoConfig(step_length=CONTINUOUS_STEP)


def episode_worker(config, study_dir: str, task, connection, options: LiveOptions,
                   initial_trust: int | None, server_pid: int) -> None:
    """The worker process's main: run the episode, write its part, say how it ended."""
    from trustroute.harness.study.context import study_context
    from trustroute.harness.study.parts import write_part_tables
    from trustroute.harness.study.runner import run_planned_episode
    die_with_server(server_pid)   # a killed server leaves no episode running
    try:
        context = study_context(config)   # this process's own, built once for its episode
        levels = context.driver_model(task.participant).trust_levels
        driver = RemoteDriver(connection, levels, initial_trust, options, episode_id=task.episode_id)
        connection.send({"type": "episode_start", "episode_id": task.episode_id, "trust": driver.trust})
        if task.position < 0:   # the warm-up: a route and incidents of its own (harness/live/warmup.py)
            record = run_warm_up(context, task, driver, driver.observe, person=driver,
                                 sumo_config=sumo_config(options))
        else:
            record = run_planned_episode(context, task, driver=driver, observer=driver.observe, person=driver,
                                         sumo_config=sumo_config(options))
        driver.await_last_answer()
        if not options.lockstep:
            record = with_reports(record, driver.answers)
        record = with_manual_measures(record, driver.wheel)
        write_part_tables(Path(study_dir), task, live_summary(record.summary, driver), record.tables(),
                          sync=True)
        summary = record.summary
        connection.send({"type": "episode_end", "episode_id": task.episode_id,
                         "satisfied": bool(summary["satisfied"]), "end_reason": summary["end_reason"],
                         "junctions": int(summary["junctions"]), "takeovers": int(summary["takeovers"])})
    except EpisodeAborted as exc:
        connection.send({"type": "episode_aborted", "episode_id": task.episode_id, "reason": str(exc)})
    except Exception as exc:  # the server must learn why; the trial stays to be run again
        connection.send({"type": "episode_failed", "episode_id": task.episode_id,
                         "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()})
    finally:
        connection.close()


# What the fork server imports before it forks the first episode: the modules episode_worker runs
# and libsumo (a study's pool forks workers after libsumo is loaded too, harness/study/workers.py).
EPISODE_MODULES = ["trustroute.harness.live.worker", "trustroute.harness.study.context",
                   "trustroute.harness.study.parts", "trustroute.harness.study.runner",
                   "trustroute.harness.study.workers", "libsumo"]


def die_with_server(server_pid: int) -> None:
    """Exit with the server. An episode process's parent is the fork server, which exits when the
    server does (its pipe from the server closes); the episode dies with the fork server
    (PR_SET_PDEATHSIG). A server gone before that was armed leaves the fork server gone too: then
    this process is not the server's any more and exits."""
    from trustroute.harness.study.workers import die_with_parent

    die_with_parent(os.getppid())
    try:
        os.kill(server_pid, 0)
    except ProcessLookupError:
        os._exit(1)


def episode_context():
    """The multiprocessing context of the episode processes: "forkserver", or "spawn" as the fallback
    where the platform has no fork server (Windows; each episode then imports everything itself)."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(EPISODE_MODULES)
    return context


def start_fork_server() -> None:
    """Start the fork server and wait until it can fork (LiveStudy.open, before the study serves):
    it imports the episode's modules (a second of CPU, longer on a busy machine) now, not when the
    first trial starts, where the server would wait for it without answering."""
    context = episode_context()
    ready = context.Process(target=time.sleep, args=(0,), name="live-fork-server-ready", daemon=True)
    ready.start()
    ready.join()


def start_episode_process(config, study_dir: Path, task, options: LiveOptions, initial_trust: int | None):
    """(process, parent end of its pipe) of a started episode worker."""
    context = episode_context()
    parent, child = context.Pipe()
    process = context.Process(target=episode_worker, name=f"live-{task.episode_id}", daemon=True,
                              args=(config, str(study_dir), task, child, options, initial_trust, os.getpid()))
    process.start()
    child.close()
    return process, parent
