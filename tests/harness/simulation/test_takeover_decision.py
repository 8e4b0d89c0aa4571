"""When a synthetic driver decides a takeover in SUMO (harness/simulation/takeover_decision.py):
once per road, as the incident's object comes into view, and the takeover starts right then."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.simulation.episode import EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.takeover_decision import VIEW_DISTANCE
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import PENTAGON_TOWN_PATH, load_town
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec


class CountingDriver(ForcedTakeover):
    """Takes over at the given kinds and notes every incident it was asked about."""

    def __init__(self, driver, kinds) -> None:
        super().__init__(driver, kinds)
        self.asked: list[str] = []

    def decides_takeover(self, incident: str) -> bool:
        self.asked.append(incident)
        return super().decides_takeover(incident)


@pytest.fixture(scope="module")
def episode(driver):
    town = load_town(PENTAGON_TOWN_PATH)
    net = build_net(town).path
    spec = load_spec(SPECS / "phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, fallback_after=None)
    counting = CountingDriver(SyntheticDriver(driver, np.random.default_rng(4), initial_trust=5),
                              kinds=("pedestrian", "obstacle", "truck"))
    positions: dict[float, tuple[float, float]] = {}

    def observe(sumo, ego, mode, road):
        positions[ego.time] = (ego.x, ego.y)

    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), counting, "t", seed=4,
                         options=EpisodeOptions(net_path=net, observer=observe))
    return record, counting, positions


def test_the_driver_is_asked_once_on_every_road_after_the_start(episode):
    record, counting, _ = episode
    roads = record.roads[record.roads["index"] > 0]   # "none" roads too: the model decides on every road
    assert counting.asked == roads["incident"].tolist()
    assert "none" in roads["incident"].tolist()


def test_a_takeover_starts_as_the_incident_comes_into_view(episode):
    record, _, positions = episode
    seen = record.incidents[record.incidents["in_view_time"].notna()]
    assert len(seen) >= 2
    for row in seen.itertuples():
        ego = positions[row.in_view_time]
        assert math.dist(ego, (row.x, row.y)) <= VIEW_DISTANCE
        assert row.takeover and row.takeover_start == row.in_view_time
        assert row.takeover_end > row.takeover_start
