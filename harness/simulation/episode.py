"""The SUMO engine: one study episode of the ego AV on libsumo.

The ego is inserted on the spec's start road. On each road, `COMMIT_DISTANCE` metres before its
end (before the ego must commit to the next junction), the runner closes the road's observation
(incident, takeover, performance measured from SUMO), lets the driver's trust move and report,
hands it to the EpisodeTracker (belief filter, DFA, end of episode), asks the tracker for the
next junction and extends the ego's route one road ahead (vehicle.setRoute). The next road's
incident is injected at that moment so its SUMO objects are in place when the ego arrives; when
the incident comes into view the synthetic driver decides takeover from its current trust; a
takeover switches the ego to manual control until that road's commit point, before the next
junction (takeover_decision.py). Per step the runner reads one subscription of the ego;
everything else runs only while an incident is live. The scenes' random draws (pedestrian
timing, obstacle position, oncoming traffic, background traffic) come from one generator seeded
by the episode's seed (`scene_rng`), separate from the driver's, so they never shift the
driver's draws (docs/scenes.md).
"""

from __future__ import annotations

import contextlib
import logging
import math
import tempfile
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa

from trustroute.app.nets import net_for
from trustroute.core.dataset import (
    INCIDENTS_SCHEMA,
    KINEMATICS_SCHEMA,
    ROADS_SCHEMA,
    frame_from_table,
    table_from_columns,
    table_from_frame,
    table_from_rows,
)
from trustroute.harness.simulation import incidents as incident_kinds
from trustroute.harness.simulation import takeover_decision
from trustroute.harness.simulation.background import BackgroundTraffic, JamRelief, background_routes
from trustroute.harness.simulation.driving_style import AUTOPILOT, apply_style
from trustroute.harness.simulation.episode_net import check_net_matches, check_readable, net_key
from trustroute.harness.simulation.episode_tracker import EpisodeSetup, EpisodeTracker
from trustroute.harness.simulation.incidents import EgoState, Incident, Scene
from trustroute.harness.simulation.performance import PerformanceMonitor, limits_for, verdict
from trustroute.harness.simulation.real_roads import RealRoads, real_scene
from trustroute.harness.simulation.sumo_start import Sumo, SumoConfig, hot_calls, sumo_session
from trustroute.networks.real_net import is_imported, road_edges
from trustroute.networks.road import Road
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
UNSEEN_ROAD = 15.0          # metres: an imported road this short is crossed within a step (0.5 s at 30 m/s)
STEP_FIELDS = ("time", "x", "y", "speed", "lane", "mode")   # what the loop logs per step, in order
SCENE_STREAM = 0x5CE7E      # the scene generator's stream: SeedSequence([seed, SCENE_STREAM])

def scene_rng(seed: int) -> np.random.Generator:
    """The episode's scene generator (every draw of the incidents and background traffic)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), SCENE_STREAM]))


_SCHEMAS = {"roads": ROADS_SCHEMA, "kinematics": KINEMATICS_SCHEMA, "incidents": INCIDENTS_SCHEMA}


class EpisodeRecord:
    """The logs of one episode (the caller writes them to Parquet). `incidents` (SUMO engine only):
    one row per road with an incident or a takeover, with the SUMO ids of its objects.

    Each table is given as an Arrow table of its dataset schema (trustroute.core.dataset), or
    as a DataFrame; `roads`, `kinematics` and `incidents` are DataFrames built on first use, and
    `tables()` hands the logs back as Arrow tables without going through pandas when they were
    given as Arrow (the SUMO engine's case: the cheap path for writers, a study writes Arrow).
    """

    def __init__(self, summary: dict, roads, kinematics, incidents=None) -> None:
        self.summary = summary
        self._sources = {"roads": roads, "kinematics": kinematics,
                         "incidents": incidents if incidents is not None else INCIDENTS_SCHEMA.empty_table()}
        self._frames: dict[str, pd.DataFrame] = {}

    def _frame(self, name: str) -> pd.DataFrame:
        frame = self._frames.get(name)
        if frame is None:
            source = self._sources[name]
            frame = source if isinstance(source, pd.DataFrame) else frame_from_table(source)
            self._frames[name] = frame
        return frame

    @property
    def roads(self) -> pd.DataFrame:
        return self._frame("roads")

    @property
    def kinematics(self) -> pd.DataFrame:
        return self._frame("kinematics")

    @property
    def incidents(self) -> pd.DataFrame:
        return self._frame("incidents")

    def tables(self) -> dict[str, pa.Table]:
        """{"roads", "kinematics", "incidents"} as Arrow tables."""
        out = {}
        for name, source in self._sources.items():
            if isinstance(source, pa.Table):
                out[name] = source
            else:
                out[name] = table_from_frame(source, _SCHEMAS[name])
        return out


class _StepLog:
    """The per-step log (STEP_FIELDS) as columns while the loop runs: time, x, y and speed in one
    float64 array, lane and mode in lists. The kinematics table is then a few buffer copies, not a
    conversion of one Python object per cell."""

    def __init__(self) -> None:
        self.floats = array("d")          # time, x, y, speed of every step, in that order
        self.lanes: list[str] = []
        self.modes: list[str] = []

    def table(self, episode_id: str) -> pa.Table:
        floats = np.frombuffer(self.floats, dtype=np.float64).reshape(-1, 4).T
        rows = len(self.lanes)
        columns = {"episode_id": pa.array([episode_id], pa.string()).take(np.zeros(rows, dtype=np.int64)),
                   **{name: pa.array(floats[i]) for i, name in enumerate(STEP_FIELDS[:4])},
                   "lane": self.lanes, "mode": self.modes}
        return table_from_columns(columns, KINEMATICS_SCHEMA, nan_as_null=False)


@dataclass
class _RoadRun:
    """What happens on one road of the episode (mutable while the ego drives it)."""

    index: int
    road: str
    kind: str
    incident: Incident | None = None
    injected_time: float = math.nan
    time_in: float = math.nan
    in_view_time: float = math.nan
    x: float = math.nan           # where the incident object was when it came into view
    y: float = math.nan
    passed_time: float = math.nan
    removed_time: float = math.nan
    decided: bool = False
    took_over: bool = False
    takeover_start: float = math.nan
    takeover_end: float = math.nan
    committed: bool = False
    next_view_check: float = -math.inf
    monitor: PerformanceMonitor = field(default_factory=PerformanceMonitor)
    offsets: dict[str, float] = field(default_factory=dict)   # edge -> where it starts along the road


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


def _check_missing_ego(now: float, start: str, current: _RoadRun) -> None:
    """The ego is not on the net at `now`: an error once it has left (the end of its route was
    reached before the route was extended), or once INSERT_TIMEOUT has passed without it."""
    if not math.isnan(current.time_in):
        raise RuntimeError(f"the ego left the net at the end of its route on {current.road} before "
                           "the route was extended")
    if now > INSERT_TIMEOUT:
        raise RuntimeError(f"the ego could not be inserted on {start} within {INSERT_TIMEOUT} s")


class _Episode:
    """One run of the loop; SUMO calls stay in here and in the incident/takeover modules."""

    def __init__(self, sumo, setup: EpisodeSetup, tracker: EpisodeTracker, driver, config: SumoConfig,
                 observer: Callable | None, rng: np.random.Generator,
                 scene_overrides: dict[str, dict] | None = None, real: RealRoads | None = None) -> None:
        self.sumo = sumo
        self.real = real               # an imported town's roads as edges of its own net, else None
        self.rng = rng
        self.scene_overrides = scene_overrides or {}
        self.setup = setup
        self.tracker = tracker
        self.driver = driver
        self.config = config
        self.observer = observer
        self.mode = AUTOPILOT.name
        self.runs: list[_RoadRun] = []
        self.steps = _StepLog()         # the kinematics table, one row per step
        self.lengths: dict[str, float] = {}
        self.min_gap = 2.5
        self.defined_types: set = set()   # incident type definers run in this simulation
        # A remote person (harness/live) takes over and hands back when they choose: such a driver
        # has takeover_request(now) -> True (take over), False (hand back) or None, asked every step.
        self.person = getattr(driver, "takeover_request", None)

    def length(self, road: str) -> float:
        if road not in self.lengths:
            self.lengths[road] = (self.sumo.lane.getLength(f"{road}_1") if self.real is None
                                  else self.real.length(road))
        return self.lengths[road]

    # -- driver and incidents -------------------------------------------------
    def decide(self, run: _RoadRun, now: float) -> None:
        self.mode = takeover_decision.decide(self.sumo, EGO_ID, run, self.driver, run.kind, now, self.mode)

    def person_control(self, run: _RoadRun, now: float, request: bool | None) -> None:
        self.mode = takeover_decision.apply_request(self.sumo, EGO_ID, run, request, self.mode, now)

    def new_run(self, index: int, road: str) -> _RoadRun:
        kind = self.setup.town.incident(road) if index > 0 else NO_INCIDENT
        limits = limits_for(self.config.performance_limits, kind or "none")
        real = self.real
        return _RoadRun(index=index, road=road, kind=kind,
                        monitor=PerformanceMonitor(ttc_horizon=limits.min_ttc),
                        offsets={road: 0.0} if real is None else real.offsets(road))

    def inject(self, run: _RoadRun, now: float, ego_distance: float) -> None:
        if self.real is not None:
            scene = real_scene(self.real, run.road, run.kind, Scene(
                road=run.road, reverse_road=None, road_length=self.length(run.road), prefix=f"inc{run.index}",
                ego_id=EGO_ID, time=now, ego_distance=ego_distance, rng=self.rng,
                overrides=self.scene_overrides.get(run.kind, {}), road_speed=ROAD_SPEED,
                step_length=self.config.step_length))
            run.incident = (None if scene is None else
                            incident_kinds.inject(run.kind, self.sumo, scene, self.defined_types))
            run.injected_time = now
            return
        other_way = Road.parse(run.road).reverse.id
        reverse = other_way if other_way in self.setup.town.incidents else None
        scene = Scene(road=run.road, reverse_road=reverse, road_length=self.length(run.road),
                      prefix=f"inc{run.index}", ego_id=EGO_ID, time=now, ego_distance=ego_distance,
                      rng=self.rng, overrides=self.scene_overrides.get(run.kind, {}), road_speed=ROAD_SPEED,
                      step_length=self.config.step_length,
                      observed_length=self.length(run.road) - COMMIT_DISTANCE)
        run.incident = incident_kinds.inject(run.kind, self.sumo, scene, self.defined_types)
        run.injected_time = now
        if run.incident is not None:
            log.debug("%s: %s incident on %s as %s", self.tracker.episode_id, run.kind, run.road,
                      ",".join(run.incident.sumo_ids))

    def remove_incident(self, run: _RoadRun, now: float) -> None:
        if run.incident is not None and math.isnan(run.removed_time):
            run.incident.remove(self.sumo)
            run.removed_time = now

    def watch(self, run: _RoadRun, ego: EgoState) -> None:
        """Per-step work for the open road's incident and the driver (only while there is some)."""
        incident = run.incident
        if incident is None:
            if ego.road in run.offsets:
                self.decide(run, ego.time)   # nothing to see: the driver decides on entering the road
            return
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
        if math.isnan(run.passed_time) and incident.is_passed(self.sumo, ego):
            run.passed_time = ego.time

    # -- the road's end -------------------------------------------------------
    def close_road(self, run: _RoadRun, now: float) -> None:
        """The observation of `run` is complete: hand back, trust moves, the tracker records it."""
        if not run.decided:
            self.decide(run, now)   # the incident never came into view: decide now, as the model does
        self.mode = takeover_decision.hand_back_at_road_end(self.sumo, EGO_ID, run, self.mode, now)
        self.remove_incident(run, now)
        performance = run.monitor.result(self.limits(run))
        trust_before = self.driver.trust
        trust_after = self.driver.move_trust(run.kind, run.took_over, performance)
        reported = self.driver.report_trust() if self.tracker.should_report() else None
        self.tracker.record_road(run.road, run.kind, run.took_over, performance, trust_before,
                                 trust_after, reported, run.time_in, now)

    def watch_open(self, run: _RoadRun, now: float, road: str, position: float, x: float, y: float,
                   speed: float, lane: str, angle: float, accel: float) -> EgoState | None:
        """`watch` the open road while there is something to watch (its incident is live, or, with
        none, the driver has still to decide); the ego's state then, else None."""
        if not run.decided if run.incident is None else math.isnan(run.removed_time):
            ego = EgoState(now, road, position, x, y, speed, lane, angle, accel)
            self.watch(run, ego)
            return ego
        return None

    def measure(self, run: _RoadRun, ego: EgoState | None, speed: float, accel: float, leader,
                step: float) -> None:
        """One step of the AV's performance on the open road (called while it drives on autopilot)."""
        collided = (self.colliding_number() > 0
                    and EGO_ID in self.sumo.simulation.getCollidingVehiclesIDList())
        run.monitor.observe(self.sumo, speed, accel, collided, leader, self.min_gap, ROAD_SPEED, step)
        if ego is not None and run.incident is not None:
            run.incident.measure(self.sumo, ego, run.monitor)

    def limits(self, run: _RoadRun):
        return limits_for(self.config.performance_limits, run.kind or "none")

    def commit(self, run: _RoadRun, now: float, position: float) -> _RoadRun | None:
        """At the commit point of `run` (`position` metres into the road): close it, choose the next
        road, extend the route."""
        run.committed = True
        if run.index > 0:
            self.close_road(run, now)
        had_fallback = self.tracker.fallback_fired
        junction = self.tracker.next_junction()
        if self.tracker.fallback_fired and not had_fallback:
            log.info("%s: 20-junction fallback fired at junction %d on %s", self.tracker.episode_id,
                     self.tracker.junctions, run.road)
        if junction is None:
            return None
        nxt = self.setup.town.successor(run.road, junction)
        if self.real is None:
            self.sumo.vehicle.setRoute(EGO_ID, [run.road, nxt])
        else:
            detour = self.real.extend_route(self.sumo, EGO_ID, run.road, nxt)
            if detour:
                log.info("%s: the net has no turn from %s into %s: driving %s between",
                         self.tracker.episode_id, run.road, nxt, " ".join(detour))
        upcoming = self.new_run(run.index + 1, nxt)
        self.runs.append(upcoming)
        if self.real is not None and self.length(nxt) < UNSEEN_ROAD:
            # The ego may cross so short a road within one step, never seen on it, and would reach
            # the end of its route: the road is closed at once (its observation, which ends at its
            # commit point before its start, is empty) and the route extended past it.
            upcoming.time_in = now
            return self.commit(upcoming, now, 0.0)
        self.inject(upcoming, now, self.length(run.road) - position + JUNCTION_LENGTH)
        return upcoming

    # -- the loop -------------------------------------------------------------
    def insert_ego(self) -> Callable | None:
        """Background traffic and the ego on the start road, subscribed; returns the background's
        per-step call (None without background vehicles)."""
        sumo = self.sumo
        start = self.setup.spec.start
        _define_ego_type(sumo)
        # On an imported town's net the background traffic comes from route files (sumo_start).
        background = BackgroundTraffic(self.config.background_vehicles if self.real is None else 0,
                                       self.rng, tuple(self.setup.town.states))
        background.start(sumo)
        depart = max(0.0, self.length(start) - COMMIT_DISTANCE - START_BEFORE_COMMIT)
        route = [start]
        if self.real is not None:
            route, depart = self.real.start(start, depart)
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

    def run(self) -> float:
        sumo = self.sumo
        start = self.setup.spec.start
        background_step = self.insert_ego()
        position_id, xy_id, speed_id, accel_id, lane_id, leader_id, angle_id = (
            sumo.VAR_LANEPOSITION, sumo.VAR_POSITION, sumo.VAR_SPEED,
            sumo.VAR_ACCELERATION, sumo.VAR_LANE_ID, sumo.VAR_LEADER, sumo.VAR_ANGLE)
        self.min_gap = sumo.vehicle.getMinGap(EGO_ID)
        current = self.new_run(0, start)
        self.runs.append(current)
        upcoming: _RoadRun | None = None
        step = self.config.step_length
        max_sim_seconds = self.config.max_sim_seconds
        now = 0.0
        # Hot loop: local names, one subscription read, three appends, Python work only where
        # something happens (an incident still live, a driver still to decide).
        calls = hot_calls(sumo)
        simulation_step, get_time = calls.step, calls.time
        get_results = calls.subscription_results
        self.colliding_number = calls.colliding_number
        lane_roads: dict[str, str] = {}   # "A-B_1" -> "A-B", ":A_5_0" -> ":A_5"
        auto = AUTOPILOT.name
        log_floats, log_lane, log_mode = (self.steps.floats.extend, self.steps.lanes.append,
                                          self.steps.modes.append)
        observer, person = self.observer, self.person
        commit_at = self.length(start) - COMMIT_DISTANCE
        while True:
            simulation_step()
            now = get_time()
            result = get_results(EGO_ID)
            if not result:
                _check_missing_ego(now, start, current)
                continue
            if math.isnan(current.time_in):
                current.time_in = now
            lane = result[lane_id]
            road = lane_roads.get(lane)
            if road is None:
                road = lane_roads[lane] = lane[:lane.rindex("_")]
            position = result[position_id]
            speed = result[speed_id]
            x, y = result[xy_id]
            if upcoming is not None and road in upcoming.offsets:   # on the next road
                current, upcoming = upcoming, None
                current.time_in = now
                commit_at = self.length(current.road) - COMMIT_DISTANCE
            open_run = upcoming if upcoming is not None else current
            if background_step is not None:
                background_step(sumo)
            if open_run.index > 0:
                if person is not None:
                    self.person_control(open_run, now, person(now))
                ego = self.watch_open(open_run, now, road, position, x, y, speed, lane, result[angle_id],
                                      result[accel_id])
                if self.mode == auto:
                    self.measure(open_run, ego, speed, result[accel_id], result[leader_id], step)
            finished = False
            along = current.offsets.get(road)   # where the ego's edge starts along the road
            if not current.committed and along is not None and along + position + speed * step >= commit_at:
                upcoming = self.commit(current, now, along + position)
                finished = upcoming is None
            # Logged after this step's decisions, so `mode` is the control the ego drives on with.
            log_floats((now, x, y, speed))
            log_lane(lane)
            log_mode(self.mode)
            if observer is not None:
                observer(sumo, EgoState(now, road, position, x, y, speed, lane, result[angle_id],
                                        result[accel_id]), self.mode, open_run.road)
            if finished:
                break
            if now > max_sim_seconds:
                raise RuntimeError(f"episode {self.tracker.episode_id} still running after "
                                   f"{max_sim_seconds:.0f} s of sim time on {road}")
        return now

    def incidents_table(self) -> pa.Table:
        """One row per road with an incident object or a takeover (row 0, the start road, never)."""
        rows = []
        for run in self.runs:
            if run.index == 0 or (run.incident is None and not run.took_over):
                continue
            monitor, incident = run.monitor, run.incident
            failed = monitor.failed_measures(self.limits(run))
            rows.append({
                "episode_id": self.tracker.episode_id, "index": run.index, "directed_road": run.road,
                "incident": run.kind,
                "sumo_ids": ",".join(incident.sumo_ids) if incident is not None else None,
                # NaN is a null in these (the times and places of what never happened)
                "injected_time": run.injected_time, "in_view_time": run.in_view_time, "x": run.x, "y": run.y,
                "passed_time": run.passed_time, "removed_time": run.removed_time,
                "takeover": run.took_over, "takeover_start": run.takeover_start,
                "takeover_end": run.takeover_end,
                "performance": verdict(failed),
                "min_ttc": monitor.min_ttc, "max_deceleration": monitor.max_deceleration,
                "collided": monitor.collided, "min_head_on_ttc": monitor.min_head_on_ttc,
                "min_pedestrian_distance": monitor.min_pedestrian_distance, "time_lost": monitor.time_lost,
                "failed_measures": ",".join(failed) or None,
                "scene": incident.details() if incident is not None else None,
            })
        return table_from_rows(rows, INCIDENTS_SCHEMA)

    def kinematics_table(self) -> pa.Table:
        return self.steps.table(self.tracker.episode_id)


def run_episode(setup: EpisodeSetup, policy: RoutingPolicy, driver, episode_id: str, seed: int,
                rrd_path: Path | None = None, *, net_path: Path | None = None,
                config: SumoConfig | None = None, observer: Callable | None = None,
                scene_overrides: dict[str, dict] | None = None) -> EpisodeRecord:
    """Run one episode in SUMO and return its logs.

    driver: a participants.synthetic_driver.SyntheticDriver (decides_takeover, move_trust, report_trust,
    trust), or a person of a live study (harness/live/worker.py RemoteDriver), who also has
    takeover_request(now): their takeover or hand-back, asked every step. seed: the scenes' seed,
    and SUMO's when the episode starts it (no SUMO draw reaches an episode: sumo_start); the
    driver carries its own Generator. net_path: the town's net (default: `net_for(setup.town)`).
    observer(sumo, ego, mode, road): called every step (tests use it to read SUMO state).
    rrd_path: also write a Rerun recording. scene_overrides:
    {incident kind: {draw name: value}} fixes scene draws (e.g. {"pedestrian": {"timing": "late"}}).
    """
    started = time.perf_counter()
    config = config if config is not None else SumoConfig()
    real = None
    # The net the town drives (trustroute/app/nets.py): an imported town's own, checked against the
    # hash the town recorded, else the built one.
    net = net_for(setup.town) if net_path is None else Path(net_path)
    if is_imported(setup.town):
        real = RealRoads(road_edges(setup.town, net), COMMIT_DISTANCE)
    key = net_key(net)
    if net_path is not None and real is None:
        check_readable(net, key)
    tracker = EpisodeTracker(setup, policy, episode_id, initial_trust=driver.trust, sim_time=0.0)
    rng = scene_rng(seed)
    with contextlib.ExitStack() as stack:
        if config.route_files or (real is not None and config.background_vehicles > 0):
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="trustroute-routes-")))
            routes = background_routes(config, real is not None, net, seed, folder)
            config = replace(config, route_files=routes)
        sumo = stack.enter_context(sumo_session(net, seed, config))
        if real is None:
            check_net_matches(sumo, setup, net, key)
        episode = _Episode(sumo, setup, tracker, driver, config, observer, rng, scene_overrides, real)
        sim_seconds = episode.run()
    record = EpisodeRecord(summary=tracker.summary(wall_seconds=time.perf_counter() - started,
                                                   sim_seconds=sim_seconds),
                           roads=tracker.roads_table(), kinematics=episode.kinematics_table(),
                           incidents=episode.incidents_table())
    if rrd_path is not None:
        from trustroute.harness.simulation.rerun_log import write_recording

        write_recording(Path(rrd_path), net, record, setup)
    return record
