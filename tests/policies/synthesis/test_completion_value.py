"""Cluster bounds on the trust-free completion's value against the exact observation tree.

The exact value is an independent recursion over observation sequences through the one filter
(TrustPOMDP.belief_update) and the labeller's strict labels, along the completion's road sequence.
The cluster bounds must bracket it from every road of seeded random small towns, with the default
merge grid (then they are nearly exact) and with a coarse grid that merges almost everything (then
the enclosures and the pessimistic labels at thresholds carry the soundness). End to end, the
returned policy of a search whose open nodes use coarse bounds is worth at least L.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.synthesis.test_synthesis_random import random_spec, random_town
from trustroute.policies.evaluate import evaluate
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.product_mdp import build_product
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import free_completion, state_only_task
from trustroute.policies.synthesis import completion_value
from trustroute.policies.synthesis.belief_cells import apply_symbol, observation_symbols
from trustroute.policies.synthesis.completion_value import FreeRoute, completion_bounds
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesis.search import held_choice, policy_choice, synthesize

HORIZON = 8
TOLERANCE = 1e-12


def exact_free_value(tables, symbols, route, x, q, p, belief, steps) -> float:
    if tables.accepting[q]:
        return 1.0
    if tables.rejecting[q] or steps == 0:
        return 0.0
    x2, p2 = int(route.next_road[x, q, p]), int(route.next_task[x, q, p])
    total = 0.0
    for symbol in symbols.by_incident[int(tables.pomdp.road_incident[x2])]:
        posterior, probability = apply_symbol(belief[None], symbols, symbol)
        if probability[0] <= 0:
            continue
        q2 = int(tables.step(np.array([q]), np.array([x2]), posterior)[0])
        total += float(probability[0]) * exact_free_value(tables, symbols, route, x2, q2, p2,
                                                          posterior[0], steps - 1)
    return total


def _problem(driver, seed):
    rng = np.random.default_rng(seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, driver)
    spec = random_spec(rng, town, np.asarray(pomdp.initial_belief))
    tables = build_product(pomdp, spec)
    task = state_only_task(town, spec)
    # the free completion the synthesis values open nodes by (moves per (x, q, p))
    route = FreeRoute.build(tables, free_completion(town, spec).slot,
                            np.asarray(task.next_state, dtype=np.int64))
    return tables, observation_symbols(pomdp), route, task


def _bounds_and_exact(driver, seed, deadline=None):
    tables, symbols, route, task = _problem(driver, seed)
    belief = np.asarray(tables.pomdp.initial_belief, dtype=float)
    roads = np.arange(tables.n_x)
    q = np.full(roads.size, tables.initial_q)
    p = np.full(roads.size, task.initial_state)
    steps = np.full(roads.size, HORIZON)
    bounds = completion_bounds(tables, symbols, route, roads, q, p, np.repeat(belief[None], roads.size, 0),
                               steps, deadline)
    exact = np.array([exact_free_value(tables, symbols, route, int(x), int(q[0]), int(p[0]), belief,
                                       HORIZON) for x in roads])
    return bounds, exact


@pytest.mark.parametrize("seed", range(8))
def test_default_bounds_bracket_and_nearly_equal_the_exact_tree(driver, seed):
    bounds, exact = _bounds_and_exact(driver, seed)
    assert np.all(bounds.lower <= exact + TOLERANCE)
    assert np.all(exact <= bounds.upper + TOLERANCE)
    # few enough sequences that only equal beliefs merge: the bounds are the exact value
    assert np.max(bounds.upper - bounds.lower) <= 1e-9


@pytest.mark.parametrize("seed", range(12))
def test_coarse_merging_stays_sound(driver, seed, monkeypatch):
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    bounds, exact = _bounds_and_exact(driver, seed)
    assert np.all(bounds.lower <= exact + TOLERANCE), (bounds.lower, exact)
    assert np.all(exact <= bounds.upper + TOLERANCE), (exact, bounds.upper)


class _SteppedClock:
    """perf_counter that advances one second per call: a deadline of k stops the propagation
    before its (k + 1)-th junction step."""

    def __init__(self) -> None:
        self.now = -1.0

    def perf_counter(self) -> float:
        self.now += 1.0
        return self.now


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("steps_before_deadline", [0, 1, 3])
def test_bounds_stopped_by_the_deadline_stay_sound(driver, seed, steps_before_deadline, monkeypatch):
    monkeypatch.setattr(completion_value, "time", _SteppedClock())
    bounds, exact = _bounds_and_exact(driver, seed, deadline=float(steps_before_deadline))
    assert np.all(bounds.lower <= exact + TOLERANCE), (bounds.lower, exact)
    assert np.all(exact <= bounds.upper + TOLERANCE), (exact, bounds.upper)


def test_bounds_stopped_by_the_deadline_are_looser(driver, monkeypatch):
    """Stopped after one junction step, the mass in flight widens the bounds (the soundness test
    above is not vacuous); with no deadline they are nearly exact."""
    monkeypatch.setattr(completion_value, "time", _SteppedClock())
    stopped = [_bounds_and_exact(driver, seed, deadline=1.0)[0] for seed in range(6)]
    assert sum(b.interrupted for b in stopped) >= 3
    assert max(float(np.max(b.straddle)) for b in stopped) > 0.01


def test_coarse_merging_loosens_where_labels_matter(driver, monkeypatch):
    """The coarse grid does widen some bound (the soundness test above is not vacuous)."""
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    widest = max(float(np.max(_bounds_and_exact(driver, seed)[0].straddle)) for seed in range(12))
    assert widest > 0.01


def test_paper_rule_is_refused(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    tables = build_product(pomdp, spec)
    task = state_only_task(pomdp.town, spec)
    route = FreeRoute.build(tables, np.where(task.next_slot >= 0, task.next_slot, 0),
                            np.asarray(task.next_state, dtype=np.int64))
    with pytest.raises(ValueError, match="Bayes"):
        completion_bounds(tables, observation_symbols(pomdp, "paper"), route, np.array([0]),
                          np.array([tables.initial_q]), np.array([task.initial_state]),
                          np.asarray(pomdp.initial_belief)[None], np.array([3]))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["phi1", "phi2_strict"])
def test_policy_is_worth_l_with_coarse_completion_bounds(pomdp, name, monkeypatch):
    """Loose bounds at open nodes make the rule that holds rows to the free move bind; the returned
    policy (exact evaluation through the RoutingPolicy interface) is still worth at least L, and
    the brute-force optimum lies in [L, U]."""
    monkeypatch.setattr(completion_value, "INITIAL_RESOLUTION", 0.05)
    monkeypatch.setattr(completion_value, "CLUSTER_CAP", 3)
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    horizon = 9
    result = synthesize(pomdp, spec, tau=0.05, horizon=horizon, completion="bounds")
    value = evaluate(pomdp, spec, result.policy, fallback_after=None, max_junctions=horizon)
    assert value.gap == 0.0
    assert result.lower > 0.1
    assert result.lower <= value.lower + TOLERANCE
    optimum = exact_optimum(pomdp, spec, horizon)
    assert result.lower - TOLERANCE <= optimum <= result.upper + TOLERANCE


def test_hold_rule_keeps_held_rows_on_the_free_move():
    """A held row leaves the free move only for a move whose L reaches its free_upper; other rows
    take the best L; the free move's L is raised to free_lower."""
    rng = np.random.default_rng(7)
    lower_q = rng.uniform(0, 1, size=(50, 3))
    strict_q, upper_q = lower_q.copy(), lower_q + 0.1
    free = rng.integers(0, 3, size=50)
    best = policy_choice(lower_q, strict_q, upper_q)
    assert (best != free).any()
    none = np.zeros(50, dtype=bool)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, none, np.zeros(50), np.ones(50))
    assert np.array_equal(move, best)
    every = np.ones(50, dtype=bool)
    best_lower = lower_q.max(axis=1)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, every, np.zeros(50), best_lower + 0.01)
    assert np.array_equal(move, free)
    move, _, _ = held_choice(lower_q, strict_q, upper_q, free, every, np.zeros(50), best_lower)
    assert np.array_equal(move, best)
    move, raised, _ = held_choice(lower_q, strict_q, upper_q, free, none, np.full(50, 2.0), np.ones(50))
    assert np.array_equal(move, free) and np.all(raised[np.arange(50), free] == 2.0)
