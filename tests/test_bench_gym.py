"""benchmarks/bench_gym.py times the environment against the plain episode it wraps: its baseline
must be that very episode (same roads, same draws), which the benchmark checks before timing; the
check fails when the two sides drive differently."""

from __future__ import annotations

import pytest

from benchmarks import bench_gym
from trustroute.harness.simulation.gym_env import TrustRoutingEnv


def test_the_baseline_is_the_environments_episode_and_a_different_one_is_refused(monkeypatch):
    env = TrustRoutingEnv(bench_gym.SPEC, engine="model")
    steps = bench_gym.check_same_episodes(env, range(4))
    assert steps >= 4 * 2   # every episode chose junctions: the two sides did drive
    monkeypatch.setattr(bench_gym, "agent", lambda observation: 1 - observation["junctions"] % 2)
    with pytest.raises(AssertionError, match="seed 0: the environment's episode"):
        bench_gym.check_same_episodes(env, range(4))
    env.close()
