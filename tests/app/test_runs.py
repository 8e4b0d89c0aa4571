"""A run is put together once: the episode of a compiled problem drives with the problem's own
trust POMDP rather than building another."""

from __future__ import annotations

import pytest

from trustroute.app.inputs import load_inputs
from trustroute.app.policy import PolicySettings, policy_for
from trustroute.app.problem import compile_problem
from trustroute.app.runs import EpisodeSettings, run_one_episode
from trustroute.harness.simulation import episode_tracker
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.participants.driver_model import load_driver_model


def test_an_episode_of_a_compiled_problem_builds_no_second_pomdp(monkeypatch, tmp_path):
    problem = compile_problem(load_inputs("phi1"))
    policy = policy_for(problem, "free", PolicySettings(cache_dir=tmp_path))
    built = []
    real = episode_tracker.build_pomdp
    monkeypatch.setattr(episode_tracker, "build_pomdp", lambda *args: built.append(args) or real(*args))
    run = run_one_episode(problem, policy, EpisodeSettings(engine="model", seed=3))
    assert built == [] and len(run.record.roads) >= 2
    # a setup without one builds its own, from its town and driver model
    setup = EpisodeSetup(town=problem.town, driver_model=problem.driver, spec=problem.spec)
    assert setup.model.pomdp is not problem.pomdp and len(built) == 1


def test_a_setup_refuses_a_pomdp_of_another_driver_model():
    problem = compile_problem(load_inputs("phi1"))
    other = load_driver_model()   # equal in content, another object: not the POMDP's
    with pytest.raises(ValueError, match="not the trust POMDP of its town and driver model"):
        EpisodeSetup(town=problem.town, driver_model=other, spec=problem.spec, pomdp=problem.pomdp)
