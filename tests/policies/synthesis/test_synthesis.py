"""Synthesis bounds against brute force, exact evaluation and simple specs of known value."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from tests.policies.routing.test_free_completion import policy_without_rows
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec, spec_from_text
from trustroute.policies.routing.free import baseline_route, trust_free_policy
from trustroute.policies.routing.protocol import DecisionContext
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesis.result import ClusterRun, SearchRun
from trustroute.policies.synthesis.settings import SynthesisSettings

EXACT_TOLERANCE = 1e-9


@pytest.mark.slow
@pytest.mark.parametrize("name", ["phi1", "phi2_strict"])
@pytest.mark.parametrize("belief_rule", ["bayes", "paper"])
def test_small_horizon_bounds_bracket_the_brute_force_optimum(pomdp, packaged_optimum, name, belief_rule):
    """(a) H <= 6 (and 8 for the interesting case): lower <= optimum <= upper, equal when the gap is 0."""
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    for horizon in (5, 6, 8):
        optimum = packaged_optimum(name, horizon, belief_rule)
        closed = synthesize(pomdp, spec,
                            SynthesisSettings(tau=1e-12, horizon=horizon, belief_rule=belief_rule))
        assert closed.lower - EXACT_TOLERANCE <= optimum <= closed.upper + EXACT_TOLERANCE
        if closed.gap <= 1e-12:
            assert closed.lower == pytest.approx(optimum, abs=EXACT_TOLERANCE)
        # A coarse run stops early: the bracket must still hold, and its policy is worth `lower`.
        coarse = synthesize(pomdp, spec, SynthesisSettings(tau=0.3, horizon=horizon, belief_rule=belief_rule))
        assert coarse.lower - EXACT_TOLERANCE <= optimum <= coarse.upper + EXACT_TOLERANCE
    assert optimum > 0.5  # H = 8 leaves room for the whole task: the test is not about zeros


def test_phi1_at_horizon_six_is_the_trust_free_route(pomdp):
    """With 6 junctions only the shortest task route fits: the optimum is the baseline's value."""
    spec = load_spec("specs/phi1.toml", pomdp.town)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-12, horizon=6))
    free = evaluate(pomdp, spec, trust_free_policy(pomdp.town, spec), EvaluationSettings(fallback_after=None))
    assert result.gap <= 1e-12
    assert result.lower == pytest.approx(free.lower, abs=EXACT_TOLERANCE)
    assert baseline_route(pomdp.town, spec) == ["E-A", "A-F", "F-G", "G-I", "I-J", "J-K", "K-L"]


@pytest.mark.parametrize("completion", ["auto", "bounds"])
@pytest.mark.parametrize("name", ["phi1", "phi2", "phi1_strict", "phi2_strict"])
def test_lower_is_the_value_of_the_returned_policy(pomdp, name, completion):
    """policies.evaluation.plain (independent tree unfolding through the RoutingPolicy interface) gives the
    returned policy exactly `lower` within H junctions when open nodes are valued by exact trees
    along the trust-free completion the policy drives there (the default on a town this size), and
    at least `lower` (at most `upper`) with the cluster bounds; L is at least the trust-free
    route's value (with exact trees: at least the free completion's alone, which comes back to a
    waypoint reached with too little trust); also for a coarse run that stops with many open nodes."""
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    horizon = 12
    free = evaluate(pomdp, spec, trust_free_policy(pomdp.town, spec),
                    EvaluationSettings(fallback_after=None, max_junctions=horizon))
    # the free completion alone (a policy without rows: state-only route, then back to what the
    # DFA still needs), which the search values open nodes by
    alone = evaluate(pomdp, spec, policy_without_rows(pomdp, spec),
                     EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert alone.lower >= free.lower - EXACT_TOLERANCE
    for tau in (1e-3, 0.05):
        result = synthesize(pomdp, spec, SynthesisSettings(tau=tau, horizon=horizon, completion=completion))
        value = evaluate(pomdp, spec, result.policy,
                         EvaluationSettings(fallback_after=None, max_junctions=horizon))
        run = result.stats.runs[0]
        assert value.gap == 0.0
        assert result.gap <= tau
        assert run.completion_closed
        assert run.completion_bounds == (completion == "bounds")
        if completion == "auto":
            assert value.lower == pytest.approx(result.lower, abs=EXACT_TOLERANCE)
            assert result.lower >= alone.lower - EXACT_TOLERANCE
        else:
            assert result.lower - EXACT_TOLERANCE <= value.lower <= result.upper + EXACT_TOLERANCE
        assert result.lower >= free.lower - EXACT_TOLERANCE


def _distance_in_junctions(town, start):
    distance = {start: 0}
    queue = deque([start])
    while queue:
        road = queue.popleft()
        for nxt in town.successors(road):
            if nxt not in distance:
                distance[nxt] = distance[road] + 1
                queue.append(nxt)
    return distance


@pytest.mark.slow
def test_state_only_reachability_is_one_or_zero(pomdp):
    """(c) `F target` is worth 1 when the target road is reachable within H junctions, else 0."""
    town = pomdp.town
    distance = _distance_in_junctions(town, "E-A")
    horizon = 3
    for target in ("A-F", "F-G", "G-I", "I-J", "J-K", "D-C", "K-L"):
        spec = spec_from_text(f'name = "reach"\nstart = "E-A"\nformula = "F target"\n'
                              f'[states]\ntarget = ["{target}"]\n', town=town)
        result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon))
        expected = 1.0 if distance[target] <= horizon else 0.0
        assert result.lower == pytest.approx(expected) and result.upper == pytest.approx(expected)
        if target in ("F-G", "D-C"):
            unbounded = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, time_limit=20))
            assert unbounded.lower == pytest.approx(1.0) and unbounded.upper == pytest.approx(1.0)


def test_unsatisfiable_state_sequence_is_zero_unbounded(pomdp):
    """`F (a & X b)` with b not a successor of a: no route satisfies it, so upper must be 0 too
    (the unbounded abstraction must not keep the greatest fixed point 1 on circling states)."""
    town = pomdp.town
    spec = spec_from_text('name = "never"\nstart = "E-A"\nformula = "F (a & X b)"\n'
                          '[states]\na = ["E-A"]\nb = ["B-C"]\n', town=town)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-6, time_limit=20))
    assert result.lower == 0.0 and result.upper == 0.0


def test_policy_acts_on_unvisited_beliefs_and_contexts(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    result = synthesize(pomdp, spec, SynthesisSettings(horizon=8))
    rng = np.random.default_rng(3)
    for road in pomdp.town.states:
        belief = rng.dirichlet(np.ones(7))
        for t in (0, 5, 40):
            context = DecisionContext(route=("E-A",) * t + (road,), dfa_state=int(rng.integers(4)),
                                      belief=belief)
            assert result.policy.next_junction(context) in pomdp.town.actions(road)


def test_unbounded_phi1_reaches_the_target_gap(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    # a work limit (policies/work_clock.py), the time limit far above it only a safety net: the
    # gap is the algorithm's, whatever the machine's load
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, time_limit=900, work_limit=3_000_000))
    assert result.upper == pytest.approx(1.0)
    assert result.gap <= 1e-3
    assert result.stats.converged


def test_unbounded_upper_closes_on_unavoidable_risk(pomdp):
    """Reaching D-K from E-A without ever showing low trust: every route crosses incident roads, so
    the value is below 1. The abstraction alone says 1 (optimistic labels); the unbounded search must
    bring upper down to the value of the returned policy, which the independent evaluator confirms."""
    town = pomdp.town
    spec = spec_from_text('name = "risky"\nstart = "E-A"\nformula = "(!lowtrust) U target"\n'
                          '[states]\ntarget = ["D-K"]\n'
                          '[beliefs.lowtrust]\ncoeffs = [1, 1, 0, 0, 0, 0, 0]\noffset = 0.3\n', town=town)
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, time_limit=900, work_limit=2_000_000))
    assert result.gap <= 1e-3 and 0.5 < result.upper < 0.9
    assert exact_optimum(pomdp, spec, 8) <= result.upper + EXACT_TOLERANCE
    value = evaluate(pomdp, spec, result.policy, EvaluationSettings(fallback_after=None))
    assert result.lower - EXACT_TOLERANCE <= value.lower <= result.upper + EXACT_TOLERANCE


def test_progress_callback_sees_the_search_bounds(pomdp):
    """on_iteration (the progress bars' feed) gets every round's root bounds, bracketing the result."""
    spec = load_spec("specs/phi1.toml", pomdp.town)
    seen: list[tuple[float, float]] = []
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=8),
                        on_iteration=lambda lo, up: seen.append((lo, up)))
    assert seen and all(lo <= up + EXACT_TOLERANCE for lo, up in seen)
    assert seen[-1] == pytest.approx((result.lower, result.upper), abs=EXACT_TOLERANCE)
    # the callback changes nothing
    assert result.lower == synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=8)).lower


@pytest.mark.slow
def test_node_budget_stops_the_search_soundly(pomdp, packaged_optimum):
    """With a small node budget the search stops early; L stays a lower bound of the returned
    policy's value (its completions may be left open) and U an upper bound of the optimum."""
    spec = load_spec("specs/phi1.toml", pomdp.town)
    horizon = 8
    optimum = packaged_optimum("phi1", horizon)
    # the search alone (clusters "off"); by default cluster policies follow an unconverged search
    result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, clusters="off",
                                                       node_budget=300))
    run = result.stats.runs[0]
    assert run.nodes >= 300 and not result.stats.converged
    value = evaluate(pomdp, spec, result.policy,
                     EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert result.lower <= value.lower + EXACT_TOLERANCE
    assert optimum <= result.upper + EXACT_TOLERANCE
    after = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, node_budget=300))
    assert [type(r) for r in after.stats.runs] == [SearchRun, ClusterRun]
    assert after.lower >= result.lower and after.upper <= result.upper
    assert after.lower - EXACT_TOLERANCE <= optimum <= after.upper + EXACT_TOLERANCE
    value = evaluate(pomdp, spec, after.policy,
                     EvaluationSettings(fallback_after=None, max_junctions=horizon))
    assert after.lower <= value.lower + EXACT_TOLERANCE
