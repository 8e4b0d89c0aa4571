"""pomdp-py POUCT baseline and the Monte Carlo runner."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.pomdp_py.pouct import monte_carlo, pouct_policy
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import DecisionContext


def dfa_state_along(town, spec, route, belief):
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    q = np.array([dfa.initial])
    for road in route:
        q = labeller.step(q, np.array([town.state_index(road)]), belief[None])
    return int(q[0])


def test_monte_carlo_of_the_baseline_agrees_with_exact_evaluation(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    policy = trust_free_policy(pomdp.town, spec)
    exact = evaluate(pomdp, spec, policy)
    result = monte_carlo(pomdp, spec, policy, 3000, np.random.default_rng(4))
    assert result.episodes == 3000
    assert abs(result.satisfaction - exact.lower) <= 4 * result.standard_error
    assert result.decisions == 3000 * (len(baseline_route(pomdp.town, spec)) - 1)


def test_pouct_takes_the_accepting_move_when_one_exists(pomdp):
    """One junction before the last waypoint with full trust: only K -> L satisfies φ1 now."""
    town = pomdp.town
    spec = load_spec("specs/phi1.toml", town)
    route = baseline_route(town, spec)
    assert route[-1] == "K-L"
    belief = np.zeros(7)
    belief[6] = 1.0
    q = dfa_state_along(town, spec, route[:-1], belief)
    policy = pouct_policy(pomdp, spec, np.random.default_rng(0), num_sims=60, max_depth=4)
    context = DecisionContext(route=tuple(route[:-1]), dfa_state=q, belief=belief)
    assert policy.next_junction(context) == "L"
    assert len(policy.planning_seconds) == 1


@pytest.mark.slow
def test_pouct_episodes_run_and_are_reproducible(pomdp):
    spec = load_spec("specs/phi2.toml", pomdp.town)
    results = []
    for _ in range(2):
        rng = np.random.default_rng(8)
        policy = pouct_policy(pomdp, spec, rng, num_sims=30, max_depth=8)
        results.append(monte_carlo(pomdp, spec, policy, 4, rng))
    assert results[0].satisfaction == results[1].satisfaction
    assert results[0].decisions == results[1].decisions > 0
    assert results[0].policy == "pouct+fallback20"
    assert 0.0 <= results[0].satisfaction <= 1.0
