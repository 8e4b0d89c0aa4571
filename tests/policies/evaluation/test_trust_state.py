"""Exact evaluation with the joint (θ, q) belief against brute force, Monte Carlo and today's evaluate."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.cli import run_cli
from tests.policies.evaluation.test_plain import RandomStationaryPolicy, simulate
from tests.policies.trust_paths import policy_value
from tests.policies.trust_specs import random_problem
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import evaluate_joint
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesize_spec import synthesize_spec


@pytest.mark.slow
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(["trust", "belief", "mixed"]),
       cap=st.integers(2, 4))
def test_exact_value_equals_brute_force_over_trust_paths(driver, seed, kind, cap):
    rng = np.random.default_rng(seed)
    pomdp, spec = random_problem(rng, driver, kind)
    for policy in (RandomStationaryPolicy(pomdp.town, rng), trust_free_policy(pomdp.town, spec)):
        exact = evaluate_joint(pomdp, spec, policy,
                               EvaluationSettings(fallback_after=None, max_junctions=cap),
                               force_joint=True)
        reference = policy_value(pomdp, spec, policy, cap)
        assert exact.gap == 0.0
        assert exact.lower == pytest.approx(reference, abs=1e-10)
        assert sum(exact.end_mass.values()) == pytest.approx(1.0, abs=1e-10)


def test_merged_unfolding_equals_the_tree_unfolding(pomdp):
    """Merging equal (road, J, beliefs, route memory) nodes changes no number of the evaluation:
    the synthesized joint policy with the fallback (its memory: the projected state) and the
    trust-free route (its memory: the whole route), on φ1 with the trust atom."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    synthesized = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=6, time_limit=20)).policy
    for policy, fallback_after in ((synthesized, 4), (trust_free_policy(pomdp.town, spec), None)):
        merged, tree = (evaluate_joint(pomdp, spec, policy,
                                       EvaluationSettings(fallback_after=fallback_after, max_junctions=12,
                                                          merge=merge)) for merge in (True, False))
        assert tree.gap == 0.0 and merged.gap == 0.0
        for name in ("lower", "upper", "expected_final_trust", "expected_junctions",
                     "fallback_probability"):
            assert getattr(merged, name) == pytest.approx(getattr(tree, name), abs=1e-12), name
        for reason, value in tree.end_mass.items():
            assert merged.end_mass[reason] == pytest.approx(value, abs=1e-12), reason
    assert merged.nodes <= tree.nodes


@pytest.mark.slow
@pytest.mark.parametrize("policy_kind", ["free", "random"])
def test_exact_value_agrees_with_monte_carlo_of_the_hidden_trust(pomdp, policy_kind):
    """φ1 with the trust atom θ >= 6 at v3; the policies never read the DFA state, so the
    simulation needs no joint filter of its own."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    rng = np.random.default_rng(20261201)
    policy = (trust_free_policy(pomdp.town, spec) if policy_kind == "free"
              else RandomStationaryPolicy(pomdp.town, np.random.default_rng(9)))
    exact = evaluate_joint(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=12))
    satisfied, _ = simulate(pomdp, spec, policy, 4000, rng, 12)
    p = exact.satisfaction_probability
    se = max(np.sqrt(p * (1 - p) / satisfied.size), 1.0 / satisfied.size)
    assert abs(satisfied.mean() - p) <= 4 * se + exact.gap, (satisfied.mean(), p, se)


@pytest.mark.parametrize("name", ["phi1", "phi2_strict"])
def test_without_trust_atoms_the_joint_unfolding_gives_todays_evaluation(pomdp, name):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    for policy in (trust_free_policy(pomdp.town, spec),
                   RandomStationaryPolicy(pomdp.town, np.random.default_rng(6))):
        today = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=3, max_junctions=10))
        joint = evaluate_joint(pomdp, spec, policy, EvaluationSettings(fallback_after=3, max_junctions=10),
                               force_joint=True)
        # The two sum the same terms in different orders: equal up to rounding (on the Town01 default
        # town phi2_strict's free policy differs by one ulp; on the earlier pentagon they were equal).
        assert abs(joint.lower - today.lower) <= 2 * math.ulp(today.lower)
        assert abs(joint.upper - today.upper) <= 2 * math.ulp(today.upper)
        assert joint.expected_final_trust == pytest.approx(today.expected_final_trust, abs=1e-12)
        assert joint.expected_junctions == pytest.approx(today.expected_junctions, abs=1e-12)
        for reason, value in today.end_mass.items():
            assert joint.end_mass[reason] == pytest.approx(value, abs=1e-15)
        dispatched = evaluate_joint(pomdp, spec, policy,
                                    EvaluationSettings(fallback_after=3, max_junctions=10))
        assert {k: v for k, v in dispatched.to_dict().items() if k != "seconds"} == \
            {k: v for k, v in today.to_dict().items() if k != "seconds"}


def test_belief_and_true_trust_readings_of_phi1_differ(pomdp):
    """The worked example of docs/trust_states.md: the trust-free route, φ1 read on the belief
    (hightrust: P(θ >= 6) > 0.5) and on the true trust (θ >= 6)."""
    belief = load_spec("specs/phi1.toml", pomdp.town)
    trust = load_spec("specs/phi1_trust.toml", pomdp.town)
    on_belief = evaluate(pomdp, belief, trust_free_policy(pomdp.town, belief))
    on_trust = evaluate_joint(pomdp, trust, trust_free_policy(pomdp.town, trust))
    assert on_belief.gap == 0.0 and on_trust.gap == 0.0
    assert abs(on_belief.lower - on_trust.lower) > 0.05


def _assert_bracket(pruned, exact_value):
    """[lower, upper] holds the exact value and its width is the pruned live mass, which is the
    sum of what each cut dropped."""
    assert pruned.lower <= exact_value + 1e-12 and exact_value <= pruned.upper + 1e-12
    assert pruned.gap == pytest.approx(pruned.end_mass["pruned"], abs=1e-12)
    assert sum(pruned.pruning["pruned_mass"].values()) == pytest.approx(pruned.end_mass["pruned"],
                                                                        abs=1e-12)
    assert sum(pruned.end_mass.values()) == pytest.approx(1.0, abs=1e-10)


@pytest.mark.parametrize("seed", [3, 17, 101])
@pytest.mark.parametrize("kind", ["trust", "mixed"])
def test_pruned_bracket_holds_the_brute_force_value(driver, seed, kind):
    """A node budget of 2 per level and a live-mass threshold cut most of the tree; the bracket
    still holds the value brute force over trust paths computes, and pruning off is exact."""
    rng = np.random.default_rng(seed)
    pomdp, spec = random_problem(rng, driver, kind)
    policy = RandomStationaryPolicy(pomdp.town, rng)
    reference = policy_value(pomdp, spec, policy, 4)
    off = evaluate_joint(pomdp, spec, policy,
                         EvaluationSettings(fallback_after=None, max_junctions=4, prune_below=0.0,
                                            max_nodes=10**9),
                         force_joint=True)
    assert off.gap == 0.0 and off.lower == pytest.approx(reference, abs=1e-10)
    assert not any(off.pruning["pruned_nodes"].values())
    for prune_below, max_nodes in ((0.0, 2), (0.05, 10**9), (0.02, 3)):
        pruned = evaluate_joint(pomdp, spec, policy,
                                EvaluationSettings(fallback_after=None, max_junctions=4,
                                                   prune_below=prune_below, max_nodes=max_nodes),
                                force_joint=True)
        _assert_bracket(pruned, reference)


@pytest.fixture(scope="module")
def phi1_trust_policy(pomdp):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    return spec, synthesize_spec(pomdp, spec, SynthesisSettings(horizon=6, time_limit=20)).policy


def test_pruning_the_joint_policy_brackets_its_exact_value(pomdp, phi1_trust_policy):
    """φ1 with the trust atom, the synthesized joint policy with the fallback, 12 junctions: the
    tree unfolding with pruning off is exact; each cut (budget, threshold, deadline) gives a
    bracket around it whose width is the pruned mass, and the cuts actually cut."""
    spec, policy = phi1_trust_policy
    exact = evaluate_joint(pomdp, spec, policy,
                           EvaluationSettings(fallback_after=4, max_junctions=12, merge=False,
                                              prune_below=0.0, max_nodes=10**9))
    assert exact.gap == 0.0
    cuts = {"beyond_budget": {"max_nodes": 20}, "below_threshold": {"prune_below": 1e-4},
            "past_deadline": {"time_limit": 1e-9}}
    for cut, options in cuts.items():
        settings = EvaluationSettings(fallback_after=4, max_junctions=12, **options)
        pruned = evaluate_joint(pomdp, spec, policy, settings)
        _assert_bracket(pruned, exact.lower)
        assert pruned.gap > 1e-6 and pruned.pruning["pruned_nodes"][cut] > 0, cut
        assert pruned.pruning["pruned_mass"][cut] == pytest.approx(pruned.gap, abs=1e-12), cut
    # The default limits cut nothing here: the same value as the exact tree.
    default = evaluate_joint(pomdp, spec, policy, EvaluationSettings(fallback_after=4, max_junctions=12))
    assert default.gap == 0.0 and default.lower == pytest.approx(exact.lower, abs=1e-12)


class NodeByNode(RoutingPolicy):
    """A joint-table policy asked node by node: not a JointTablePolicy, so evaluate_joint has no
    batch path for it; its decisions and route memory are the table policy's."""

    name = "node-by-node"

    def __init__(self, inner: JointTablePolicy) -> None:
        self.inner = inner

    def next_junction(self, context):
        return self.inner.next_junction(context)

    def route_memory(self, route):
        return self.inner.route_memory(route)


def test_prefetched_decisions_are_the_node_by_node_decisions(pomdp):
    """The joint policy decides each level's nodes in one batch (prefetch); without it every node
    asks on its own: the same evaluation, number for number (a policy of horizon 12 on 14
    junctions without the fallback, where its decisions differ between nodes of a level)."""
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    policy = synthesize_spec(pomdp, spec, SynthesisSettings(horizon=12, time_limit=20)).policy
    batched = evaluate_joint(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=14))
    alone = evaluate_joint(pomdp, spec, NodeByNode(policy), EvaluationSettings(fallback_after=None,
                                                                               max_junctions=14))
    for name in ("lower", "upper", "expected_final_trust", "nodes"):
        assert getattr(batched, name) == getattr(alone, name), name
    assert batched.end_mass == alone.end_mass


@pytest.mark.slow
def test_the_cli_brackets_phi1_trust_at_the_default_cap(capsys, tmp_path):
    """`trustroute evaluate specs/phi1_trust.toml aware` at the default cap (60) returns a certified
    bracket whose width is the pruned mass; the 20-junction value, exact there, is below it."""
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1_trust.toml", "aware", "--cache-dir",
                           str(tmp_path), "--json")
    assert code == 0
    value = json.loads(out)
    assert value["max_junctions"] == 60
    assert 0.0 <= value["lower"] <= value["upper"] <= 1.0
    # the width is the pruned mass plus the outward rounding (policies/synthesis/rounding.py: a few
    # 1e-12 on the joint (θ, q) filter at 60 junctions), never less than the pruned mass
    width, pruned = value["upper"] - value["lower"], value["end_mass"]["pruned"]
    assert pruned - 1e-15 <= width <= pruned + 1e-10
    assert value["pruning"]["max_nodes"] > 0
    code, out, _ = run_cli(capsys, "evaluate", "specs/phi1_trust.toml", "aware", "--cache-dir",
                           str(tmp_path), "--max-junctions", "20", "--max-nodes", "1000000", "--json")
    at_20 = json.loads(out)
    assert code == 0 and at_20["gap"] < 1e-9
    # More junctions can only add accepted mass (the fallback at 20 is the same in both runs).
    assert at_20["lower"] <= value["upper"] + 1e-12
