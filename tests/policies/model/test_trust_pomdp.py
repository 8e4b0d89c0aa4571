"""The trust POMDP's arrays and its belief filters against independent computations.

Bayes: brute-force enumeration over all trust paths θ0..θT on random models and random
observation sequences. Paper: its own formula b' ∝ b·T[inc][h][e], written out with loops.
"""

from __future__ import annotations

import itertools
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustroute.participants.driver_model import DriverModel
from trustroute.policies.model import trust_pomdp
from trustroute.policies.model.trust_pomdp import TrustPOMDP, build_pomdp

INCIDENTS = ("obstacle", "pedestrian", "truck", "none")


def random_model(rng: np.random.Generator, n: int, performance_dependent: bool,
                 sparse: bool) -> DriverModel:
    """Random row-stochastic dynamics; `sparse` puts zeros in rows and 0/1 takeover probabilities,
    so that impossible observations (probability 0) occur too."""
    k = len(INCIDENTS)
    takeover = rng.uniform(0, 1, size=(k, n))
    transition = rng.dirichlet(np.ones(n), size=(k, 2, 2, n))
    if sparse:
        takeover[rng.uniform(size=takeover.shape) < 0.2] = 0.0
        takeover[rng.uniform(size=takeover.shape) < 0.2] = 1.0
        mask = rng.uniform(size=transition.shape) < 0.4
        mask[..., 0] = False                      # keep every row non-empty
        transition = np.where(mask, 0.0, transition)
        transition /= transition.sum(axis=-1, keepdims=True)
    if performance_dependent:
        failure = rng.uniform(0, 0.6, size=(k, n))
    else:
        failure = np.zeros((k, n))
        transition[:, :, 1] = transition[:, :, 0]
    return DriverModel(trust_levels=tuple(range(1, n + 1)), incident_types=INCIDENTS,
                       takeover_probability=takeover, failure_probability=failure,
                       trust_transition=transition, initial_belief=rng.dirichlet(np.ones(n)),
                       trust_free_takeover_probability={}, source_path="<random>")


def brute_force(model: DriverModel, belief: np.ndarray,
                observations: list[tuple[int, int, int]]) -> tuple[np.ndarray, float]:
    """Joint mass of (θ_T, observations) by summing over every trust path; returns the
    normalised posterior of θ_T and the probability of the whole observation sequence."""
    n = model.n_trust
    mass = np.zeros(n)
    for path in itertools.product(range(n), repeat=len(observations) + 1):
        weight = belief[path[0]]
        for t, (inc, h, e) in enumerate(observations):
            before, after = path[t], path[t + 1]
            p_h = model.takeover_probability[inc, before]
            p_e = model.failure_probability[inc, before]
            weight *= ((p_h if h else 1 - p_h) * (p_e if e else 1 - p_e)
                       * model.trust_transition[inc, h, e, before, after])
            if weight == 0.0:
                break
        mass[path[-1]] += weight
    total = mass.sum()
    return (mass / total if total > 0 else mass), total


def pomdp_for(town, model: DriverModel) -> TrustPOMDP:
    return build_pomdp(town, model)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 7), steps=st.integers(1, 4),
       performance_dependent=st.booleans(), sparse=st.booleans(), data=st.data())
def test_bayes_filter_equals_brute_force_over_trust_paths(town, seed, n, steps, performance_dependent,
                                                          sparse, data):
    if n ** (steps + 1) > 20_000:
        steps = 2
    rng = np.random.default_rng(seed)
    model = random_model(rng, n, performance_dependent, sparse)
    pomdp = pomdp_for(town, model)
    observation = st.tuples(st.integers(0, len(INCIDENTS) - 1), st.integers(0, 1),
                            st.integers(0, 1) if performance_dependent else st.just(0))
    observations = data.draw(st.lists(observation, min_size=steps, max_size=steps))
    belief = model.initial_belief
    sequence_probability = 1.0
    for inc, h, e in observations:
        posterior, probability = pomdp.belief_update(belief, inc, h, e)
        assert posterior.shape == (1, n)
        belief = posterior[0]
        sequence_probability *= probability[0]
    expected, total = brute_force(model, model.initial_belief, observations)
    assert sequence_probability == pytest.approx(total, rel=1e-9, abs=1e-300)
    if total > 0:
        assert np.allclose(belief, expected, rtol=1e-9, atol=1e-12)
        assert belief.sum() == pytest.approx(1.0, abs=1e-12)
    else:
        assert not belief.any()                     # zero row, never NaN


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), performance_dependent=st.booleans())
def test_vectorised_update_equals_row_by_row(town, seed, performance_dependent):
    rng = np.random.default_rng(seed)
    model = random_model(rng, 7, performance_dependent, sparse=False)
    pomdp = pomdp_for(town, model)
    beliefs = rng.dirichlet(np.ones(7), size=50)
    inc = rng.integers(0, 4, size=50)
    h = rng.integers(0, 2, size=50)
    e = rng.integers(0, 2, size=50) if performance_dependent else np.zeros(50, dtype=int)
    for rule in ("bayes", "paper"):
        batch, probability = pomdp.belief_update(beliefs, inc, h, e, rule=rule)
        for k in range(50):
            one, p_one = pomdp.belief_update(beliefs[k], int(inc[k]), int(h[k]), int(e[k]), rule=rule)
            assert np.allclose(batch[k], one[0], rtol=1e-12, atol=1e-15)
            assert probability[k] == pytest.approx(p_one[0], rel=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_an_update_in_blocks_of_rows_is_one_update_bit_for_bit(town, seed, monkeypatch):
    """belief_update computes BLOCK_ROWS rows at a time; a row's arithmetic is its own, so blocks
    of any size give one call's values bit for bit (impossible observations and zero rows too)."""
    rng = np.random.default_rng(seed)
    pomdp = pomdp_for(town, random_model(rng, 7, performance_dependent=bool(seed % 2), sparse=True))
    n = 1000
    beliefs = rng.dirichlet(np.ones(7), size=n)
    beliefs[::97] = 0.0
    observation = (rng.integers(0, 4, size=n), rng.integers(0, 2, size=n), rng.integers(0, 2, size=n))
    for rule in ("bayes", "paper"):
        monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", n)
        whole = pomdp.belief_update(beliefs, *observation, rule=rule)
        monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", 37)
        blocks = pomdp.belief_update(beliefs, *observation, rule=rule)
        assert [a.tobytes() for a in blocks] == [a.tobytes() for a in whole]


@pytest.mark.parametrize("seed", range(2))
def test_posteriors_and_probabilities_apart_are_the_update_bit_for_bit(town, seed, monkeypatch):
    """A caller holding the rows' observation probabilities (the evaluation, which sizes a level's
    children by them) asks `posterior` for the rest: the two, each in one call over rows of several
    blocks, are `belief_update`'s values bit for bit."""
    rng = np.random.default_rng(seed)
    pomdp = pomdp_for(town, random_model(rng, 7, performance_dependent=bool(seed % 2), sparse=True))
    monkeypatch.setattr(trust_pomdp, "BLOCK_ROWS", 37)
    n = 1000
    beliefs = rng.dirichlet(np.ones(7), size=n)
    beliefs[::97] = 0.0
    observation = (rng.integers(0, 4, size=n), rng.integers(0, 2, size=n), rng.integers(0, 2, size=n))
    for rule in ("bayes", "paper"):
        posterior, probability = pomdp.belief_update(beliefs, *observation, rule=rule)
        assert pomdp.posterior(beliefs, *observation, rule=rule).tobytes() == posterior.tobytes()
        assert pomdp.observation_probability(beliefs, *observation).tobytes() == probability.tobytes()


def test_an_update_of_many_rows_holds_no_transition_matrix_per_row(pomdp):
    """The transition matrices an update gathers, [rows, θ, θ'] (seven times the beliefs' bytes),
    are gathered BLOCK_ROWS rows at a time: an update of 200,000 rows holds little more than its
    posteriors and their probabilities."""
    n = 200_000
    beliefs = np.tile(np.asarray(pomdp.initial_belief, dtype=float), (n, 1))
    incident = np.arange(n) % len(pomdp.driver.incident_types)
    tracemalloc.start()
    try:
        pomdp.belief_update(beliefs, incident, 1, 0)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * beliefs.nbytes, f"{peak / beliefs.nbytes:.1f} times the beliefs' bytes"


def paper_update(model: DriverModel, belief: np.ndarray, inc: int, h: int, e: int) -> np.ndarray:
    """The authors' update written out: b'(θ') = Σθ b(θ) T[inc][h][e](θ, θ') / Σ(...)."""
    n = model.n_trust
    out = np.zeros(n)
    for after in range(n):
        out[after] = sum(belief[before] * model.trust_transition[inc, h, e, before, after]
                         for before in range(n))
    return out / out.sum()


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), performance_dependent=st.booleans())
def test_paper_rule_is_its_own_formula(town, seed, performance_dependent):
    rng = np.random.default_rng(seed)
    model = random_model(rng, 7, performance_dependent, sparse=False)
    pomdp = pomdp_for(town, model)
    belief = rng.dirichlet(np.ones(7))
    inc, h = int(rng.integers(4)), int(rng.integers(2))
    e = int(rng.integers(2)) if performance_dependent else 0
    posterior, probability = pomdp.belief_update(belief, inc, h, e, rule="paper")
    assert np.allclose(posterior[0], paper_update(model, belief, inc, h, e), rtol=1e-12)
    _, bayes_probability = pomdp.belief_update(belief, inc, h, e, rule="bayes")
    assert probability[0] == pytest.approx(bayes_probability[0], rel=1e-12)


def test_paper_and_bayes_differ_on_the_default_model(pomdp, driver):
    """A takeover on an obstacle says trust was low; only the Bayes rule uses that."""
    inc = driver.incident_index("obstacle")
    bayes, _ = pomdp.belief_update(driver.initial_belief, inc, 1, 0, rule="bayes")
    paper, _ = pomdp.belief_update(driver.initial_belief, inc, 1, 0, rule="paper")
    levels = np.arange(1, 8)
    assert bayes[0] @ levels < paper[0] @ levels - 0.3


def test_unknown_rule_is_rejected(pomdp):
    with pytest.raises(ValueError, match="unknown belief rule"):
        pomdp.belief_update(pomdp.initial_belief, 0, 0, 0, rule="other")


def test_arrays_follow_the_town_and_model(pomdp, town, driver):
    for x, road in enumerate(town.states):
        assert driver.incident_types[pomdp.road_incident[x]] == town.incident(road)
        actions = town.actions(road)
        assert pomdp.action_junctions[x] == actions
        for slot, junction in enumerate(actions):
            assert town.states[pomdp.next_state(x, slot)] == town.successor(road, junction)
        assert (pomdp.successor_table[x, len(actions):] == -1).all()
    # P(h, e | θ, inc) sums to 1 over (h, e); weighted rows sum to the likelihood
    assert np.allclose(pomdp.observation_likelihood.sum(axis=(1, 2)), 1.0)
    assert np.allclose(pomdp.weighted_transition.sum(axis=-1), pomdp.observation_likelihood)
    with pytest.raises(ValueError):
        pomdp.weighted_transition[0, 0, 0, 0, 0] = 1.0      # read-only


def test_observation_probabilities_sum_to_one(pomdp):
    rng = np.random.default_rng(3)
    beliefs = rng.dirichlet(np.ones(7), size=20)
    for inc in range(4):
        total = sum(pomdp.observation_probability(beliefs, inc, h, e) for h in (0, 1) for e in (0, 1))
        assert np.allclose(total, 1.0)


@pytest.mark.parametrize("seed", [3, 11])
def test_the_filter_keeps_the_prior_exactly_where_the_observation_is_impossible(town, seed):
    rng = np.random.default_rng(seed)
    model = random_model(rng, 5, performance_dependent=True, sparse=True)
    pomdp = pomdp_for(town, model)
    beliefs = rng.dirichlet(np.ones(5), size=64)
    beliefs[rng.uniform(size=beliefs.shape) < 0.5] = 0.0   # sparse beliefs: more impossible rows
    beliefs[beliefs.sum(axis=1) == 0, 0] = 1.0
    beliefs /= beliefs.sum(axis=1, keepdims=True)
    incident = rng.integers(0, len(INCIDENTS), size=64)
    h, e = rng.integers(0, 2, size=64), rng.integers(0, 2, size=64)
    # row 0 certainly impossible: sure of a trust level that never takes over there, a takeover
    never = np.argwhere(model.takeover_probability == 0.0)
    assert len(never)
    incident[0], level = never[0]
    beliefs[0], h[0] = np.eye(5)[level], 1
    for rule in ("paper", "bayes"):
        update, probability = pomdp.belief_update(beliefs, incident, h, e, rule=rule)
        posterior, possible = pomdp.filter(beliefs, incident, h, e, rule=rule)
        assert np.array_equal(possible, update.sum(axis=1) > 0)
        assert np.array_equal(posterior[possible], update[possible])
        assert np.array_equal(posterior[~possible], beliefs[~possible])
    # under Bayes both kinds of row were met; impossible ones are those of probability 0
    assert (~possible).any() and possible.any()
    assert (probability[~possible] == 0).all()
