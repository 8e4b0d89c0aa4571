"""Bounds on Pr_max by search over joint beliefs, against brute force and the belief-only search."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.policies.trust_paths import optimum
from tests.policies.trust_specs import random_problem
from trustroute.policies.belief.trust_state_relaxation import relaxed_guide, relaxed_values
from trustroute.policies.evaluation.trust_state import evaluate_joint_table
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.protocol import Certificate
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.trust_state_synthesis.search import JointLimits, joint_bounds, joint_search
from trustroute.policies.trust_state_synthesis.synthesis import decision_table

TOLERANCE = 1e-9


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["trust", "belief", "mixed"]),
       horizon=st.integers(1, 3))
def test_bounds_bracket_the_brute_force_optimum(driver, seed, kind, horizon):
    rng = np.random.default_rng(seed)
    pomdp, spec = random_problem(rng, driver, kind)
    reference = optimum(pomdp, spec, horizon)
    bounded = joint_bounds(pomdp, spec, depth=0, horizon=horizon)
    assert bounded.lower == pytest.approx(reference, abs=TOLERANCE)
    assert bounded.lower - TOLERANCE <= reference <= bounded.upper + TOLERANCE
    # Cutting the tree (pruning, few nodes) and the unbounded objective keep the bounds sound.
    cut = joint_bounds(pomdp, spec, depth=0, horizon=horizon, prune_below=0.05, max_nodes=3)
    assert cut.lower - TOLERANCE <= reference <= cut.upper + TOLERANCE
    unbounded = joint_bounds(pomdp, spec, depth=horizon)
    assert unbounded.upper >= reference - TOLERANCE
    # Unbounded: at least the bounded optimum (the leaves continue open-loop), at most the upper.
    assert bounded.lower - TOLERANCE <= unbounded.lower <= unbounded.upper + TOLERANCE
    assert float(relaxed_values(pomdp, spec, horizon)[horizon].max()) <= 1.0


@pytest.mark.parametrize("name", ["phi1", "phi2_strict"])
def test_without_trust_atoms_the_search_equals_the_belief_only_exact_search(pomdp, name):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    for horizon in (5, 7):
        bounds = joint_bounds(pomdp, spec, depth=0, horizon=horizon)
        assert bounds.lower == pytest.approx(exact_optimum(pomdp, spec, horizon), abs=1e-12)
        assert bounds.gap <= 1e-11


def test_a_search_cut_to_few_nodes_still_brackets_the_exact_value(pomdp):
    """φ1 with the trust atom: cut nodes get the open-loop lower bound and the relaxation's upper.
    Each search names what ended it (`stopped_by`): the complete one convergence, the cut one its
    node cap (by max_nodes or prune_below), the unbounded one the depth that left live nodes."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    exact = joint_bounds(pomdp, spec, depth=0, horizon=8)
    cut = joint_bounds(pomdp, spec, depth=0, horizon=8, max_nodes=50)
    assert cut.cut_nodes > 0 and exact.cut_nodes == 0
    assert cut.lower - TOLERANCE <= exact.lower <= cut.upper + TOLERANCE
    assert cut.nodes < exact.nodes / 10
    pruned = joint_bounds(pomdp, spec, depth=0, horizon=8, prune_below=0.01)
    assert pruned.cut_nodes == 0 and pruned.gap > exact.gap
    assert (exact.stopped_by, cut.stopped_by, pruned.stopped_by) == ("convergence", "node cap", "node cap")
    assert joint_bounds(pomdp, spec, depth=4).stopped_by == "depth cap"


def test_with_a_guide_the_cut_search_lower_bound_is_the_value_of_the_policy_it_returns(pomdp):
    """Nodes below the expanded ones follow the policy's own rule off its rows (the guide), so
    with room for all of them the search's lower bound is exactly the returned policy's value."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    horizon = 10
    guide = relaxed_guide(pomdp, spec, horizon)
    bounds, decisions = joint_search(pomdp, spec, horizon, horizon,
                                     limits=JointLimits(max_nodes=20, guided_nodes=10**7), guide=guide)
    assert bounds.cut_nodes > 0
    policy = JointTablePolicy(decision_table(decisions), pomdp, spec, guide_horizon=horizon,
                              certificate=Certificate(horizon=horizon))
    value = evaluate_joint_table(pomdp, spec, policy, horizon)
    assert value.lower == value.upper and value.stopped == "convergence"
    assert bounds.lower == pytest.approx(value.lower, abs=1e-12)
    # Without the guide the open-loop continuation the search credits is not what the policy does.
    open_loop, decisions = joint_search(pomdp, spec, horizon, horizon, limits=JointLimits(max_nodes=20))
    policy = JointTablePolicy(decision_table(decisions), pomdp, spec, guide_horizon=horizon,
                              certificate=Certificate(horizon=horizon))
    assert abs(open_loop.lower - evaluate_joint_table(pomdp, spec, policy, horizon).lower) > 1e-9
