"""The incident scenes in SUMO: waiting for an oncoming truck, objects where the log says,
pedestrian safety over seeded episodes, measured failures, and a driver whose trust depends on
them (docs/scenes.md)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import trustroute.participants as participants
from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.simulation.episode import EGO_ID, EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.performance import PerformanceLimits, PerformanceMonitor
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import load_town
from trustroute.participants.driver_model import load_driver_model
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec

PERFORMANCE_MODEL = Path(participants.__file__).parent / "data" / "driver_model_performance.json"


@pytest.fixture(scope="module")
def town():
    # The default town (Town01): INCIDENT_ROUTE has the pedestrian on A-B, the obstacle on the
    # 236 m C-J (room to stage a wait and an overtake) and the truck on J-K.
    return load_town()


@pytest.fixture(scope="module")
def net(town, tmp_path_factory):
    return build_net(town, cache_dir=tmp_path_factory.mktemp("nets")).path


@pytest.fixture(scope="module")
def setup(town, driver):
    return EpisodeSetup(town=town, driver_model=driver, spec=load_spec(SPECS / "phi1.toml", town),
                        fallback_after=None)


# A-B entered from the start road F-A, where the ego is still accelerating: a late person there
# steps out when a gentle stop suffices. Entered from E-A at free speed (INCIDENT_ROUTE), the person
# can appear no earlier than the incident's injection, when the ego already needs 4.1-4.7 m/s² to
# stop (by where the 0.5 s step falls): every late step-out there that needs more than the ego's
# comfortable 4.5 m/s² is an emergency brake (docs/scenes.md).
COMFORTABLE_DECEL = 4.5
LATE_ROUTE = ("F-A", "A-B", "B-C")


@pytest.fixture(scope="module")
def late_setup(setup):
    return replace(setup, spec=replace(setup.spec, start=LATE_ROUTE[0]))


def _run(setup, net, seed, overrides=None, observer=None, model=None, takeovers=(), route=INCIDENT_ROUTE):
    model = model if model is not None else setup.driver_model
    synthetic = ForcedTakeover(SyntheticDriver(model, np.random.default_rng(seed), initial_trust=4),
                               takeovers)
    return run_episode(setup, FixedRoute(route), synthetic, f"s{seed}", seed=seed,
                       options=EpisodeOptions(net_path=net, observer=observer,
                                              scene_overrides=overrides or {}))


def _ego_steps(setup, net, seed, overrides):
    steps = []

    def observe(sumo, ego, mode, road):
        others = {v: (sumo.vehicle.getLaneID(v), tuple(sumo.vehicle.getPosition(v)))
                  for v in sumo.vehicle.getIDList() if v != EGO_ID}
        persons = {p: tuple(sumo.person.getPosition(p)) for p in sumo.person.getIDList()}
        steps.append({"time": ego.time, "lane": ego.lane, "pos": ego.lane_position, "speed": ego.speed,
                      "xy": (ego.x, ego.y),
                      "objects": {**others, **{p: ("", xy) for p, xy in persons.items()}}})

    record = _run(setup, net, seed, overrides, observe)
    return record, steps


def _obstacle_row(record):
    rows = record.incidents[record.incidents["incident"] == "obstacle"]
    assert len(rows) == 1
    return rows.iloc[0]


def test_an_oncoming_truck_makes_the_ego_wait_before_overtaking(setup, net):
    free = {"obstacle": {"oncoming": False, "bicycle": False}}
    met = {"obstacle": {"oncoming": True, "oncoming_offset": 1.0, "bicycle": False}}
    record_free, free_steps = _ego_steps(setup, net, 3, free)
    record_met, met_steps = _ego_steps(setup, net, 3, met)
    row = _obstacle_row(record_met)
    assert "oncoming=inc3.oncoming" in row.scene and row.sumo_ids.endswith("inc3.oncoming")

    def first_opposite(steps):
        return next(s for s in steps if s["lane"] == "J-C_1")

    def slowest_before_overtaking(steps):
        # From the obstacle's injection until the ego is first in the oncoming lane (on Town01 SUMO
        # may pull out before C-J itself, already in the junction from B-C).
        start = first_opposite(steps)["time"]
        return min(s["speed"] for s in steps if row.injected_time <= s["time"] < start)

    # alone, the ego pulls out without stopping; with the truck timed to meet it, it (nearly) stops behind the
    # obstacle and pulls out only once the truck has passed it
    assert slowest_before_overtaking(free_steps) > 5.0
    assert slowest_before_overtaking(met_steps) < 2.0
    met_time = float(row.scene.split("met_time=")[1].split()[0])
    assert first_opposite(met_steps)["time"] >= met_time
    assert first_opposite(met_steps)["time"] > first_opposite(free_steps)["time"] + 3.0
    assert record_met.incidents.set_index("incident").loc["obstacle", "time_lost"] > \
        record_free.incidents.set_index("incident").loc["obstacle", "time_lost"] + 3.0
    # and the obstacle is there all along
    obstacle = "inc3.obstacle"
    during = [s for s in met_steps if row.injected_time < s["time"] < row.removed_time]
    assert all(obstacle in s["objects"] for s in during[1:])


def test_every_incident_is_in_sumo_where_and_when_the_log_says(setup, net):
    record, steps = _ego_steps(setup, net, 5, {"truck": {"parked": True}})
    assert sorted(record.incidents["incident"]) == ["obstacle", "pedestrian", "truck"]
    by_time = {s["time"]: s for s in steps}
    for row in record.incidents.itertuples():
        main_id = row.sumo_ids.split(",")[0]
        seen = [s["time"] for s in steps if main_id in s["objects"]]
        assert seen and row.injected_time <= min(seen) and max(seen) <= row.removed_time
        # in view at the logged time, at the logged place
        at_view = by_time[row.in_view_time]
        assert math.dist(at_view["objects"][main_id][1], (row.x, row.y)) < 0.5
        assert math.dist(at_view["xy"], (row.x, row.y)) <= 80.0
        # on its road: lanes of the incident road or of its opposite direction (persons: no lane)
        lane = at_view["objects"][main_id][0]
        u, v = row.directed_road.split("-")
        # an oncoming truck may still be on the road it comes from (`from=` in the scene)
        came_from = row.scene.split("from=")[1].split()[0] if "from=" in row.scene else None
        assert lane == "" or lane.rsplit("_", 1)[0] in (row.directed_road, f"{v}-{u}", came_from)
        assert row.passed_time <= row.removed_time
    # J-K's opposite lane is shorter than truck.PARKED_MIN_LANE: the parked car is not placed even when
    # drawn (the truck could not pass it before the meeting), so the truck is the only object
    truck = record.incidents[record.incidents["incident"] == "truck"].iloc[0]
    assert "parked=no" in truck.scene and truck.sumo_ids.count(",") == 0


SEEDS = range(40)


@pytest.fixture(scope="module")
def nominal_records(setup, net):
    return [_run(setup, net, seed) for seed in SEEDS]


@pytest.mark.slow
def test_no_pedestrian_collision_under_autopilot_and_measured_failures(nominal_records):
    """Default scenes over seeded episodes: never a collision with a person, the timing draws vary,
    and the measured performance is `fail` in a few episodes (rare, not zero)."""
    records = nominal_records
    incidents = [r.incidents for r in records]
    pedestrians = [f[f["incident"] == "pedestrian"].iloc[0] for f in incidents]
    assert not any(p.collided for p in pedestrians)
    assert all(p.min_pedestrian_distance > 1.0 for p in pedestrians)
    timings = {p.scene.split()[0] for p in pedestrians}
    assert {"timing=early", "timing=none"} <= timings
    fails = sum(int((f["performance"] == "fail").sum()) for f in incidents)
    rows = sum(len(f) for f in incidents)
    assert 0 < fails < 0.2 * rows
    # a failure is what a measure shows, and the roads table carries the same verdict
    for record in records:
        roads = record.roads.set_index("directed_road")
        for row in record.incidents.itertuples():
            assert (row.performance == "fail") == isinstance(row.failed_measures, str)
            assert roads.loc[row.directed_road, "performance"] == row.performance


def test_limits_decide_the_verdict():
    monitor = PerformanceMonitor()
    monitor.head_on(1.2)
    monitor.pedestrian_distance(2.5)
    assert monitor.result(PerformanceLimits(min_head_on_ttc=1.5)) == "fail"
    assert monitor.failed_measures(PerformanceLimits(min_head_on_ttc=1.0)) == []
    assert monitor.failed_measures(PerformanceLimits(min_head_on_ttc=1.0, min_pedestrian_distance=3.0)) == [
        "pedestrian_distance"]
    with pytest.raises(ValueError, match="max_deceleration"):
        PerformanceLimits(max_deceleration=-1.0)


def test_background_traffic_is_seeded(setup, net):
    from dataclasses import replace

    from trustroute.harness.simulation.sumo_start import SumoConfig

    config = replace(SumoConfig(), background_vehicles=6)
    counts = []

    def observe(sumo, ego, mode, road):
        counts.append(sum(1 for v in sumo.vehicle.getIDList() if v.startswith("bg")))

    driver = setup.driver_model
    runs = []
    for _ in range(2):
        counts.clear()
        synthetic = SyntheticDriver(driver, np.random.default_rng(1), initial_trust=4)
        record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "bg", seed=1,
                             options=EpisodeOptions(net_path=net, config=config, observer=observe))
        runs.append((record.kinematics.copy(), list(counts)))
    assert runs[0][0].equals(runs[1][0]) and runs[0][1] == runs[1][1]
    assert max(runs[0][1]) == 6 and min(runs[0][1][5:]) >= 4


def test_a_forced_late_pedestrian_is_a_measured_fail(setup, late_setup, net):
    """A person who steps out when the ego needs more than its comfortable deceleration to stop:
    the AV's emergency brake stops it without a collision, and the hard braking is a measured
    `fail`. The same person stepping out when a gentle stop suffices is yielded to: `succ`.
    (The draw was a margin in metres before the AV could brake for a person; it is now the
    deceleration the ego needs, docs/scenes.md.)"""
    late = _run(setup, net, 3, {"pedestrian": {"timing": "late", "late_deceleration": 6.0}})
    row = late.incidents[late.incidents["incident"] == "pedestrian"].iloc[0]
    assert row.scene.startswith("timing=late late_deceleration=6.00")
    assert row.performance == "fail" and "deceleration" in row.failed_measures
    assert not row.collided and row.max_deceleration > 5.0
    assert late.roads.set_index("directed_road").loc["A-B", "performance"] == "fail"
    yielded = _run(late_setup, net, 3, {"pedestrian": {"timing": "late", "late_deceleration": 1.5}},
                   route=LATE_ROUTE)
    row = yielded.incidents[yielded.incidents["incident"] == "pedestrian"].iloc[0]
    assert row.performance == "succ" and not row.collided and row.max_deceleration <= 5.0
    assert row.min_pedestrian_distance > 2.0


@pytest.mark.slow
def test_late_pedestrians_are_never_hit_under_autopilot(setup, late_setup, net):
    """Every pedestrian forced late, with the drawn deceleration of each seed (docs/scenes.md):
    the emergency brake stops the ego before the person every time. Entered at free speed
    (INCIDENT_ROUTE) the ego needs at least 4 m/s² when it sees the person: each step-out that
    needs more than the comfortable deceleration is an emergency brake (a measured `fail`), each
    other a gentle stop (`succ`), and both happen; entered from the start road (LATE_ROUTE) they
    are all gentle stops (`succ`)."""
    verdicts = {}
    for route, where in ((INCIDENT_ROUTE, setup), (LATE_ROUTE, late_setup)):
        rows = []
        for seed in range(15):
            record = _run(where, net, seed, {"pedestrian": {"timing": "late"}}, route=route)
            rows.append(record.incidents[record.incidents["incident"] == "pedestrian"].iloc[0])
        assert not any(row.collided for row in rows)
        assert all(row.min_pedestrian_distance > 1.0 for row in rows)
        needs = [float(row.scene.split("seen_needing=")[1].split()[0]) for row in rows]
        for row, need in zip(rows, needs, strict=True):
            assert row.performance == ("fail" if need > COMFORTABLE_DECEL else "succ"), (route, need)
        if route == INCIDENT_ROUTE:
            assert min(needs) >= 4.0
        verdicts[route] = {row.performance for row in rows}
    assert verdicts == {INCIDENT_ROUTE: {"fail", "succ"}, LATE_ROUTE: {"succ"}}


def test_skipped_reads_change_nothing(setup, net, monkeypatch):
    """The runner and the oncoming truck skip SUMO reads while a bound on the closing speed says
    nothing can happen; with the bound switched off (a read every step) the logs are the same."""
    import pandas as pd

    from trustroute.harness.simulation import episode
    from trustroute.harness.simulation.incidents import oncoming

    overrides = {"obstacle": {"oncoming": True, "oncoming_offset": -1.0}, "truck": {"parked": True}}
    bounded = [_run(setup, net, seed, overrides, takeovers=("truck",)) for seed in (2, 9)]
    monkeypatch.setattr(episode, "MAX_CLOSING", float("inf"))
    monkeypatch.setattr(oncoming.OncomingVehicle, "_quiet_until", lambda self, now, gap: now)
    every_step = [_run(setup, net, seed, overrides, takeovers=("truck",)) for seed in (2, 9)]
    for a, b in zip(bounded, every_step, strict=True):
        pd.testing.assert_frame_equal(a.incidents, b.incidents)
        pd.testing.assert_frame_equal(a.kinematics, b.kinematics)
        assert a.incidents["in_view_time"].notna().all()


# The benchmark's route through every kind on Town01: E-A, A-B pedestrian, B-C, C-D truck, D-E obstacle.
OBSTACLE_RUN = '''name = "obstacle_run"
start = "E-A"
formula = "F v1"

[states]
v1 = ["D-E"]
'''


@pytest.mark.slow
def test_a_seeded_study_measures_failures_and_the_example_driver_reacts(tmp_path):
    """Two seeded SUMO studies through the study runner (OBSTACLE_RUN on Town01), one with
    the default driver model and one with the example model whose trust drops after `fail`:
    SUMO measures the same failures in both (the scenes do not depend on the driver model), at
    least one; trust trajectories are the same where nothing failed and differ somewhere else."""
    from trustroute.core.dataset import read_roads
    from trustroute.harness.study.config import study_config_from_dict
    from trustroute.harness.study.manifest import consolidate
    from trustroute.harness.study.plan import plan_episodes
    from trustroute.harness.study.runner import run_study

    assert load_driver_model(PERFORMANCE_MODEL).depends_on_performance
    (tmp_path / "obstacle_run.toml").write_text(OBSTACLE_RUN)
    roads = {}
    for label, model in (("default", None), ("example", str(PERFORMANCE_MODEL))):
        # On the default town. About 6 % of these episodes fail (docs/scenes.md, mostly the obstacle
        # on D-E): 100 participants expect about 6 failures (none with probability below 1 %; the
        # seed is fixed).
        study = {"name": label, "participants": 100, "seed": 1, "engine": "sumo",
                 "specs": [str(tmp_path / "obstacle_run.toml")], "conditions": ["free"]}
        if model:
            study["driver_model"] = model
        config = study_config_from_dict({"study": study}, "scenes", tmp_path)
        run = run_study(config, tmp_path / label, progress=False)
        assert not run.failed
        consolidate(run.study_dir, run.context, plan_episodes(config), config.content_hash, {}, {})
        roads[label] = read_roads(run.study_dir).sort_values(["episode_id", "index"], ignore_index=True)
    default, example = roads["default"], roads["example"]
    assert default["directed_road"].tolist() == example["directed_road"].tolist()
    assert default["performance"].tolist() == example["performance"].tolist()
    assert (default["performance"] == "fail").sum() >= 1
    differ = 0
    for episode_id, group in default.groupby("episode_id"):
        other = example[example["episode_id"] == episode_id]
        same = group["trust_after"].tolist() == other["trust_after"].tolist()
        if (group["performance"] == "fail").any():
            differ += not same
        else:
            assert same, episode_id
    assert differ >= 1


def test_the_leader_subscription_reaches_every_ttc_limit():
    """A leader TTC below a limit needs a gap below ROAD_SPEED × limit: the subscription's
    look-ahead covers the largest limit configured (and grows with it)."""
    from trustroute.harness.simulation.episode import leader_horizon
    from trustroute.harness.simulation.sumo_start import SumoConfig
    from trustroute.networks.sumo_net import ROAD_SPEED

    default = SumoConfig()
    largest = max(limits.min_ttc for limits in default.performance_limits.values())
    assert leader_horizon(default) >= largest * ROAD_SPEED
    wide = SumoConfig(performance_limits={"none": PerformanceLimits(min_ttc=4.0)})
    assert leader_horizon(wide) >= 4.0 * ROAD_SPEED > leader_horizon(default)


def test_an_oncoming_truck_comes_from_the_road_leading_in_unless_unseen(setup, net):
    """A truck timed to meet the obstacle later than the opposite road alone allows starts on the
    road leading into it (in SUMO from the injection on, where SUMO's overtaking checks see it);
    drawn `unseen`, it enters at the opposite road's start only later (docs/scenes.md)."""
    entered = {}
    for unseen in (False, True):
        overrides = {"obstacle": {"oncoming": True, "oncoming_offset": 6.0, "bicycle": False,
                                  "unseen": unseen}}
        record, steps = _ego_steps(setup, net, 3, overrides)
        row = _obstacle_row(record)
        came_from = row.scene.split("from=")[1].split()[0]
        first = next(s for s in steps if "inc3.oncoming" in s["objects"])
        entered[unseen] = (came_from, first["time"] - row.injected_time, first["objects"]["inc3.oncoming"][0])
    seen_from, seen_after, seen_lane = entered[False]
    assert seen_from not in ("C-J", "J-C") and seen_lane == f"{seen_from}_1" and seen_after <= 1.0
    unseen_from, unseen_after, unseen_lane = entered[True]
    assert unseen_from == "J-C" and unseen_lane == "J-C_1" and unseen_after > 2.0
