"""The SUMO engine: one study episode of the ego AV on libsumo, as a steppable object.

`SumoEpisode` is driven from outside (stepping.py): `advance()` runs SUMO to the next decision
point or the end, `choose(junction)` answers a decision point; `run_episode` drives it with its own
routing policy to the end. The road network is chosen once (episode_roads.py: a net built from the
town, or an imported town's own net) and asked through one interface.

The ego is inserted on the spec's start road. On each road, `COMMIT_DISTANCE` metres before its
end (before the ego must commit to the next junction), the episode closes the road's observation
(incident, takeover, performance measured from SUMO), lets the driver's trust move and report,
hands it to the EpisodeTracker (belief filter, DFA, end of episode) and stops at a decision point;
once the next junction is chosen it extends the ego's route one road ahead (vehicle.setRoute).
The next road's incident is injected at that moment so its SUMO objects are in place when the ego
arrives; when the incident comes into view the synthetic driver decides takeover from its current
trust; a takeover switches the ego to manual control until that road's commit point, before the
next junction (takeover_decision.py). A person at the wheel (drivers.py `PersonControls`, a live
study) takes over and hands back when they choose, and drives by hand in control, the ego waiting
for their hand-back before the next junction (manual_driving.py). Per step the episode reads one
subscription of the ego; everything else runs only while an incident is live. The scenes' random
draws (pedestrian timing, obstacle position, oncoming traffic, background traffic) come from one
generator seeded by the episode's seed (`scene_rng`), separate from the driver's, so they never
shift the driver's draws (docs/scenes.md).
"""

from __future__ import annotations

import contextlib
import logging
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyarrow as pa

from trustroute.harness.simulation import incidents as incident_kinds
from trustroute.harness.simulation import takeover_decision
from trustroute.harness.simulation.background import (
    BackgroundTraffic,
    JamRelief,
    background_routes,
    sim_time_cap_reached,
)
from trustroute.harness.simulation.drivers import Driver, PersonControls
from trustroute.harness.simulation.driving_style import AUTOPILOT, apply_style
from trustroute.harness.simulation.episode_record import EpisodeRecord, StepLog
from trustroute.harness.simulation.episode_roads import EpisodeRoads, background_vehicles, episode_roads
from trustroute.harness.simulation.episode_tracker import DrivenRoad, EpisodeSetup, EpisodeTracker
from trustroute.harness.simulation.incidents import EgoState
from trustroute.harness.simulation.manual_driving import ManualDriving
from trustroute.harness.simulation.performance import PerformanceMonitor, limits_for
from trustroute.harness.simulation.road_run import RoadRun, incidents_table
from trustroute.harness.simulation.stepping import DecisionPoint, End, run_to_end
from trustroute.harness.simulation.sumo_start import HotCalls, Sumo, SumoConfig, hot_calls, sumo_session
from trustroute.networks.sumo_net import ROAD_SPEED
from trustroute.networks.town import NO_INCIDENT
from trustroute.policies.routing.protocol import RoutingPolicy

log = logging.getLogger(__name__)

EGO_ID = "ego"
EGO_TYPE = "trustroute_ego"
COMMIT_DISTANCE = 30.0      # metres before a road's end: decide the next junction here
MAX_CLOSING = 30.0          # m/s: no incident object and the ego close in on each other faster
START_BEFORE_COMMIT = 40.0  # the ego is inserted this far before the start road's commit point
INSERT_TIMEOUT = 30.0       # seconds of sim time for the ego to appear
MAX_LEADER_HORIZON = 1000.0  # metres: the most the subscription looks ahead for a leader
JUNCTION_LENGTH = 8.0       # metres: a typical internal lane, for timing scenes from the commit point
SCENE_STREAM = 0x5CE7E      # the scene generator's stream: SeedSequence([seed, SCENE_STREAM])


def scene_rng(seed: int) -> np.random.Generator:
    """The episode's scene generator (every draw of the incidents and background traffic)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), SCENE_STREAM]))


@dataclass(frozen=True, eq=False)
class EpisodeOptions:
    """How a SUMO episode runs besides its setup, policy, driver, id and seed.

    net_path: the town's net (default: the town's built net, cached; an imported town's own net).
    config: SUMO's settings. observer(sumo, ego, mode, road): called every step (tests read SUMO
    state with it; a live study paces and streams with it). scene_overrides: {incident kind:
    {draw name: value}} fixes scene draws (e.g. {"pedestrian": {"timing": "late"}}). person: a
    person at the wheel (live studies), asked every step. rrd_path: also write a Rerun recording.
    """

    net_path: Path | None = None
    config: SumoConfig = field(default_factory=SumoConfig)
    observer: Callable | None = None
    scene_overrides: dict[str, dict] = field(default_factory=dict)
    person: PersonControls | None = None
    rrd_path: Path | None = None


class _Step(NamedTuple):
    """A step whose end (its log row and observer) waits for the decision taken in it."""

    now: float
    road: str
    position: float
    x: float
    y: float
    speed: float
    lane: str
    angle: float
    accel: float
    open_road: str


class _EpisodeStopped(Exception):
    """The episode was closed before its end: its simulation goes as after an error."""


def leader_horizon(config: SumoConfig) -> float:
    """How far ahead the ego's subscription looks for a leader: a leader TTC below a limit needs a
    bumper gap below speed × limit (the closing speed is at most the ego's), and the ego drives at
    most ROAD_SPEED, so a leader farther than the largest limit × ROAD_SPEED cannot matter (SUMO
    then searches fewer lanes each step)."""
    largest = max((limits.min_ttc for limits in config.performance_limits.values()), default=0.0)
    return min(largest * ROAD_SPEED + 1.0, MAX_LEADER_HORIZON)


def _define_ego_type(sumo) -> None:
    sumo.vehicletype.copy("DEFAULT_VEHTYPE", EGO_TYPE)
    sumo.vehicletype.setImperfection(EGO_TYPE, 0.0)   # the AV drives without driver noise
    sumo.vehicletype.setSpeedDeviation(EGO_TYPE, 0.0)


def _check_missing_ego(now: float, start: str, current: RoadRun) -> None:
    """The ego is not on the net at `now`: an error once it has left (the end of its route was
    reached before the route was extended), or once INSERT_TIMEOUT has passed without it."""
    if not math.isnan(current.time_in):
        raise RuntimeError(f"the ego left the net at the end of its route on {current.road} before "
                           "the route was extended")
    if now > INSERT_TIMEOUT:
        raise RuntimeError(f"the ego could not be inserted on {start} within {INSERT_TIMEOUT} s")


class SumoEpisode:
    """One episode on libsumo, stepped from outside (stepping.py). SUMO calls stay in here and in
    the incident, takeover and manual-driving modules."""

    # Set when the first `advance` starts SUMO (`_begin`), and by the loop.
    sumo: Sumo
    current: RoadRun                 # the road the ego is on
    _calls: HotCalls
    _step_ms: int                     # SUMO's step in its clock's milliseconds
    _step: _Step                      # the step a decision point was reached in

    def __init__(self, setup: EpisodeSetup, policy: RoutingPolicy, driver: Driver, episode_id: str,
                 seed: int, options: EpisodeOptions | None = None) -> None:
        """seed: the scenes' seed, and SUMO's when the episode starts it (no SUMO draw reaches an
        episode: sumo_start); the driver carries its own Generator."""
        self.started = time.perf_counter()
        options = options if options is not None else EpisodeOptions()
        self.options = options
        self.setup = setup
        self.seed = seed
        self.config = options.config
        self.roads: EpisodeRoads = episode_roads(setup.town, options.net_path, COMMIT_DISTANCE)
        self.tracker = EpisodeTracker(setup, policy, episode_id, initial_trust=driver.trust, sim_time=0.0)
        self.rng = scene_rng(seed)
        self.driver = driver
        self.observer = options.observer
        self.person = options.person
        self.manual = (ManualDriving(options.person, EGO_ID, COMMIT_DISTANCE, self.roads.chain)
                       if options.person is not None and options.person.drives_by_hand else None)
        if options.person is not None:
            options.person.drive_on(self.roads.chain)
        self.mode = AUTOPILOT.name
        self.carried_takeover = False   # a person's takeover in a road's closing step, for the next road
        self.runs: list[RoadRun] = []
        self.steps = StepLog()         # the kinematics table, one row per step
        self.min_gap = 2.5
        self.defined_types: set = set()   # incident type definers run in this simulation
        self._stack: contextlib.ExitStack | None = None
        self._background_step: Callable | None = None
        self.upcoming: RoadRun | None = None   # the road chosen next, once committed
        self.commit_at = 0.0                    # where on the current road its commit point is
        self._pending: tuple[RoadRun, float, float] | None = None  # (run, now, position) to choose at
        self._point: DecisionPoint | None = None   # the decision point waiting for its answer
        self._end: End | None = None
        self._closed = False                      # stopped before its end (close, or an error)
        # "A-B_1" -> ("A-B_1", "A-B"), ":A_5_0" -> (":A_5_0", ":A_5"): a lane's road, and the one
        # copy of its id that the step log holds (SUMO gives a new string every step; repeated
        # objects are cheaper for the kinematics table to convert)
        self._lane_roads: dict[str, tuple[str, str]] = {}

    @property
    def policy(self) -> RoutingPolicy:
        return self.tracker.policy

    def length(self, road: str) -> float:
        return self.roads.length(self.sumo, road)

    # -- stepping ---------------------------------------------------------------
    def advance(self) -> DecisionPoint | End:
        if self._end is not None:
            return self._end
        if self._closed:
            raise RuntimeError(f"episode {self.tracker.episode_id} was closed before its end")
        try:
            if self._stack is None:
                self._begin()
            elif self._pending is not None:
                if self.tracker.expected_road() is None and self._point is not None:
                    return self._point   # not answered yet: the same point
                point = self._resume()
                if point is not None:
                    return point
            return self._loop()
        except BaseException as exc:
            self._close_after(exc)
            raise

    def choose(self, junction: str) -> None:
        if self._pending is None:
            raise ValueError(f"episode {self.tracker.episode_id}: no decision point to answer "
                             "(call advance first)")
        had_fallback = self.tracker.fallback_fired
        self.tracker.choose(junction)
        if self.tracker.fallback_fired and not had_fallback:
            log.info("%s: 20-junction fallback fired at junction %d on %s", self.tracker.episode_id,
                     self.tracker.junctions, self._pending[0].road)

    def close(self) -> None:
        if self._end is None:
            self._close_after(_EpisodeStopped())

    def _close_after(self, error: BaseException) -> None:
        """Leave the SUMO session as an error does (the simulation it leaves behind is closed)."""
        stack, self._stack = self._stack, None
        self._closed = True
        if stack is not None:
            stack.__exit__(type(error), error, error.__traceback__)

    # -- driver and incidents -------------------------------------------------
    def decide(self, run: RoadRun, now: float) -> None:
        self.mode = takeover_decision.decide(self.sumo, EGO_ID, run, self.driver, run.kind, now, self.mode)

    def person_control(self, run: RoadRun, now: float, request: bool | None, closing: bool) -> None:
        """A person's takeover or hand-back on the open road `run`. A takeover in the step that
        reaches the road's commit point (`closing`) goes to the next road: applied on this one,
        the road's end would hand back in the same step, unseen, and the person's station would
        wait for a mode change that never comes."""
        if request is None and self.carried_takeover:
            request = True
        self.carried_takeover = request is True and closing and self.mode == AUTOPILOT.name
        if not self.carried_takeover:
            self.mode = takeover_decision.apply_request(self.sumo, EGO_ID, run, request, self.mode, now)

    def new_run(self, index: int, road: str) -> RoadRun:
        kind = self.setup.town.incident(road) if index > 0 else NO_INCIDENT
        limits = limits_for(self.config.performance_limits, kind or "none")
        return RoadRun(index=index, road=road, kind=kind,
                        monitor=PerformanceMonitor(ttc_horizon=limits.min_ttc),
                        offsets=self.roads.offsets(road))

    def inject(self, run: RoadRun, now: float, ego_distance: float) -> None:
        run.injected_time = now
        if run.kind == NO_INCIDENT:
            return   # no scene to place (placing draws nothing)
        scene = self.roads.place(
            run.kind, road=run.road, road_length=self.length(run.road), prefix=f"inc{run.index}",
            ego_id=EGO_ID, time=now, ego_distance=ego_distance, rng=self.rng,
            overrides=self.options.scene_overrides.get(run.kind, {}), road_speed=ROAD_SPEED,
            step_length=self.config.step_length)
        run.incident = (None if scene is None else
                        incident_kinds.inject(run.kind, self.sumo, scene, self.defined_types))
        if run.incident is not None:
            log.debug("%s: %s incident on %s as %s", self.tracker.episode_id, run.kind, run.road,
                      ",".join(run.incident.sumo_ids))

    def remove_incident(self, run: RoadRun, now: float) -> None:
        if run.incident is not None and math.isnan(run.removed_time):
            run.incident.remove(self.sumo)
            run.removed_time = now
            run.quiet = True

    def watch(self, run: RoadRun, ego: EgoState) -> None:
        """Per-step work for the open road's incident and the driver's view of it, while the road
        has an incident and is not `quiet` (on a road without one the driver decides on entering
        it: nothing to watch, so the loop builds no ego state for it)."""
        incident = run.incident
        assert incident is not None   # (the loop watches only a road with an incident)
        incident.step(self.sumo, ego)
        if not run.decided and ego.time >= run.next_view_check:
            where = incident.position(self.sumo)
            if where is not None:
                distance = math.dist(where, (ego.x, ego.y))
                if takeover_decision.in_view(distance):
                    run.in_view_time = ego.time
                    run.x, run.y = where
                    self.decide(run, ego.time)
                else:
                    # The gap closes at most MAX_CLOSING m/s: no need to look again before then.
                    unseen = distance - takeover_decision.VIEW_DISTANCE
                    run.next_view_check = ego.time + unseen / MAX_CLOSING
        # The objects stay after the ego has passed (an obstacle never leaves by itself); they are
        # taken out when the road's observation closes.
        if math.isnan(run.passed_time):
            if incident.is_passed(self.sumo, ego):
                run.passed_time = ego.time
        elif run.decided and incident.done():
            # Nothing of this road is left to happen before its end: the steps after this one
            # neither watch it nor build the ego's state for it.
            run.quiet = True

    # -- the road's end -------------------------------------------------------
    def close_road(self, run: RoadRun, now: float) -> None:
        """The observation of `run` is complete: hand back, trust moves, the tracker records it."""
        if not run.decided:
            self.decide(run, now)   # the incident never came into view: decide now, as the model does
        self.mode = takeover_decision.hand_back_at_road_end(self.sumo, EGO_ID, run, self.mode, now)
        self.remove_incident(run, now)
        performance = run.monitor.result(self.limits(run))
        trust_before = self.driver.trust
        trust_after = self.driver.move_trust(run.kind, run.took_over, performance)
        reported = self.driver.report_trust() if self.tracker.should_report() else None
        self.tracker.record_road(DrivenRoad(run.road, run.kind, run.took_over, performance, trust_before,
                                            trust_after, reported, run.time_in, now))

    def measure(self, run: RoadRun, ego: EgoState | None, speed: float, accel: float, leader,
                step: float) -> None:
        """One step of the AV's performance on the open road (called while it drives on autopilot)."""
        collided = (self.colliding_number() > 0
                    and EGO_ID in self.sumo.simulation.getCollidingVehiclesIDList())
        run.monitor.observe(self.sumo, speed, accel, collided, leader, self.min_gap, ROAD_SPEED, step)
        if ego is not None and run.incident is not None:
            run.incident.measure(self.sumo, ego, run.monitor)

    def limits(self, run: RoadRun):
        return limits_for(self.config.performance_limits, run.kind or "none")

    def commit(self, run: RoadRun, now: float, position: float) -> DecisionPoint | None:
        """At the commit point of `run` (`position` metres into the road): close it; the decision
        point of the next junction, or None when the episode is over."""
        run.committed = True
        if run.index > 0:
            self.close_road(run, now)
        else:   # the start road is not observed, but a person in control hands back here too
            self.mode = takeover_decision.hand_back_at_road_end(self.sumo, EGO_ID, run, self.mode, now)
        context = self.tracker.decision_point()
        if context is None:
            return None
        self._pending = (run, now, position)
        self._point = DecisionPoint(context, self.setup.town.actions(context.road))
        return self._point

    def extend(self, run: RoadRun, now: float, position: float) -> RoadRun:
        """The chosen road after `run` (committed `position` metres into it): the ego's route
        extended into it and its run begun, its incident injected; a road the ego may cross within
        a step is entered at once instead (its observation, which ends at its commit point before
        its start, is empty: it is committed at once too)."""
        junction = self.tracker.next_junction()
        assert junction is not None   # (extended only after the choice)
        nxt = self.setup.town.successor(run.road, junction)
        detour = self.roads.extend_route(self.sumo, EGO_ID, run.road, nxt)
        if detour:
            log.info("%s: the net has no turn from %s into %s: driving %s between",
                     self.tracker.episode_id, run.road, nxt, " ".join(detour))
        upcoming = self.new_run(run.index + 1, nxt)
        if run.index == 0:
            takeover_decision.count_for_first_road(run, upcoming)
        self.runs.append(upcoming)
        if self.roads.crossed_within_a_step(self.sumo, nxt):
            upcoming.time_in = now
        else:
            self.inject(upcoming, now, self.length(run.road) - position + JUNCTION_LENGTH)
        return upcoming

    def _resume(self) -> DecisionPoint | End | None:
        """After the choice at the pending decision point: the route extended, then the rest of the
        step; a further decision point or the end when the next road is crossed within the step,
        else None (the loop goes on)."""
        assert self._pending is not None   # (advance resumes only a pending decision point)
        run, now, position = self._pending
        self._pending = None
        upcoming = self.extend(run, now, position)
        if not math.isnan(upcoming.time_in):   # crossed within the step
            point = self.commit(upcoming, now, 0.0)
            return point if point is not None else self._end_after_step()
        self.upcoming = upcoming
        self._go_on_after_step()
        return None

    # -- the loop -------------------------------------------------------------
    def insert_ego(self) -> Callable | None:
        """Background traffic and the ego on the start road, subscribed; returns the background's
        per-step call (None without background vehicles)."""
        sumo = self.sumo
        start = self.setup.spec.start
        _define_ego_type(sumo)
        # On an imported town's net the background traffic comes from route files (sumo_start).
        background = BackgroundTraffic(background_vehicles(self.roads, self.config), self.rng,
                                       tuple(self.setup.town.states))
        background.start(sumo)
        route, depart = self.roads.start(
            start, max(0.0, self.length(start) - COMMIT_DISTANCE - START_BEFORE_COMMIT))
        sumo.route.add("ego_route", route)
        sumo.vehicle.add(EGO_ID, "ego_route", typeID=EGO_TYPE, depart="now", departLane="best",
                         departPos=f"{depart:.2f}", departSpeed="max")
        apply_style(sumo, EGO_ID, AUTOPILOT)
        # One subscription carries everything the loop reads each step, the leader included (the
        # road is the lane's edge, "A-B" of "A-B_1", ":A_5" of ":A_5_0": one variable less).
        sumo.vehicle.subscribe(EGO_ID, [sumo.VAR_LANEPOSITION, sumo.VAR_POSITION,
                                        sumo.VAR_SPEED, sumo.VAR_ACCELERATION, sumo.VAR_LANE_ID,
                                        sumo.VAR_LEADER, sumo.VAR_ANGLE], 0.0, 1e9,
                               {sumo.VAR_LEADER: leader_horizon(self.config)})
        if not self.config.route_files:
            return background.step if background.count > 0 else None
        relief = JamRelief(EGO_ID)
        if background.count == 0:
            return relief.step

        def both(sumo: Sumo) -> None:
            background.step(sumo)
            relief.step(sumo)

        return both

    def _begin(self) -> None:
        """SUMO started (or returned to its empty state) on the episode's net, the ego inserted."""
        config, roads = self.config, self.roads
        self._stack = stack = contextlib.ExitStack()
        stack.__enter__()
        if config.route_files or (roads.imported and config.background_vehicles > 0):
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="trustroute-routes-")))
            routes = background_routes(config, roads.imported, roads.net, self.seed, folder)
            self.config = config = replace(config, route_files=routes)
        self.sumo = sumo = stack.enter_context(sumo_session(roads.net, self.seed, config))
        roads.check(sumo, self.setup)
        self._background_step = self.insert_ego()
        self.min_gap = sumo.vehicle.getMinGap(EGO_ID)
        self.current = self.new_run(0, self.setup.spec.start)
        self.runs.append(self.current)
        self.commit_at = self.length(self.current.road) - COMMIT_DISTANCE
        self._calls = hot_calls(sumo)
        self._step_ms = round(sumo.simulation.getDeltaT() * 1000)
        self.colliding_number = self._calls.colliding_number

    def _loop(self) -> DecisionPoint | End:
        """Step SUMO to the next commit point: its decision point, or the end."""
        sumo = self.sumo
        start = self.setup.spec.start
        position_id, xy_id, speed_id, accel_id, lane_id, leader_id, angle_id = (
            sumo.VAR_LANEPOSITION, sumo.VAR_POSITION, sumo.VAR_SPEED,
            sumo.VAR_ACCELERATION, sumo.VAR_LANE_ID, sumo.VAR_LEADER, sumo.VAR_ANGLE)
        current, upcoming, commit_at = self.current, self.upcoming, self.commit_at
        step = self.config.step_length
        # Hot loop: local names, one subscription read, three appends, Python work only where
        # something happens (an incident still live, a driver still to decide).
        calls = self._calls
        simulation_step, get_results = calls.step, calls.subscription_results
        # SUMO's clock counts whole milliseconds and reads as ms / 1000: read once here, then
        # counted step by step in the same units (the same float as asking every step).
        now_ms, step_ms = round(calls.time() * 1000), self._step_ms
        lane_roads = self._lane_roads
        auto = AUTOPILOT.name
        log_floats, log_lane, log_mode = (self.steps.floats.extend, self.steps.lanes.append,
                                          self.steps.modes.append)
        background_step = self._background_step
        after_step = self.observer is not None or self.manual is not None
        person = self.person.takeover_request if self.person is not None else None
        max_sim_seconds = self.config.max_sim_seconds
        # Kept as locals, changed only where they change (the ego appears, reaches the next road).
        entered = not math.isnan(current.time_in)
        open_run = upcoming if upcoming is not None else current
        while True:
            simulation_step()
            now_ms += step_ms
            now = now_ms / 1000
            result = get_results(EGO_ID)
            if not result or not result[lane_id]:   # not on the net (yet): SUMO's lane id is ""
                _check_missing_ego(now, start, current)
                continue
            if not entered:
                current.time_in = now
                entered = True
            lane = result[lane_id]
            known = lane_roads.get(lane)
            if known is None:
                known = lane_roads[lane] = (lane, lane[:lane.rindex("_")])
            lane, road = known
            position = result[position_id]
            speed = result[speed_id]
            x, y = result[xy_id]
            if upcoming is not None and road in upcoming.offsets:   # on the next road
                current, upcoming = upcoming, None
                current.time_in = now
                commit_at = self.length(current.road) - COMMIT_DISTANCE
                self.current, self.upcoming, self.commit_at = current, upcoming, commit_at
                open_run = current
            if background_step is not None:
                background_step(sumo)
            along = current.offsets.get(road)   # where the ego's edge starts along the road
            commits = (not current.committed and along is not None
                       and along + position + speed * step >= commit_at)
            if person is not None:   # on the start road too: a takeover acts in its step everywhere
                self.person_control(open_run, now, person(now), commits)
            if open_run.index > 0:
                ego = None
                incident = open_run.incident
                if incident is None and not open_run.decided and road in open_run.offsets:
                    self.decide(open_run, now)   # nothing to see: the driver decides on entering
                elif incident is not None and not open_run.quiet:
                    ego = EgoState(now, road, position, x, y, speed, lane, result[angle_id], result[accel_id])
                    self.watch(open_run, ego)
                if self.mode == auto:
                    self.measure(open_run, ego, speed, result[accel_id], result[leader_id], step)
            if commits:
                assert along is not None   # (commits only on a road of the current run)
                self._step = _Step(now, road, position, x, y, speed, lane, result[angle_id],
                                   result[accel_id], open_run.road)
                point = self.commit(current, now, along + position)
                return point if point is not None else self._end_after_step()
            # Logged after this step's decisions, so `mode` is the control the ego drives on with.
            log_floats((now, x, y, speed))
            log_lane(lane)
            log_mode(self.mode)
            if after_step:
                self._after_step(_Step(now, road, position, x, y, speed, lane, result[angle_id],
                                       result[accel_id], open_run.road))
            if now > max_sim_seconds:
                self._too_long(road)

    def _after_step(self, step: _Step) -> None:
        """The person's manual driving, then the observer, on the step's ego."""
        ego = EgoState(step.now, step.road, step.position, step.x, step.y, step.speed, step.lane,
                       step.angle, step.accel)
        if self.manual is not None:
            self.manual.step(self.sumo, ego, self.mode, step.open_road)
        if self.observer is not None:
            self.observer(self.sumo, ego, self.mode, step.open_road)

    def _too_long(self, road: str) -> None:
        raise sim_time_cap_reached(self.tracker.episode_id, road,
                                   self.sumo.vehicle.getWaitingTime(EGO_ID), self.config)

    def _complete_step(self) -> None:
        """The rest of the step a decision was taken in: its log row, then the observer."""
        step = self._step
        self.steps.floats.extend((step.now, step.x, step.y, step.speed))
        self.steps.lanes.append(step.lane)
        self.steps.modes.append(self.mode)
        if self.observer is not None or self.manual is not None:
            self._after_step(step)

    def _end_after_step(self) -> End:
        self._complete_step()
        return self._ended(self._step.now)

    def _go_on_after_step(self) -> None:
        self._complete_step()
        if self._step.now > self.config.max_sim_seconds:
            self._too_long(self._step.road)

    def _ended(self, sim_seconds: float) -> End:
        stack, self._stack = self._stack, None
        if stack is not None:
            stack.close()
        record = EpisodeRecord(
            summary=self.tracker.summary(wall_seconds=time.perf_counter() - self.started,
                                         sim_seconds=sim_seconds),
            roads=self.tracker.roads_table(), kinematics=self.kinematics_table(),
            incidents=self.incidents_table())
        if self.options.rrd_path is not None:
            # rerun is loaded only when a recording is asked for
            from trustroute.harness.simulation.rerun_log import write_recording

            write_recording(Path(self.options.rrd_path), self.roads.net, record, self.setup)
        self._end = End(record)
        return self._end

    def incidents_table(self) -> pa.Table:
        return incidents_table(self.runs, self.tracker.episode_id, self.config.performance_limits)

    def kinematics_table(self) -> pa.Table:
        return self.steps.table(self.tracker.episode_id)



def run_episode(setup: EpisodeSetup, policy: RoutingPolicy, driver: Driver, episode_id: str, seed: int,
                options: EpisodeOptions | None = None) -> EpisodeRecord:
    """Run one episode in SUMO, driven by its own routing policy (`SumoEpisode` stepped to its end),
    and return its logs; `options`: the net, SUMO's settings, an observer, scene draws, a person at
    the wheel, a Rerun recording (None: the defaults)."""
    options = options if options is not None else EpisodeOptions()
    return run_to_end(SumoEpisode(setup, policy, driver, episode_id, seed, options))
