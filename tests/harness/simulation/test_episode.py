"""The SUMO engine: route following, determinism, logs, bad input, flat memory over many episodes."""

from __future__ import annotations

import math
import os
from collections import Counter

import numpy as np
import pandas as pd
import pytest

from tests.harness.helpers import SPECS
from trustroute.core.dataset import KINEMATICS_SCHEMA, ROADS_SCHEMA
from trustroute.core.errors import InputError
from trustroute.harness.simulation import sumo_start
from trustroute.harness.simulation.episode import EpisodeOptions, SumoEpisode, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.stepping import run_to_end
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import town_from_dict
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy


@pytest.fixture(scope="module")
def phi1(town):
    return load_spec(SPECS / "phi1.toml", town)


@pytest.fixture(scope="module")
def setup(town, driver, phi1):
    return EpisodeSetup(town=town, driver_model=driver, spec=phi1)


def _episode(setup, net_path, seed, trust=None, episode_id="e"):
    driver = SyntheticDriver(setup.driver_model, np.random.default_rng(seed), initial_trust=trust)
    return run_episode(setup, trust_free_policy(setup.town, setup.spec), driver, episode_id, seed,
                       EpisodeOptions(net_path=net_path))


def _roads_driven(kinematics: pd.DataFrame) -> list[str]:
    """The sequence of (non-internal) edges the ego was on, from SUMO's own lane ids."""
    edges = [lane.rsplit("_", 1)[0] for lane in kinematics["lane"] if not lane.startswith(":")]
    return [e for i, e in enumerate(edges) if i == 0 or e != edges[i - 1]]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_free_phi1_follows_the_baseline_route(setup, net_path, seed):
    record = _episode(setup, net_path, seed)
    route = baseline_route(setup.town, setup.spec)
    assert record.roads["directed_road"].tolist() == route
    assert _roads_driven(record.kinematics) == route
    assert record.roads["action"].iloc[:-1].tolist() == [r.split("-")[1] for r in route[1:]]
    assert pd.isna(record.roads["action"].iloc[-1])
    summary = record.summary
    assert summary["junctions"] == len(route) - 1
    assert summary["end_reason"] in ("accepted", "destination")
    assert summary["satisfied"] == (summary["end_reason"] == "accepted")
    assert summary["takeovers"] == int(record.roads["takeover"].sum())
    assert summary["final_trust"] == record.roads["trust_after"].iloc[-1]


def test_log_schema(setup, net_path):
    record = _episode(setup, net_path, 5)
    assert tuple(record.roads.columns) == tuple(ROADS_SCHEMA.names)
    assert tuple(record.kinematics.columns) == tuple(KINEMATICS_SCHEMA.names)
    roads = record.roads
    assert (roads["sim_time_in"].diff().iloc[1:] > 0).all()
    assert (roads["sim_time_out"] >= roads["sim_time_in"]).all()
    # trust chains from road to road; the performance column is measured on every driven road
    assert (roads["trust_before"].iloc[1:].to_numpy() == roads["trust_after"].iloc[:-1].to_numpy()).all()
    assert set(roads["performance"].iloc[1:]) <= {"succ", "fail"}
    kin = record.kinematics
    assert set(kin["mode"]) <= {"auto", "manual"}
    assert kin["time"].is_monotonic_increasing and kin["speed"].between(0, 14.5).all()
    assert record.summary["sim_seconds"] == pytest.approx(kin["time"].iloc[-1])
    for frame in (record.roads, record.kinematics, record.incidents):
        assert (frame["episode_id"] == "e").all()


def test_same_seed_same_logs(setup, net_path):
    first, second = _episode(setup, net_path, 7), _episode(setup, net_path, 7)
    pd.testing.assert_frame_equal(first.roads, second.roads)
    pd.testing.assert_frame_equal(first.kinematics, second.kinematics)
    pd.testing.assert_frame_equal(first.incidents, second.incidents)
    strip = ("wall_seconds",)
    assert {k: v for k, v in first.summary.items() if k not in strip} == {
        k: v for k, v in second.summary.items() if k not in strip}
    other = _episode(setup, net_path, 8)
    assert not (other.roads["trust_after"].tolist() == first.roads["trust_after"].tolist()
                and other.roads["takeover"].tolist() == first.roads["takeover"].tolist()
                and other.kinematics.equals(first.kinematics))


def test_the_clock_is_read_once_per_advance_and_counted_in_steps(setup, net_path, monkeypatch):
    """SUMO's clock is asked once per `advance` and counted step by step from there: every step's
    time is the one SUMO reports (read here by an observer), and no step asks SUMO for it."""
    import libsumo

    native = libsumo.libsumo._libsumo
    asked = []
    get_time = native.simulation_getTime

    def counted():
        asked.append(1)
        return get_time()

    monkeypatch.setattr(native, "simulation_getTime", counted)
    seen = []

    def observer(sumo, ego, mode, road):
        seen.append((ego.time, get_time()))

    driver = SyntheticDriver(setup.driver_model, np.random.default_rng(3))
    record = run_episode(setup, trust_free_policy(setup.town, setup.spec), driver, "e", 3,
                         EpisodeOptions(net_path=net_path, observer=observer))
    assert seen and all(ours == sumo for ours, sumo in seen)
    assert record.kinematics["time"].tolist() == [ours for ours, _ in seen]
    assert len(asked) <= len(record.roads)   # one per advance: one per road and the end


def test_no_object_known_to_be_out_of_the_simulation_is_asked_for(setup, net_path, monkeypatch):
    """A truck taken out behind the ego, or one seen to have left, is not removed again at the
    road's end, and a person taken out is not looked for: SUMO's refusal of each is an exception.
    (The first read that finds a truck gone is the one refusal left.)"""
    import libsumo

    native = libsumo.libsumo._libsumo
    refused = []

    def refusals_noted(name):
        call = getattr(native, name)

        def asked(*args):
            try:
                return call(*args)
            except Exception:
                refused.append(name)
                raise

        return asked

    for name in ("vehicle_remove", "vehicle_getRoadID", "person_getRoadID", "person_getPosition"):
        monkeypatch.setattr(native, name, refusals_noted(name))
    records = [_episode(setup, net_path, seed) for seed in range(8)]
    assert sum(len(record.incidents) for record in records) >= 16   # trucks and pedestrians met
    assert refused == []


def test_the_nets_static_facts_are_read_once_per_started_simulation(setup, net_path, monkeypatch):
    """Lane lengths, links, a junction's edges, lanes closed to trucks and crossings are read from
    SUMO once in a simulation: the same episode again reads none; a new start reads them again."""
    import libsumo

    native = libsumo.libsumo._libsumo
    read = []

    def reads_noted(name):
        call = getattr(native, name)

        def asked(*args):
            read.append(name)
            return call(*args)

        return asked

    for name in ("lane_getLength", "lane_getLinks", "lane_getShape", "lane_getDisallowed",
                 "junction_getIncomingEdges", "junction_getOutgoingEdges"):
        monkeypatch.setattr(native, name, reads_noted(name))
    sumo_start.close_simulation()
    _episode(setup, net_path, 0)
    first = len(read)
    _episode(setup, net_path, 0)
    assert first > 0 and len(read) == first
    sumo_start.close_simulation()
    _episode(setup, net_path, 0)
    assert len(read) == 2 * first


def test_a_road_whose_incident_is_over_is_watched_no_more(setup, net_path, monkeypatch):
    """Once a road's incident is decided, passed and done (the person taken out behind the ego, the
    truck gone after the meeting), the episode stops stepping it: at most the one step that finds
    it so enters `watch` with it over. The person alone is over for about 16 steps of each episode."""
    watch = SumoEpisode.watch
    over = Counter()   # (episode's seed, road index) -> steps that watched the road with its incident over
    seed = 0   # the episode under way (not its id(): an episode freed gives its id to a later one)

    def watched(self, run, ego):
        if run.decided and not math.isnan(run.passed_time) and run.incident.done():
            over[seed, run.index] += 1
        watch(self, run, ego)

    monkeypatch.setattr(SumoEpisode, "watch", watched)
    episodes = []
    for seed in range(6):
        episodes.append(_episode(setup, net_path, seed))
    assert sum(len(record.incidents) for record in episodes) >= 12
    assert len(over) >= 6 and max(over.values()) == 1


def test_the_step_log_keeps_one_string_per_lane(setup, net_path):
    """SUMO gives the ego's lane id as a new string every step; the step log keeps one copy of each
    (the kinematics table converts repeated objects faster), the same ids as SUMO's."""
    driver = SyntheticDriver(setup.driver_model, np.random.default_rng(3))
    episode = SumoEpisode(setup, trust_free_policy(setup.town, setup.spec), driver, "e", 3,
                          EpisodeOptions(net_path=net_path))
    record = run_to_end(episode)
    lanes = episode.steps.lanes
    assert lanes == record.kinematics["lane"].tolist() and len(lanes) > 50
    assert len({id(lane) for lane in lanes}) == len(set(lanes)) < 20


def test_a_reused_simulation_reads_the_net_files_status_once(setup, net_path, monkeypatch):
    """Returning the open simulation to its snapshot checks the net is a file and reads its
    identity (rewritten in place: another simulation) with one status read of the file."""
    config = sumo_start.SumoConfig()
    with sumo_start.sumo_session(net_path, 1, config):
        pass
    status = os.stat
    read = []

    def noted(path, *args, **kwargs):
        if os.fspath(path) == os.fspath(net_path):
            read.append(path)
        return status(path, *args, **kwargs)

    monkeypatch.setattr(os, "stat", noted)
    with sumo_start.sumo_session(net_path, 2, config):
        pass
    assert len(read) == 1


class LoopPolicy(RoutingPolicy):
    """Circles F-G-I-H-F (never finished): the 20-junction rule has to end the loop."""

    name = "loop"
    ring = {"F": "G", "G": "I", "I": "H", "H": "F"}

    def next_junction(self, context):
        return self.ring.get(context.road.split("-")[1], "F")


def test_fallback_fires_and_is_logged(town, driver, phi1, net_path, caplog):
    setup = EpisodeSetup(town=town, driver_model=driver, spec=phi1, fallback_after=4)
    synthetic = SyntheticDriver(driver, np.random.default_rng(0), initial_trust=6)
    with caplog.at_level("INFO", logger="trustroute.harness.simulation.episode"):
        record = run_episode(setup, LoopPolicy(), synthetic, "fb", 0, EpisodeOptions(net_path=net_path))
    roads = record.roads
    assert record.summary["fallback_fired"]
    assert roads["fallback"].tolist().index(True) == 4 and not roads["fallback"].iloc[:4].any()
    assert any("fallback fired at junction 4" in m for m in caplog.messages)
    assert roads["directed_road"].tolist()[:5] == ["E-A", "A-F", "F-G", "G-I", "I-H"]
    assert record.summary["end_reason"] in ("accepted", "destination")
    assert _roads_driven(record.kinematics) == roads["directed_road"].tolist()


def test_unreadable_net(setup, tmp_path):
    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge")
    with pytest.raises(InputError, match="not a readable SUMO net"):
        _episode(setup, bad, 0)
    with pytest.raises(InputError, match="does not exist"):
        _episode(setup, tmp_path / "missing.net.xml", 0)


def test_net_of_another_town(setup, town, tmp_path):
    data = {"junctions": {"P": [0, 0], "Q": [300, 0], "R": [0, 300]},
            "roads": [["P", "Q"], ["Q", "R"], ["R", "P"]],
            "incidents": {r: "none" for r in ("P-Q", "Q-P", "Q-R", "R-Q", "R-P", "P-R")}}
    other = build_net(town_from_dict(data, "other.json"), cache_dir=tmp_path).path
    with pytest.raises(InputError, match="has no edge for road"):
        _episode(setup, other, 0)


def test_missing_sumo_binary(setup, net_path, monkeypatch):
    import sumolib

    monkeypatch.setattr(sumolib, "checkBinary", lambda name, bindir=None: "sumo-not-installed")
    monkeypatch.setenv("PATH", "")
    sumo_start.sumo_binary.cache_clear()
    try:
        with pytest.raises(InputError, match="SUMO binary 'sumo' was not found"):
            _episode(setup, net_path, 0)
    finally:
        sumo_start.sumo_binary.cache_clear()


def _rss_mb() -> float:
    with open("/proc/self/statm") as handle:
        pages = int(handle.read().split()[1])
    import os

    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


@pytest.mark.slow
def test_two_hundred_episodes_keep_memory_flat(setup, net_path):
    for seed in range(20):   # warm-up: caches, allocator pools
        _episode(setup, net_path, seed)
    before = _rss_mb()
    for seed in range(200):
        record = _episode(setup, net_path, 1000 + seed)
        assert record.summary["end_reason"] in ("accepted", "destination")
    growth = _rss_mb() - before
    assert growth < 25.0, f"RSS grew by {growth:.1f} MB over 200 episodes"


@pytest.mark.slow
def test_sumo_episodes_match_the_exact_evaluation(setup, net_path, pomdp):
    """End to end: satisfaction and final trust of SUMO episodes vs the exact tree evaluation."""
    from trustroute.policies.evaluation.plain import evaluate

    exact = evaluate(pomdp, setup.spec, trust_free_policy(setup.town, setup.spec),
                     EvaluationSettings(fallback_after=20))
    n = 300
    records = [_episode(setup, net_path, 5000 + seed) for seed in range(n)]
    satisfied = np.mean([r.summary["satisfied"] for r in records])
    final_trust = np.mean([r.summary["final_trust"] for r in records])
    p = exact.satisfaction_probability
    assert abs(satisfied - p) < 4 * np.sqrt(p * (1 - p) / n)
    assert abs(final_trust - exact.expected_final_trust) < 0.2


