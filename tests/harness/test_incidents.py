"""Each incident kind appears in SUMO as it should, is logged with its ids and is removed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.episode import EGO_ID, run_episode
from trustroute.harness.episode_tracker import EpisodeSetup
from trustroute.harness.incidents import obstacle
from trustroute.networks.sumo_net import build_net
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec


class Recorder:
    """Observer: the SUMO state around the ego at every step, read straight from SUMO."""

    def __init__(self) -> None:
        self.steps: list[dict] = []

    def __call__(self, sumo, ego, mode, road) -> None:
        leader = sumo.vehicle.getLeader(EGO_ID, 200.0)
        self.steps.append({
            "time": ego.time, "road": ego.road, "pos": ego.lane_position, "xy": (ego.x, ego.y),
            "speed": ego.speed, "lane": sumo.vehicle.getLaneID(EGO_ID), "leader": leader[0] if leader else "",
            "persons": {p: (sumo.person.getRoadID(p), tuple(sumo.person.getPosition(p)))
                        for p in sumo.person.getIDList()},
            "vehicles": {v: (sumo.vehicle.getLaneID(v), sumo.vehicle.getLanePosition(v),
                             sumo.vehicle.getSpeed(v)) for v in sumo.vehicle.getIDList() if v != EGO_ID},
            "collisions": [(c.collider, c.victim) for c in sumo.simulation.getCollisions()],
        })


@pytest.fixture(scope="module", params=["auto", "manual"])
def episode(request, town, driver, tmp_path_factory):
    net = build_net(town, cache_dir=tmp_path_factory.mktemp("nets")).path
    spec = load_spec(SPECS / "phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, fallback_after=None)
    kinds = () if request.param == "auto" else ("pedestrian", "obstacle", "truck")
    synthetic = ForcedTakeover(SyntheticDriver(driver, np.random.default_rng(4), initial_trust=4), kinds)
    recorder = Recorder()
    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "inc", seed=3, net_path=net,
                         observer=recorder)
    return record, recorder.steps


def _incident(record, kind):
    rows = record.incidents[record.incidents["incident"] == kind]
    assert len(rows) == 1
    return rows.iloc[0]


def test_route_and_logged_ids(episode):
    record, steps = episode
    assert record.roads["directed_road"].tolist() == list(INCIDENT_ROUTE)
    assert record.summary["end_reason"] == "destination"
    assert sorted(record.incidents["incident"]) == ["obstacle", "pedestrian", "truck"]
    for row in record.incidents.itertuples():
        assert row.sumo_ids and row.injected_time <= row.in_view_time <= row.removed_time
        ids = row.sumo_ids.split(",")
        seen = [s["time"] for s in steps if any(i in s["persons"] or i in s["vehicles"] for i in ids)]
        assert seen, f"{row.sumo_ids} never appeared in SUMO"
        # removed once passed (or at the road's end): gone from SUMO afterwards
        assert max(seen) <= row.removed_time
        assert not any(i in s["persons"] or i in s["vehicles"]
                       for i in ids for s in steps if s["time"] > row.removed_time)
    assert not any(s["collisions"] for s in steps)


def test_pedestrian_crosses_and_the_ego_yields(episode):
    record, steps = episode
    person = _incident(record, "pedestrian").sumo_ids
    on_crossing = [s for s in steps if person in s["persons"] and "_c" in s["persons"][person][0]]
    assert len(on_crossing) >= 4, "the pedestrian never walked on a crossing"
    assert {s["persons"][person][0].split("_")[0] for s in on_crossing} == {":A"}   # at the start of A-B
    # the ego waited (standing) while the person was on the crossing, and never came close
    assert any(s["speed"] < 0.1 for s in on_crossing)
    distances = [math.dist(s["xy"], s["persons"][person][1]) for s in steps if person in s["persons"]]
    assert min(distances) > 2.0
    # it reached the far sidewalk: the crossing was completed before the ego drove through
    last = [s["persons"][person][0] for s in steps if person in s["persons"]][-1]
    assert last in ("A-B", ":A_w1") or last.startswith(":A_w")
    first_on_road = next(s["time"] for s in steps if s["road"] == "A-B")
    assert first_on_road > on_crossing[-1]["time"] - 1.0


def test_obstacle_blocks_the_lane(episode):
    record, steps = episode
    vehicle = _incident(record, "obstacle").sumo_ids
    present = [s for s in steps if vehicle in s["vehicles"]]
    lane, position, speed = present[-1]["vehicles"][vehicle]
    assert lane == "C-J_1" and speed == 0.0
    assert all(s["vehicles"][vehicle][1] == pytest.approx(position) for s in present)   # it never moves
    blocked = [s for s in present if s["lane"] == lane and s["pos"] < position and s["speed"] < 0.1]
    assert len(blocked) * 0.5 >= obstacle.CLEAR_AFTER - 0.5, "the ego did not wait behind the obstacle"
    assert all(s["pos"] < position for s in present if s["road"] == "C-J")   # never through it
    after = [s for s in steps if s["road"] == "C-J" and s["pos"] > position]
    assert after and vehicle not in after[0]["vehicles"]


def test_truck_is_ahead(episode):
    record, steps = episode
    truck = _incident(record, "truck").sumo_ids
    following = [s for s in steps if s["leader"] == truck and s["road"] == "J-K"]
    assert len(following) >= 10
    assert all(s["vehicles"][truck][1] > s["pos"] for s in following)
    assert max(s["vehicles"][truck][2] for s in following) <= 6.0 + 1e-6
    # the ego ends up at the truck's pace
    assert min(s["speed"] for s in following[len(following) // 2:]) < 7.0
