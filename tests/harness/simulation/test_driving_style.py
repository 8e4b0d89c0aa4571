"""A forced takeover changes the ego's control in SUMO and is handed back before the next junction."""

from __future__ import annotations

import numpy as np
import pytest

from tests.harness.helpers import INCIDENT_ROUTE, SPECS, FixedRoute, ForcedTakeover
from trustroute.harness.simulation.driving_style import AUTOPILOT, MANUAL
from trustroute.harness.simulation.episode import EGO_ID, EpisodeOptions, run_episode
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.networks.sumo_net import build_net
from trustroute.networks.town import PENTAGON_TOWN_PATH, load_town
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.spec import load_spec


def _run(town, driver, net, kinds):
    spec = load_spec(SPECS / "phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, fallback_after=None)
    steps = []

    def observe(sumo, ego, mode, road):
        steps.append({"time": ego.time, "road": ego.road, "mode": mode,
                      "speed_factor": sumo.vehicle.getSpeedFactor(EGO_ID), "tau": sumo.vehicle.getTau(EGO_ID),
                      "decel": sumo.vehicle.getDecel(EGO_ID), "speed": ego.speed})

    synthetic = ForcedTakeover(SyntheticDriver(driver, np.random.default_rng(0), initial_trust=5), kinds)
    record = run_episode(setup, FixedRoute(INCIDENT_ROUTE), synthetic, "t", seed=0,
                         options=EpisodeOptions(net_path=net, observer=observe))
    return record, steps


@pytest.fixture(scope="module")
def town():
    # Staged on the long-road layout (the pentagon): on the Town01 default town's 50-70 m roads of
    # INCIDENT_ROUTE the driver drives manually for one or two steps, too few to compare speeds.
    return load_town(PENTAGON_TOWN_PATH)


@pytest.fixture(scope="module")
def net(town, tmp_path_factory):
    return build_net(town, cache_dir=tmp_path_factory.mktemp("nets")).path


def test_forced_takeover_switches_control_and_hands_back(town, driver, net):
    record, steps = _run(town, driver, net, kinds=("pedestrian", "obstacle"))
    takeovers = record.incidents[record.incidents["takeover"]]
    assert sorted(takeovers["incident"]) == ["obstacle", "pedestrian"]
    assert record.roads.set_index("directed_road").loc[["A-B", "C-J"], "takeover"].all()
    assert not record.roads.set_index("directed_road").loc["J-K", "takeover"]
    for row in takeovers.itertuples():
        during = [s for s in steps if row.takeover_start < s["time"] < row.takeover_end]
        assert during, "no steps under manual control"
        # SUMO really drives the ego with the human's style while the driver has control
        for s in during:
            assert s["mode"] == "manual"
            assert s["speed_factor"] == pytest.approx(MANUAL.speed_factor)
            assert s["tau"] == pytest.approx(MANUAL.tau) and s["decel"] == pytest.approx(MANUAL.decel)
        # back on autopilot at the next junction after the incident's road
        left_road = next(i for i, s in enumerate(steps) if s["time"] > row.takeover_start
                         and s["road"] == row.directed_road)
        junction = next(s for s in steps[left_road:] if s["road"].startswith(":"))
        assert junction["mode"] == "auto" and junction["speed_factor"] == pytest.approx(1.0)
        assert junction["tau"] == pytest.approx(AUTOPILOT.tau)
        assert row.takeover_end <= junction["time"]
    # the kinematics log carries the same modes
    manual = record.kinematics[record.kinematics["mode"] == "manual"]
    assert len(manual) == sum(1 for s in steps if s["mode"] == "manual")


def test_without_takeover_the_ego_stays_on_autopilot(town, driver, net):
    record, steps = _run(town, driver, net, kinds=())
    assert record.summary["takeovers"] == 0
    assert all(s["speed_factor"] == pytest.approx(AUTOPILOT.speed_factor) for s in steps)
    assert set(record.kinematics["mode"]) == {"auto"}


def test_manual_driving_is_slower_on_a_free_road(town, driver, net):
    """The style is not cosmetic: the driver's speed factor shows in the speeds SUMO drives."""
    _, auto_steps = _run(town, driver, net, kinds=())
    _, manual_steps = _run(town, driver, net, kinds=("pedestrian",))
    manual_on_road = [s for s in manual_steps if s["road"] == "A-B" and s["mode"] == "manual"]
    assert len(manual_on_road) > 20
    assert max(s["speed"] for s in manual_on_road) == pytest.approx(MANUAL.speed_factor * 13.89, abs=0.05)
    assert max(s["speed"] for s in auto_steps if s["road"] == "A-B") == pytest.approx(13.89, abs=0.05)
