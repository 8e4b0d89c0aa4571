"""The steppable episode (harness/simulation/stepping.py): stepped by hand with the policy's own
choices it gives the very logs of `run_episode` / `run_model_episode`; a decision point offers the
town's legal moves and refuses others; an end is final; a closed episode leaves SUMO usable."""

from __future__ import annotations

import numpy as np
import pytest

from tests.harness.helpers import SPECS
from trustroute.harness.simulation.episode import EpisodeOptions, SumoEpisode, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import ModelEpisode, run_model_episode
from trustroute.harness.simulation.stepping import DecisionPoint, End
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import trust_free_policy


@pytest.fixture(scope="module")
def setup(town, driver):
    return EpisodeSetup(town=town, driver_model=driver, spec=load_spec(SPECS / "phi1.toml", town))


def _driver(setup, seed):
    return SyntheticDriver(setup.driver_model, np.random.default_rng(seed))


def _stepped(episode) -> tuple[End, list[DecisionPoint]]:
    points = []
    point = episode.advance()
    while isinstance(point, DecisionPoint):
        points.append(point)
        assert episode.advance() is point   # asked again before the choice: the same point
        episode.choose(episode.policy.next_junction(point.context))
        point = episode.advance()
    return point, points


def _same_tables(a, b) -> None:
    for name, table in a.tables().items():
        assert table.equals(b.tables()[name]), name
    timeless = ("wall_seconds",)
    assert {k: v for k, v in a.summary.items() if k not in timeless} == \
        {k: v for k, v in b.summary.items() if k not in timeless}


def test_a_sumo_episode_stepped_by_hand_logs_what_run_episode_logs(setup, net_path):
    policy = trust_free_policy(setup.town, setup.spec)
    expected = run_episode(setup, policy, _driver(setup, 5), "s", 5, EpisodeOptions(net_path=net_path))
    episode = SumoEpisode(setup, policy, _driver(setup, 5), "s", 5, EpisodeOptions(net_path=net_path))
    end, points = _stepped(episode)
    _same_tables(end.record, expected)
    assert len(points) == end.record.summary["junctions"]
    for point in points:
        assert point.legal == setup.town.actions(point.context.road)
    assert episode.advance() is end   # the end is final


def test_a_model_episode_stepped_by_hand_logs_what_run_model_episode_logs(setup):
    policy = trust_free_policy(setup.town, setup.spec)
    expected = run_model_episode(setup, policy, _driver(setup, 8), "m", 8)
    end, points = _stepped(ModelEpisode(setup, policy, _driver(setup, 8), "m", 8))
    _same_tables(end.record, expected)
    assert [p.context.road for p in points] == end.record.roads["directed_road"].tolist()[:-1]


def test_an_illegal_choice_is_refused_and_a_closed_episode_leaves_sumo_usable(setup, net_path):
    policy = trust_free_policy(setup.town, setup.spec)
    episode = SumoEpisode(setup, policy, _driver(setup, 2), "c", 2, EpisodeOptions(net_path=net_path))
    point = episode.advance()
    assert isinstance(point, DecisionPoint)
    illegal = next(j for j in setup.town.junctions if j not in point.legal)
    with pytest.raises(ValueError, match="not a legal move"):
        episode.choose(illegal)
    episode.choose(point.legal[0])
    assert isinstance(episode.advance(), DecisionPoint | End)
    episode.close()   # mid-episode: SUMO's simulation goes as after an error
    with pytest.raises(RuntimeError, match="closed before its end"):
        episode.advance()
    expected = run_episode(setup, policy, _driver(setup, 5), "s", 5, EpisodeOptions(net_path=net_path))
    again = run_episode(setup, policy, _driver(setup, 5), "s", 5, EpisodeOptions(net_path=net_path))
    _same_tables(again, expected)
