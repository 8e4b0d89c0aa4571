"""pomdp-py POUCT baseline and the Monte Carlo runner.

The search's generative step (`ProductModel.step`) is tested against the trust POMDP it
simulates: the joint frequencies of (h, e, θ') with a chi-square test at a fixed seed (and shown to
reject the neighbouring trust row), the AV belief against the Bayes filter, the DFA states against
the compiled spec and the projected task, absorption once the spec is decided, and the legal moves.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.participants.test_synthetic_driver import chi_square_p
from tests.policies.model.test_trust_pomdp import random_model
from trustroute.harness.simulation.model_engine import monte_carlo
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.pomdp_py.pouct import (
    ProductState,
    RoadAction,
    build_product_model,
    pouct_policy,
)
from trustroute.policies.routing.episode_rules import dfa_verdict
from trustroute.policies.routing.free import baseline_route
from trustroute.policies.routing.protocol import DecisionContext

ALPHA = 1e-4


@pytest.fixture(scope="module")
def failing_pomdp(town):
    """A random model with AV failures, so that all four (h, e) outcomes occur."""
    return build_pomdp(town, random_model(np.random.default_rng(12), 7, performance_dependent=True,
                                          sparse=False))


def dfa_state_along(town, spec, route, belief):
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    q = np.array([dfa.initial])
    for road in route:
        q = labeller.step(q, np.array([town.state_index(road)]), belief[None])
    return int(q[0])


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


@pytest.mark.parametrize("start, junction, trust", [("E-A", "B", 3), ("A-F", "G", 0), ("H-L", "K", 6)])
def test_simulated_step_matches_the_model(failing_pomdp, start, junction, trust):
    pomdp, town = failing_pomdp, failing_pomdp.town
    spec = load_spec("specs/phi1.toml", town)
    model = build_product_model(pomdp, spec)
    road = town.state_index(town.successor(start, junction))
    (action,) = [a for a in model.actions[town.state_index(start)] if a.junction == junction]
    assert action.road == road
    belief = np.asarray(pomdp.initial_belief, dtype=float)
    q = int(model.compiled.initial_state(belief))
    state = ProductState(town.state_index(start), trust, q, model.task.projected_state((start,)),
                         belief, (0, 0), False)
    inc = int(pomdp.road_incident[road])
    rng = np.random.default_rng(31 + trust)
    n = 20000
    counts = np.zeros((2, 2, 7))
    seen: dict[tuple[int, int], ProductState] = {}
    for _ in range(n):
        after = model.step(state, action, rng)
        h, e = after.observation
        counts[h, e, after.theta] += 1
        seen.setdefault((h, e), after)
        assert after.road == road
    expected = pomdp.weighted_transition[inc, :, :, trust, :]          # P(h, e, θ' | θ, inc)
    assert expected.sum() == pytest.approx(1.0)
    assert chi_square_p(counts.ravel(), expected.ravel()) > ALPHA
    wrong = trust + 1 if trust < 6 else trust - 1
    assert chi_square_p(counts.ravel(), pomdp.weighted_transition[inc, :, :, wrong, :].ravel()) < ALPHA
    # the rest of the state is the AV's: its Bayes filter on (inc, h, e) and the DFA on the new belief
    assert len(seen) == 4                                             # all (h, e) outcomes occur
    for (h, e), after in seen.items():
        exact = pomdp.belief_update(belief, inc, h, e)[0][0]
        assert np.allclose(after.belief, exact, rtol=1e-12, atol=1e-15)
        assert after.q == model.compiled.step_road(q, town.states[road], after.belief)
        assert after.q_projected == model.task.next_state[state.q_projected, road]
        assert after.over == (dfa_verdict(model.compiled, after.q) is not None)


def test_a_decided_state_is_absorbing(pomdp):
    """Along φ1's trust-free route at full trust the spec is accepted on the last road; from then
    on every move leaves the state as it is (no more reward, no more draws)."""
    town = pomdp.town
    spec = load_spec("specs/phi1.toml", town)
    model = build_product_model(pomdp, spec)
    route = baseline_route(town, spec)
    belief = np.zeros(7)
    belief[6] = 1.0
    state = ProductState(town.state_index(route[0]), 6, int(model.compiled.initial_state(belief)),
                         model.task.projected_state(route[:1]), belief, (0, 0), False)
    rng = np.random.default_rng(0)
    for road in route[1:]:
        assert not state.over
        (action,) = [a for a in model.actions[state.road] if town.states[a.road] == road]
        state = model.step(state, action, rng)
    assert state.over and model.compiled.accepting[state.q]
    before = rng.bit_generator.state
    for action in model.actions[state.road]:
        assert model.step(state, action, rng) is state
    assert rng.bit_generator.state == before


def test_actions_are_the_legal_moves(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    model = build_product_model(pomdp, spec)
    town = pomdp.town
    for x, road in enumerate(town.states):
        actions = model.actions[x]
        assert [a.junction for a in actions] == list(town.actions(road))
        assert [town.states[a.road] for a in actions] == [town.successor(road, j) for j in town.actions(road)]
        assert len(set(actions)) == len(actions) and RoadAction(actions[0].road, "?") == actions[0]
