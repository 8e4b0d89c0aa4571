"""The model engine: per-episode path vs vectorised batch path vs the exact evaluation.

Independent computations that must agree: `run_model_episode` (EpisodeTracker + SyntheticDriver,
one episode at a time), `simulate_batch` (numpy, all episodes at once) and
`policies.evaluation.plain.evaluate` (exact tree unfolding, no sampling). Agreement is checked within
4.5 standard errors, so a wrong rule (a missed fallback, an off-by-one junction cap, a takeover
drawn from trust after the road) fails while sampling noise does not.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from tests.policies.model.test_trust_pomdp import random_model
from trustroute.harness.simulation.episode_tracker import EpisodeSetup
from trustroute.harness.simulation.model_engine import monte_carlo, run_model_episode, simulate_batch
from trustroute.participants.driver_model import driver_model_from_dict
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy

Z = 4.5


class LoopingPolicy(RoutingPolicy):
    """Deterministic, belief-dependent, loops: exercises the fallback and many distinct decisions."""

    name = "looping"

    def __init__(self, town) -> None:
        self.town = town

    def next_junction(self, context) -> str:
        actions = self.town.actions(context.road)
        # high believed trust: first option; otherwise second (loops around the town)
        high = float(context.belief[5:].sum()) > 0.5
        return actions[0] if high or len(actions) == 1 else actions[len(context.route) % len(actions)]


def _per_episode(setup, policy, driver, count, seed):
    rng = np.random.default_rng(seed)
    summaries = [
        run_model_episode(setup, policy, SyntheticDriver(driver, rng), f"e{i}", 0).summary
        for i in range(count)
    ]
    return summaries


def _close(a: float, b: float, se: float) -> bool:
    return abs(a - b) <= Z * se + 1e-12


@pytest.mark.parametrize("spec_name", ["phi1", "phi2"])
def test_batch_matches_exact_for_free_policy(town, driver, pomdp, spec_name):
    spec = load_spec(f"specs/{spec_name}.toml", town)
    policy = trust_free_policy(town, spec)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    exact = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=20))
    batch = simulate_batch(setup, policy, 40_000, np.random.default_rng(1))
    p = exact.satisfaction_probability
    assert exact.gap < 1e-9
    assert _close(batch.satisfied.mean(), p, math.sqrt(p * (1 - p) / 40_000))
    se_trust = batch.final_trust.std() / math.sqrt(40_000)
    assert _close(batch.final_trust.mean(), exact.expected_final_trust, se_trust)
    assert _close(batch.junctions.mean(), exact.expected_junctions, batch.junctions.std() / 200 + 1e-9)


@pytest.mark.slow
def test_per_episode_path_matches_exact_and_batch_for_looping_policy(town, driver, pomdp):
    spec = load_spec("specs/phi1.toml", town)
    policy = LoopingPolicy(town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec, fallback_after=20)
    exact = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=20))
    n_single, n_batch = 600, 20_000
    single = _per_episode(setup, policy, driver, n_single, 3)
    batch = simulate_batch(setup, policy, n_batch, np.random.default_rng(4))
    p = exact.satisfaction_probability
    rate = np.mean([s["satisfied"] for s in single])
    assert _close(rate, p, math.sqrt(p * (1 - p) / n_single))
    assert _close(batch.satisfied.mean(), p, math.sqrt(p * (1 - p) / n_batch))
    # fallback and end reasons agree between the two simulation paths
    fired_single = np.mean([s["fallback_fired"] for s in single])
    assert _close(fired_single, batch.fallback_fired.mean(), math.sqrt(0.25 / n_single + 0.25 / n_batch))
    assert _close(fired_single, exact.fallback_probability, math.sqrt(0.25 / n_single))
    # episode length against the exact expectation (catches a fallback one junction early or late)
    se_junctions = batch.junctions.std() / math.sqrt(n_batch) + 1e-9
    assert _close(batch.junctions.mean(), exact.expected_junctions, se_junctions)
    se_trust = batch.final_trust.std() / math.sqrt(n_batch)
    assert _close(batch.final_trust.mean(), exact.expected_final_trust, se_trust)
    for reason in ("accepted", "destination", "rejected", "cap"):
        a = np.mean([s["end_reason"] == reason for s in single])
        b = np.mean(batch.end_reason == reason)
        assert _close(a, b, math.sqrt(0.25 / n_single + 0.25 / n_batch)), reason
    for key in ("junctions", "takeovers", "mean_trust", "final_trust"):
        values = np.array([s[key] for s in single], dtype=float)
        other = getattr(batch, key).astype(float)
        se = math.sqrt(values.var() / n_single + other.var() / n_batch) + 1e-9
        assert _close(values.mean(), other.mean(), se), key


def test_batch_with_a_population_of_drivers(town, driver):
    """Drivers who never take over and trust fully vs the nominal: the batch must use each
    episode's own driver model (a mix-up shows in the takeover counts)."""

    data = driver.to_dict()
    data["takeover_probability"] = {k: [0.0] * 7 for k in data["takeover_probability"]}
    calm = driver_model_from_dict(data, "calm")
    spec = load_spec("specs/phi2.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    index = np.arange(2000) % 2
    batch = simulate_batch(
        setup,
        trust_free_policy(town, spec),
        2000,
        np.random.default_rng(5),
        drivers=[driver, calm],
        driver_index=index,
    )
    assert batch.takeovers[index == 1].sum() == 0
    assert batch.takeovers[index == 0].sum() > 0


def test_model_episode_log_columns(town, driver):
    spec = load_spec("specs/phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=driver, spec=spec)
    record = run_model_episode(
        setup, trust_free_policy(town, spec), SyntheticDriver(driver, np.random.default_rng(0)), "x", 0
    )
    roads = record.roads
    assert list(roads["index"]) == list(range(len(roads)))
    assert roads["sim_time_in"].isna().all() and roads["sim_time_out"].isna().all()
    assert record.kinematics.empty
    assert record.summary["junctions"] == len(roads) - 1
    # the driver's takeover is decided at the trust before the road; the AV's filter saw it
    assert (roads["reported_trust"].iloc[1:] >= 1).all() and pd.isna(roads["reported_trust"].iloc[0])


SUMMARY_KEYS = ("satisfied", "junctions", "takeovers", "final_trust", "end_reason", "fallback_fired")


def test_one_batch_episode_is_the_tracker_episode_draw_for_draw(town):
    """Without trust reports (the batch path draws none) the batch path on one episode and the
    per-episode path (tracker + synthetic driver) draw the same numbers from the same seed, so they
    drive the same episode: one driver step, one set of episode rules."""
    model = random_model(np.random.default_rng(12), 7, performance_dependent=True, sparse=False)
    spec = load_spec("specs/phi1.toml", town)
    setup = EpisodeSetup(town=town, driver_model=model, spec=spec, report_every=10_000)
    for policy in (trust_free_policy(town, spec), LoopingPolicy(town)):
        outcomes = set()
        for seed in range(40):
            record = run_model_episode(setup, policy, SyntheticDriver(model, np.random.default_rng(seed)),
                                       "e", 0)
            assert record.roads["reported_trust"].isna().all()
            batch = simulate_batch(setup, policy, 1, np.random.default_rng(seed)).frame().iloc[0]
            assert tuple(record.summary[k] for k in SUMMARY_KEYS) == tuple(batch[k] for k in SUMMARY_KEYS)
            assert record.summary["mean_trust"] == pytest.approx(batch["mean_trust"], rel=1e-12)
            outcomes.add(tuple(record.summary[k] for k in ("takeovers", "final_trust", "end_reason")))
        assert len(outcomes) >= 5     # the episodes differ: the equality is not a constant


@pytest.mark.slow
def test_monte_carlo_is_the_batch_path_one_episode_at_a_time(town, pomdp):
    spec = load_spec("specs/phi2.toml", town)
    policy = LoopingPolicy(town)
    setup = EpisodeSetup(town=town, driver_model=pomdp.driver, spec=spec)
    # An exact, draw-for-draw equality, not an estimate: 100 episodes (both outcomes among them, and
    # over two thousand decisions) are enough for one extra or missing draw to show.
    episodes = 100
    result = monte_carlo(pomdp, spec, policy, episodes, np.random.default_rng(6))
    rng = np.random.default_rng(6)
    runs = [simulate_batch(setup, policy, 1, rng) for _ in range(episodes)]
    assert result.satisfaction == np.mean([run.satisfied[0] for run in runs])
    assert result.mean_final_trust == np.mean([run.final_trust[0] for run in runs])
    assert result.decisions == sum(int(run.junctions[0]) for run in runs)
    assert result.policy == "looping+fallback20" and 0 < result.satisfaction < 1


@pytest.mark.slow
def test_monte_carlo_of_the_baseline_agrees_with_exact_evaluation(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    policy = trust_free_policy(pomdp.town, spec)
    exact = evaluate(pomdp, spec, policy)
    # 2000 episodes are enough to fail a takeover drawn from the trust after the road (about 5
    # standard errors off here) or from one level above the trust before it (about 8)
    episodes = 2000
    result = monte_carlo(pomdp, spec, policy, episodes, np.random.default_rng(4))
    assert result.episodes == episodes
    assert abs(result.satisfaction - exact.lower) <= 4 * result.standard_error
    assert result.decisions == episodes * (len(baseline_route(pomdp.town, spec)) - 1)


def test_monte_carlo_drives_the_pomdps_driver(town):
    """A driver whose AV always fails and who drops to the lowest trust on a failure ends every
    episode there; the same driver with an AV that never fails does not: the Monte Carlo draws the
    AV's performance from the model."""
    model = random_model(np.random.default_rng(3), 7, performance_dependent=True, sparse=False)
    data = model.to_dict()
    for incident in data["trust_transition"]:
        for action in data["trust_transition"][incident]:
            data["trust_transition"][incident][action]["fail"] = [[1.0] + [0.0] * 6] * 7
    data["failure_probability"] = {k: [1.0] * 7 for k in data["incident_types"]}
    failing = build_pomdp(town, driver_model_from_dict(data, "failing"))
    data["failure_probability"] = {k: [0.0] * 7 for k in data["incident_types"]}
    never = build_pomdp(town, driver_model_from_dict(data, "never"))
    spec = load_spec("specs/phi1.toml", town)
    policy = trust_free_policy(town, spec)
    low = monte_carlo(failing, spec, policy, 400, np.random.default_rng(1)).mean_final_trust
    high = monte_carlo(never, spec, policy, 400, np.random.default_rng(1)).mean_final_trust
    assert low == 1.0 and high > 2.5
