"""The remote driver in the study's episode code (in this process, on libsumo): a person's takeover
reaches SUMO and the logs, and the tracker decides exactly as it does for the same observations."""

from __future__ import annotations

import math
import time

import numpy as np
import pandas as pd
import pytest

from trustroute.app.nets import net_for
from trustroute.harness.live.view import next_junction, role
from trustroute.harness.live.worker import (
    STATION_WAIT,
    EpisodeAborted,
    LiveOptions,
    RemoteDriver,
    live_summary,
    sumo_config,
    with_manual_measures,
    with_reports,
)
from trustroute.harness.simulation.episode import COMMIT_DISTANCE
from trustroute.harness.simulation.episode_tracker import DrivenRoad, EpisodeTracker
from trustroute.harness.simulation.manual_driving import WARN_DISTANCE
from trustroute.harness.simulation.manual_measures import oncoming_seconds
from trustroute.harness.simulation.real_roads import RealRoads
from trustroute.harness.simulation.wheel_driving import OFF_ROUTE_LIMIT, nearest_on
from trustroute.harness.study.config import load_study_config
from trustroute.harness.study.context import study_context
from trustroute.harness.study.plan import plan_episodes
from trustroute.harness.study.runner import run_planned_episode
from trustroute.networks.real_net import road_edges

from .conftest import tiny_config

pytestmark = pytest.mark.slow


class Pipe:
    """The worker's end of the pipe: controls queued in advance, messages sent kept."""

    def __init__(self, controls=(), hand_back_when_warned: bool = True) -> None:
        self.controls, self.sent = list(controls), []
        self.hand_back_when_warned = hand_back_when_warned

    def send(self, message: dict) -> None:
        self.sent.append(message)
        if message["type"] == "warning" and self.hand_back_when_warned:
            self.controls.append({"type": "hand_back"})

    def poll(self, timeout: float = 0.0) -> bool:
        return bool(self.controls)

    def recv(self) -> dict:
        return self.controls.pop(0)


def live_episode(tmp_path, controls):
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe(controls)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, client="scripted"),
                          episode_id=task.episode_id)
    record = run_planned_episode(study_context(config), task, driver=driver, observer=driver.observe,
                                 person=driver)
    return config, task, driver, pipe, record


def test_a_takeover_from_the_pipe_reaches_sumo_and_the_logs(tmp_path):
    config, task, driver, pipe, record = live_episode(
        tmp_path, [{"type": "takeover"}, {"type": "trust", "value": 3}])
    roads = record.roads
    assert bool(roads["takeover"].iloc[1]) is True       # the first road after the start
    assert roads["reported_trust"].dropna().tolist() == []   # a report outside a prompt is on no road ...
    report = next(event for event in driver.events if event["type"] == "trust")
    assert (report["value"], report["road"], report["answers_prompt"]) == (3, 1, False)   # ... but logged
    assert int(roads["trust_before"].iloc[0]) == 5        # the trust stated at the start
    assert "manual" in set(record.kinematics["mode"])
    incidents = record.incidents
    assert bool(incidents["takeover"].iloc[0]) and not np.isnan(incidents["takeover_start"].iloc[0])
    frames = [m for m in pipe.sent if m["type"] == "frame"]
    assert frames and all(isinstance(f["vehicles"], list) and isinstance(f["persons"], list) for f in frames)
    assert {f["junction"] for f in frames} - {None} <= {road.split("-")[1] for road in roads["directed_road"]}
    prompts = [m["prompt"] for m in pipe.sent if m["type"] == "road"]   # report_every = 1
    assert prompts == [{"episode_id": task.episode_id, "road": k} for k in range(1, len(roads))]
    kinds = [m["type"] for m in pipe.sent]
    assert "frame" in kinds and kinds.count("road") == len(roads) - 1
    assert [m["mode"] for m in pipe.sent if m["type"] == "mode"][:2] == ["manual", "auto"]
    summary = live_summary(record.summary, driver)
    assert summary["live"]["driver"] == "scripted"
    assert [e["type"] for e in summary["live"]["events"]] == ["takeover", "trust", "hand_back"]
    # warned before the junction, the person handed back before the road's observation closed
    (warning,) = [m for m in pipe.sent if m["type"] == "warning"]
    back = [m for m in pipe.sent if m["type"] == "mode"][1]
    first_road = next(m for m in pipe.sent if m["type"] == "road")
    assert warning["t"] <= back["t"] < first_road["t"]


def test_without_a_hand_back_the_ego_waits_short_of_the_junction(tmp_path):
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6))
    waited, taken = [], []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        # the takeover comes on a road with room to stop short of its commit point
        room = sumo.lane.getLength(ego.lane) - ego.lane_position if ego.road == road else 0.0
        if not taken and room > WARN_DISTANCE + 50.0:
            taken.append(road)
            pipe.controls.append({"type": "takeover"})
        if mode == "manual" and ego.speed == 0.0:   # held short of the commit point
            waited.append(ego.time)
            if len(waited) == 40:   # 20 s of simulated time standing: the person hands back now
                pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver)
    assert len(waited) >= 40
    ticks = record.kinematics
    manual = ticks["time"][ticks["mode"] == "manual"]
    back = ticks["time"][(ticks["mode"] == "auto") & (ticks["time"] > manual.min())].min()
    assert back > waited[39] and manual.max() >= waited[39]   # handed back by the person, after waiting


def keep_lane(sumo, pose) -> dict:
    """A person keeping their lane by wheel: steering against the heading's error to the lane and
    the ego's lateral offset (SUMO's, left positive), the accelerator held down."""
    ego = "ego"
    lane, position = sumo.vehicle.getLaneID(ego), sumo.vehicle.getLanePosition(ego)
    error = (sumo.lane.getAngle(lane, position) - pose.angle + 180.0) % 360.0 - 180.0
    steer = 0.05 * error + 0.3 * sumo.vehicle.getLateralLanePosition(ego)
    return {"type": "control", "source": "wheel", "steer": max(-1.0, min(1.0, steer)), "throttle": 0.6,
            "brake": 0.0}


def test_by_wheel_without_a_hand_back_the_ego_is_held_short_of_the_junction(tmp_path):
    """Continuous driving, the accelerator held down: the wheel's hold stops the car before the
    commit point (harness/simulation/wheel_driving.py `Wheel`) until the person hands back."""
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    held, taken = [], []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        room = sumo.lane.getLength(ego.lane) - ego.lane_position if ego.road == road else 0.0
        if not taken and room > WARN_DISTANCE + 50.0:
            taken.append(road)
            pipe.controls.append({"type": "takeover"})
        if mode == "manual" and driver.wheel.pose is not None and not held:
            pipe.controls.append(keep_lane(sumo, driver.wheel.pose))
        if mode == "manual" and ego.speed == 0.0 and ego.road == road:
            held.append((ego.time, sumo.lane.getLength(ego.lane) - ego.lane_position))
            if len(held) == 40:
                pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    assert [e["type"] for e in driver.wheel.events] == ["hold"]   # in its lane all along
    assert len(held) >= 40 and {round(left, 2) for _, left in held} == {round(held[0][1], 2)}
    assert held[0][1] > COMMIT_DISTANCE   # standing before the commit point, accelerator down
    kinds = [m.get("kind") for m in pipe.sent if m["type"] == "warning"]
    assert kinds == ["hand_back", "hold"]
    ticks = record.kinematics
    manual = ticks["time"][ticks["mode"] == "manual"]
    back = ticks["time"][(ticks["mode"] == "auto") & (ticks["time"] > manual.min())].min()
    assert back > held[39][0] and len(record.roads) > 2   # handed back, and the episode went on
    # the takeover's measures: in its lane all along, braked by the hold at 3 m/s² (and rolling)
    row = with_manual_measures(record, driver.wheel).incidents.query("takeover").iloc[0]
    assert (row["road_departures"], row["collisions"], row["oncoming_seconds"]) == (0, 0, 0.0)
    assert 0.0 < row["lateral_sd"] < 0.5 and 3.0 < row["manual_max_deceleration"] < 3.3
    assert row["manual_min_ttc"] > 0.0


CSOMOR = """[study]
name = "csomor-live"
participants = 1
seed = 1
engine = "live"
town = "csomor"
specs = ["csomor5"]
conditions = ["free"]
"""


def csomor_episode(tmp_path):
    """(the study context, its roads as SUMO edge chains, the first planned episode) of a one-
    participant continuous-driving study on `csomor`: the context built once per test."""
    (tmp_path / "live.toml").write_text(CSOMOR)
    config = load_study_config(tmp_path / "live.toml")
    context = study_context(config)
    return context, RealRoads(road_edges(context.town, net_for(context.town)), COMMIT_DISTANCE), \
        plan_episodes(config)[0]


def test_by_wheel_on_an_imported_town_the_ego_is_held_short_of_the_road_end(tmp_path):
    """The same on `csomor`, an imported town: a road there runs along SUMO edges with ids of
    their own, and junctions between them (real_roads.py). Taken over on the first edge of a road
    of two, the accelerator held down, the car is held short of the road's commit point, never
    drives into the next road in the person's hands, and the person hands back there."""
    context, real, task = csomor_episode(tmp_path)
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    held, taken = [], []

    def to_end(ego, road):   # metres to the end of the road's last edge, as the episode counts them
        return real.length(road) - real.offsets(road)[ego.road] - ego.lane_position

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        chain = real.roads[road].ids
        if not taken and len(chain) > 1 and ego.road == chain[0] and to_end(ego, road) > WARN_DISTANCE + 50:
            taken.append((road, chain))
            pipe.controls.append({"type": "takeover"})
        if mode == "manual" and driver.wheel.pose is not None and not held:
            pipe.controls.append(keep_lane(sumo, driver.wheel.pose))
        if mode == "manual" and ego.speed == 0.0 and ego.road in real.offsets(taken[0][0]):
            held.append((ego.time, ego.lane, round(to_end(ego, taken[0][0]), 2)))
            if len(held) == 40:
                pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(context, task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    (road, chain), = taken
    assert [e["type"] for e in driver.wheel.events] == ["hold"]   # in its lane all along
    assert len(held) >= 40 and {(lane, left) for _, lane, left in held} == {held[0][1:]}   # in one place
    assert held[0][2] > COMMIT_DISTANCE   # before the commit point, accelerator down
    kinds = [m.get("kind") for m in pipe.sent if m["type"] == "warning"]
    assert sorted(kinds) == ["hand_back", "hold"]   # told to hand back, and held (faster: held first)
    ticks = record.kinematics
    manual = ticks[ticks["mode"] == "manual"]
    driven = {lane.rsplit("_", 1)[0] for lane in manual["lane"] if not lane.startswith(":")}
    assert driven <= set(chain), (road, chain, driven)   # never into the next road
    back = ticks["time"][(ticks["mode"] == "auto") & (ticks["time"] > manual["time"].min())].min()
    assert back > held[39][0] and record.summary["end_reason"] == "accepted"
    handed = [e["type"] for e in driver.events if e["type"] != "control"]
    assert handed == ["takeover", "hand_back"]   # handed back by the person, not at the commit point


def test_by_wheel_on_an_imported_town_a_takeover_after_the_choice_is_held_at_its_road_end(tmp_path):
    """On `csomor`, taken over after the junction ahead was chosen (the open road is the next one,
    the ego still on an edge of the road before it), the accelerator held down: the car is held
    at the end of the road it is on, never drives into the next road in the person's hands, and
    the person hands back there."""
    context, real, task = csomor_episode(tmp_path)
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    held, taken = [], []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        behind = not ego.road.startswith(":") and ego.road not in real.offsets(road)
        if not taken and ego.time > 5.0 and behind:   # the first road's choice is behind the ego
            taken.append((ego.road, road))
            pipe.controls.append({"type": "takeover"})
        if mode == "manual" and driver.wheel.pose is not None and not held:
            pipe.controls.append(keep_lane(sumo, driver.wheel.pose))
        if mode == "manual" and ego.speed == 0.0:
            held.append((ego.time, ego.lane, round(sumo.lane.getLength(ego.lane) - ego.lane_position, 2)))
            if len(held) == 20:
                pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(context, task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    (edge, road), = taken
    assert [e["type"] for e in driver.wheel.events] == ["hold"]
    assert len(held) >= 20 and {(lane, left) for _, lane, left in held} == {held[0][1:]}   # in one place
    assert held[0][1].rsplit("_", 1)[0] == edge and held[0][2] > 0.0   # short of its road's end
    ticks = record.kinematics
    manual = ticks[ticks["mode"] == "manual"]
    assert not set(manual["lane"].str.rsplit("_", n=1).str[0]) & set(real.roads[road].ids)   # not into it
    handed = [e["type"] for e in driver.events if e["type"] != "control"]
    assert handed == ["takeover", "hand_back"] and record.summary["end_reason"] == "accepted"


def follow(shape, pose) -> dict:
    """A person by wheel following the polyline `shape` (SUMO's x, y points, in the ego's
    direction) from the model's `pose`: steering against the heading's error and the lateral
    offset (left positive), the accelerator lightly down."""
    x, y, angle = nearest_on(shape, pose.x, pose.y)
    radians = math.radians(angle)
    lateral = (pose.x - x) * -math.cos(radians) + (pose.y - y) * math.sin(radians)
    error = (angle - pose.angle + 180.0) % 360.0 - 180.0
    steer = 0.05 * error + 0.3 * lateral
    return {"type": "control", "source": "wheel", "steer": max(-0.3, min(0.3, steer)), "throttle": 0.2,
            "brake": 0.0}


def test_by_wheel_on_an_imported_town_the_oncoming_lane_is_the_net_s_reverse_edge(tmp_path):
    """On `csomor`, taken over on a long edge of a two-way street (the net has an edge between the
    same junctions the other way round: its oncoming lane), the person steers into the oncoming
    lane and back: the `oncoming` event is logged, then `own_lane`, the time there is measured,
    and a hand-back asked for there is refused (the person hands back in their lane later)."""
    context, real, task = csomor_episode(tmp_path)
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    taken: list[tuple[str, str, float]] = []
    refused: list[bool] = []

    def reverse_of(sumo, edge):
        ends = (sumo.edge.getToJunction(edge), sumo.edge.getFromJunction(edge))
        reverse = lanes_of(edge).reverse_edge
        swapped = reverse is not None and (sumo.edge.getFromJunction(reverse),
                                           sumo.edge.getToJunction(reverse)) == ends
        return reverse if swapped else None

    def road_of(edge):
        return next(road for road, value in real.roads.items() if edge in value.ids)

    def lanes_of(edge):
        return next(lanes for lanes in real.roads[road_of(edge)].edges if lanes.edge == edge)

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        if not taken and ego.road in real.roads[road].ids and ego.time > 2.0:
            rest = sumo.lane.getLength(ego.lane) - ego.lane_position
            reverse = reverse_of(sumo, ego.road)
            if reverse is not None and rest > 150.0 and ego.speed > 3.0:
                taken.append((ego.road, reverse, ego.time))
                pipe.controls.append({"type": "takeover"})
        if mode != "manual" or driver.wheel.pose is None or not taken:
            return
        edge, reverse, since = taken[0]
        lanes = lanes_of(edge)
        own = sumo.lane.getShape(f"{edge}_{lanes.driving_lane}")
        there = sumo.lane.getShape(f"{reverse}_{lanes.reverse_lane}")[::-1]   # in the ego's direction
        seconds = ego.time - since
        pipe.controls.append(follow(there if 1.0 < seconds < 5.0 else own, driver.wheel.pose))
        if seconds > 3.5 and not refused:   # in the oncoming lane: the hand-back is refused
            refused.append(driver.wheel.may_hand_back)
            pipe.controls.append({"type": "hand_back"})
        if seconds > 9.0 and len(taken) == 1 and driver.wheel.may_hand_back:
            taken.append((edge, reverse, ego.time))
            pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(context, task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    edge, reverse, since = taken[0]
    kinds = [e["type"] for e in driver.wheel.events]
    assert kinds[:2] == ["oncoming", "own_lane"], (edge, reverse, kinds)
    assert 1.0 < oncoming_seconds(driver.wheel.events, since, math.inf) < 6.0
    ticks = record.kinematics
    assert f"{reverse}_{lanes_of(edge).reverse_lane}" in set(ticks["lane"][ticks["mode"] == "manual"])
    warnings = [m["kind"] for m in pipe.sent if m["type"] == "warning"]
    assert refused == [False] and "back_to_lane" in warnings, warnings
    handed = [(e["type"], e["t"]) for e in driver.events if e["type"] != "control"]
    assert [kind for kind, _ in handed] == ["takeover", "hand_back", "hand_back"]   # the first refused
    assert len(taken) == 2   # handed back in its lane
    manual = ticks["time"][ticks["mode"] == "manual"]
    assert manual.min() < handed[1][1] < handed[2][1] <= manual.max() + 0.5
    assert record.summary["end_reason"] == "accepted"


# Simulated times of a takeover on the tiny study's route (E-A, A-F, F-G, G-I, ...): on a road
# after its junction's choice (E-A at 4, A-F, F-G: the open road is already the next one), near
# enough the junction that the car cannot stop before it (10: it stops in the junction); inside a
# junction (16, :G_5). (On the start road before its commit point, where the ego is inserted too
# close to stop short of it, the episode hands back there: test_live_start_road.py.)
COASTING_TAKEOVERS = (4.0, 8.0, 10.0, 14.0, 16.0)


@pytest.mark.parametrize("at", COASTING_TAKEOVERS)
def test_by_wheel_a_takeover_without_controls_is_held_or_stopped_and_the_episode_goes_on(tmp_path, at):
    """The person takes over and gives no controls (the wheel not connected yet): the car coasts
    straight on. It is held before the junction (event `hold`), or, leaving the road, stopped off
    it (`off_road`, `stopped_off_road`) before SUMO could not place it any more; either way it
    never drives beyond the road open at the takeover in the person's hands, their hand-back
    where it stands gives it back to the autopilot, and the episode runs to its end."""
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    asked, taken, stood = [], [], []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        if not asked and ego.time >= at:
            asked.append(ego.time)
            pipe.controls.append({"type": "takeover"})
        if mode == "manual" and not taken:
            taken.append((ego.road, road))   # the ego's edge and the open road when it applies
        if mode == "manual" and ego.speed == 0.0:
            stood.append(ego.time)
            if len(stood) == 20:   # standing 1 s: the person hands back where the car is
                pipe.controls.append({"type": "hand_back"})

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    assert record.summary["end_reason"] == "accepted" and len(record.roads) == 7   # as without it
    events = driver.wheel.events
    kinds = [e["type"] for e in events]
    assert kinds in (["hold"], ["off_road", "stopped_off_road"]), kinds
    if kinds[-1] == "stopped_off_road":
        assert OFF_ROUTE_LIMIT < events[-1]["distance"] < OFF_ROUTE_LIMIT + 2.0
    (edge, road), = taken
    ticks = record.kinematics
    manual = ticks[ticks["mode"] == "manual"]
    driven = {lane.rsplit("_", 1)[0] for lane in manual["lane"] if not lane.startswith(":")}
    assert driven <= {edge, road}, (driven, edge, road)   # never past the road open at the takeover
    assert len(stood) >= 20 and manual["time"].max() >= stood[19]
    back = ticks["time"][(ticks["mode"] == "auto") & (ticks["time"] > manual["time"].min())].min()
    assert back > stood[19]   # the person's hand-back, where the car stood
    assert [e["type"] for e in driver.events] == ["takeover", "hand_back"]


def test_by_wheel_off_the_road_at_the_commit_point_the_autopilot_goes_on_along_the_route(tmp_path):
    """Taken over on the short road A-F, steered to the right with the accelerator half down: the
    car leaves the road while the hold brakes it, and the road's commit point hands back first.
    The autopilot takes the car from its lane there with the route the episode has just extended
    (not the one before the choice), and the episode runs to its end."""
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([], hand_back_when_warned=False)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, driving="continuous"))
    taken = []

    def observe(sumo, ego, mode, road):
        driver.observe(sumo, ego, mode, road)
        if not taken and ego.time >= 7.0:
            taken.append(road)
            pipe.controls.append({"type": "takeover"})
        elif mode == "manual" and len(taken) == 1:
            taken.append(road)
            pipe.controls.append({"type": "control", "source": "wheel", "steer": 0.5, "throttle": 0.5,
                                  "brake": 0.0})

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver,
                                 sumo_config=sumo_config(driver.options))
    assert taken == ["A-F", "A-F"]
    assert [e["type"] for e in driver.wheel.events] == ["hold", "off_road"]
    assert record.summary["end_reason"] == "accepted" and len(record.roads) == 7
    assert [e["type"] for e in driver.events] == ["takeover", "control"]   # handed back by the episode
    ticks = record.kinematics
    manual = ticks[ticks["mode"] == "manual"]
    assert set(manual["lane"].str.rsplit("_", n=1).str[0]) == {"A-F"}
    after = ticks[ticks["time"] > manual["time"].max()]
    assert after["lane"].iloc[0].startswith("A-F_") and "F-G_1" in set(after["lane"])


def test_the_tracker_decides_as_for_the_same_observations_headless(tmp_path):
    """Replaying the live episode's observations through the shared EpisodeTracker gives the very
    junctions, beliefs and DFA states the live episode logged."""
    config, task, driver, pipe, record = live_episode(tmp_path, [{"type": "takeover"}])
    context = study_context(config)
    cell = (task.spec, task.condition)
    tracker = EpisodeTracker(context.setup(*cell), context.policies[cell], task.episode_id, initial_trust=5)
    rows = record.roads.to_dict("records")
    for row in rows[1:]:
        tracker.next_junction()
        tracker.record_road(DrivenRoad(row["directed_road"], row["incident"], bool(row["takeover"]),
                                       row["performance"], 5, 5, None, row["sim_time_in"],
                                       row["sim_time_out"]))
    tracker.next_junction()
    replayed = tracker.roads_frame()
    for column in ("directed_road", "action", "belief_after", "dfa_state"):
        assert [str(v) for v in replayed[column]] == [str(v) for v in record.roads[column]], column


def test_an_abort_stops_the_episode(tmp_path):
    with pytest.raises(EpisodeAborted):
        live_episode(tmp_path, [{"type": "abort"}])


def test_the_next_junction_is_the_end_of_the_road():
    assert [next_junction(r) for r in ("A-B", "E-A", ":B_3", "")] == ["B", "A", None, None]


def test_what_the_view_calls_each_object():
    assert [role(i) for i in ("inc3.obstacle", "inc2.pedestrian", "inc4.oncoming", "bg7", "ego")] == [
        "obstacle", "pedestrian", "oncoming", "traffic", "traffic"]


def test_road_events_prompt_every_report_every_roads_and_answers_name_their_road():
    pipe = Pipe()
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), None, LiveOptions(report_every=2), episode_id="e1")
    assert driver.trust == 4                    # no trust stated: the middle level
    driver.apply({"type": "trust", "value": 6})   # outside a prompt: the stated trust, on no road
    assert driver.move_trust("none", False, "succ") == 6
    driver.move_trust("truck", True, "fail")
    assert [m["prompt"] for m in pipe.sent] == [None, {"episode_id": "e1", "road": 2}]
    assert driver.report_trust() is None and driver.awaiting_report
    driver.move_trust("none", False, "succ")   # road 4 is open when the answer to road 2 comes
    driver.apply({"type": "trust", "value": 3, "prompt": {"episode_id": "e1", "road": 2}})
    driver.apply({"type": "trust", "value": 5, "prompt": {"episode_id": "e0", "road": 2}})   # not ours
    driver.apply({"type": "trust", "value": 2, "prompt": {"episode_id": "e1", "road": 3}})   # no prompt there
    assert driver.answers == {2: 3} and not driver.awaiting_report and driver.trust == 2
    logged = [(e["value"], e["road"], e["answers_prompt"]) for e in driver.events if e["type"] == "trust"]
    assert logged == [(6, 1, False), (3, 2, True), (5, 4, False), (2, 4, False)]
    driver.apply({"type": "takeover"})
    assert driver.takeover_request(1.0) is True and driver.takeover_request(1.5) is None
    driver.announce_mode("manual", 1.5)   # (the episode applied the takeover)
    driver.apply({"type": "hand_back"})
    assert driver.takeover_request(2.0) is False


def test_a_request_for_the_mode_the_ego_is_on_is_neither_applied_nor_logged():
    """A hand-back that crossed the episode's own at the commit point before the server was told of
    it reaches the episode on autopilot: done already, so it is no event of the part."""
    driver = RemoteDriver(Pipe(), (1, 2, 3, 4, 5, 6, 7), None, LiveOptions(), episode_id="e1")
    driver.apply({"type": "hand_back"})
    assert driver.takeover_request(0.5) is None and driver.events == []
    driver.apply({"type": "takeover"})
    assert driver.takeover_request(1.0) is True
    driver.announce_mode("manual", 1.5)
    driver.apply({"type": "takeover"})
    assert driver.takeover_request(2.0) is None
    driver.announce_mode("auto", 2.5)   # the episode's own hand-back at the commit point
    driver.apply({"type": "hand_back"})
    assert driver.takeover_request(3.0) is None
    assert [event["type"] for event in driver.events] == ["takeover"]


def test_every_answer_goes_on_the_road_it_answers_and_the_last_is_awaited(tmp_path):
    config, task, driver, pipe, record = live_episode(tmp_path, [{"type": "takeover"}])
    roads = [m for m in pipe.sent if m["type"] == "road"]
    assert roads[-1]["prompt"] == {"episode_id": task.episode_id, "road": len(roads)}
    # answers in the order sent, each late (the last after the arrival), one prompt left unanswered
    for road in roads[1:]:
        pipe.controls.append({"type": "trust", "value": 1 + road["index"] % 7, "prompt": road["prompt"]})
    started = time.monotonic()
    driver.await_last_answer()
    assert time.monotonic() - started < 1.0 and not driver.awaiting_report
    reported = with_reports(record, driver.answers).roads.set_index("index")["reported_trust"]
    assert pd.isna(reported[0]) and pd.isna(reported[1])   # the start road, and the unanswered prompt
    assert {int(k): int(v) for k, v in reported.dropna().items()} == {
        road["index"]: 1 + road["index"] % 7 for road in roads[1:]}
    assert with_reports(record, {}) is record   # no answers: the record as the tracker logged it


def test_without_an_answer_the_end_waits_final_report_seconds_then_goes_on(tmp_path):
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([])
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5,
                          LiveOptions(pace=1e6, client="scripted", final_report_seconds=0.3))
    record = run_planned_episode(study_context(config), task, driver=driver, observer=driver.observe,
                                 person=driver)
    started = time.monotonic()
    driver.await_last_answer()
    assert 0.3 <= time.monotonic() - started < 5.0
    assert with_reports(record, driver.answers) is record


def test_a_takeover_in_the_step_a_road_closes_goes_to_the_next_road_and_the_station_sees_it(tmp_path):
    # where the first road closes, from the same episode without a takeover: its road event is sent
    # in the closing step, stamped with the step before it
    *_, quiet, _ = live_episode(tmp_path, [])
    before_closing = next(m["t"] for m in quiet.sent if m["type"] == "road" and m["index"] == 1)
    config = tiny_config(tmp_path, participants=1)
    task = plan_episodes(config)[0]
    pipe = Pipe([])
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=1e6, client="scripted"),
                          episode_id=task.episode_id)

    def observe(sumo, ego, mode, road):
        if ego.time == before_closing:   # read now, so the episode applies it in the closing step
            pipe.controls.append({"type": "takeover"})
        driver.observe(sumo, ego, mode, road)

    record = run_planned_episode(study_context(config), task, driver=driver, observer=observe, person=driver)
    taken = dict(zip(record.roads["index"], record.roads["takeover"], strict=True))
    assert (bool(taken[1]), bool(taken[2])) == (False, True)
    # the station is told: the takeover shows as a mode change, after the first road's event
    kinds = [(m["type"], m.get("mode"), m.get("index")) for m in pipe.sent if m["type"] in ("mode", "road")]
    assert kinds[:3] == [("road", None, 1), ("mode", "manual", None), ("mode", "auto", None)]


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class SlowStation(Pipe):
    """A station that confirms the frame of `t` only once `at` wall seconds have passed."""

    def __init__(self, clock: Clock, t: float, at: float) -> None:
        super().__init__()
        self.clock, self.t, self.at = clock, t, at

    def poll(self, timeout: float = 0.0) -> bool:
        self.clock.now += timeout
        if self.t is not None and self.clock.now >= self.at:
            self.controls.append({"type": "shown", "t": self.t})
            self.t = None
        return bool(self.controls)


def test_the_episode_waits_for_a_station_that_falls_behind_and_not_for_one_gone_silent():
    clock = Clock()
    pipe = SlowStation(clock, t=29.5, at=101.0)
    driver = RemoteDriver(pipe, (1, 2, 3, 4, 5, 6, 7), 5, LiveOptions(pace=20.0), clock=clock)
    driver.origin, driver.frame_time = (clock.now - 10.0, 0.0), 30.0   # the wall clock is past step 30.5
    assert driver.wait_for_the_wall_clock(30.5) is False          # no confirmation yet: not waited for
    driver.apply({"type": "shown", "t": 25.0})                     # 5 s behind the last frame sent
    assert driver.wait_for_the_wall_clock(30.5) is True            # waited; the pace goes on from here
    assert clock.now >= 101.0 and driver.station_time == 29.5
    assert "shown" not in {event["type"] for event in driver.events}   # the pace's, not an event
    # a station that confirms nothing more for STATION_WAIT is no longer waited for
    driver.frame_time = 60.0
    started = clock.now
    assert driver.wait_for_the_wall_clock(60.5) is True
    assert STATION_WAIT < clock.now - started < STATION_WAIT + 0.1 and driver.station_time is None
    assert driver.wait_for_the_wall_clock(61.0) is False
