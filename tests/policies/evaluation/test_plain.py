"""Exact policy evaluation against an independent Monte Carlo simulation of the trust model.

The simulation samples the hidden trust path θ0, θ1, ... from the driver model, the takeovers
and the AV's failures from θ, and runs the AV's belief filter on what it observes; it shares
no code with the belief-tree unfolding in policies/evaluation/plain.py.
"""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.policies.evaluation import unfolding
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP
from trustroute.policies.routing.fallback import FallbackPolicy, with_fallback
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

RANDOM_POLICY_SEED = {"phi1": 9, "phi2": 6}


class RandomStationaryPolicy(RoutingPolicy):
    """A fixed random map (road, E[θ] >= 4.5) -> next junction, drawn from `rng`."""

    name = "random"

    def __init__(self, town, rng):
        self.town = town
        self.table = {
            (road, high): town.actions(road)[int(rng.integers(len(town.actions(road))))]
            for road in town.states for high in (False, True)
        }

    def next_junction(self, context):
        high = bool(context.belief @ np.arange(1, 8) >= 4.5)
        return self.table[(context.road, high)]


def simulate(pomdp, spec, policy, episodes, rng, max_junctions, belief_rule="bayes"):
    """Monte Carlo: returns (satisfied bool[episodes], final true trust int[episodes]). The DFA reads
    the true trust level of each position (trust-state atoms, docs/trust_states.md).

    The episodes advance together, one junction at a time: trust, takeovers and failures are drawn
    for all of them at once (inverse CDF), and the policy, a deterministic function of its context,
    is asked once per distinct context."""
    town, driver = pomdp.town, pomdp.driver
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    satisfied = np.zeros(episodes, dtype=bool)
    theta = draw_rows(np.broadcast_to(driver.initial_belief, (episodes, driver.n_trust)), rng)
    belief = np.tile(np.asarray(driver.initial_belief, dtype=float), (episodes, 1))
    routes = [[spec.start] for _ in range(episodes)]
    q = labeller.step(np.full(episodes, dfa.initial), np.full(episodes, town.state_index(spec.start)),
                      belief, theta)
    active = np.ones(episodes, dtype=bool)
    decided: dict = {}
    for level in range(max_junctions + 1):
        satisfied |= active & dfa.accepting[q]
        active &= ~(dfa.accepting[q] | dfa.rejecting[q])
        moving = []
        roads = []
        for n in np.flatnonzero(active):
            key = (tuple(routes[n]), int(q[n]), belief[n].tobytes())
            if key not in decided:
                context = DecisionContext(route=key[0], dfa_state=key[1], belief=belief[n].copy())
                finished = policy.finished(context) or level == max_junctions
                decided[key] = None if finished else town.successor(routes[n][-1],
                                                                    policy.next_junction(context))
            if decided[key] is not None:
                moving.append(n)
                roads.append(decided[key])
        active[:] = False
        if not moving:
            break
        moving = np.array(moving)
        active[moving] = True
        inc = np.array([driver.incident_index(town.incident(road)) for road in roads])
        t = theta[moving]
        h = (rng.random(moving.size) < driver.takeover_probability[inc, t]).astype(np.int64)
        e = (rng.random(moving.size) < driver.failure_probability[inc, t]).astype(np.int64)
        theta[moving] = draw_rows(driver.trust_transition[inc, h, e, t], rng)
        belief[moving] = pomdp.belief_update(belief[moving], inc, h, e, rule=belief_rule)[0]
        for n, road in zip(moving, roads, strict=True):
            routes[n].append(road)
        x = np.array([town.state_index(road) for road in roads])
        q[moving] = labeller.step(q[moving], x, belief[moving], theta[moving])
    final_trust = np.asarray(driver.trust_levels, dtype=float)[theta]
    return satisfied, final_trust


def draw_rows(probabilities: np.ndarray, rng) -> np.ndarray:
    """One index per row of `probabilities` [n, k], drawn by inverse CDF."""
    cumulative = np.cumsum(probabilities, axis=1)
    u = rng.random(probabilities.shape[0]) * cumulative[:, -1]
    return np.minimum((cumulative <= u[:, None]).sum(axis=1), probabilities.shape[1] - 1)


def assert_agrees(evaluation, satisfied, final_trust):
    n = satisfied.size
    p = evaluation.satisfaction_probability
    se = max(np.sqrt(p * (1 - p) / n), 1.0 / n)
    assert abs(satisfied.mean() - p) <= 4 * se + evaluation.gap, (satisfied.mean(), p, se)
    se_trust = final_trust.std(ddof=1) / np.sqrt(n)
    assert abs(final_trust.mean() - evaluation.expected_final_trust) <= 4 * se_trust + 1e-9


@pytest.mark.parametrize("name", ["phi1", "phi2"])
@pytest.mark.parametrize("belief_rule", ["bayes", "paper"])
def test_baseline_value_agrees_with_monte_carlo(pomdp, name, belief_rule):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    policy = trust_free_policy(pomdp.town, spec)
    evaluation = evaluate(pomdp, spec, policy, EvaluationSettings(belief_rule=belief_rule))
    assert evaluation.gap == 0.0
    assert evaluation.end_mass["accepted"] + evaluation.end_mass["destination"] == pytest.approx(1.0)
    satisfied, trust = simulate(pomdp, spec, policy, 3000, np.random.default_rng(11), 60, belief_rule)
    assert_agrees(evaluation, satisfied, trust)


@pytest.mark.parametrize("name", ["phi1", "phi2"])
@pytest.mark.parametrize("after", [None, 6])
def test_random_stationary_policy_agrees_with_monte_carlo(pomdp, name, after):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    # Seeds chosen so that, without the fallback, the policy satisfies the spec sometimes but not always.
    policy = RandomStationaryPolicy(pomdp.town, np.random.default_rng(RANDOM_POLICY_SEED[name]))
    cap = 14
    evaluation = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=after, max_junctions=cap))
    simulated = policy if after is None else with_fallback(policy, pomdp.town, spec, after=after)
    satisfied, trust = simulate(pomdp, spec, simulated, 3000, np.random.default_rng(17), cap)
    assert_agrees(evaluation, satisfied, trust)
    masses = evaluation.end_mass
    assert sum(masses.values()) == pytest.approx(1.0)
    if after is None:
        assert 0.05 < evaluation.lower < 0.95
        assert masses["destination"] == 0.0
        assert evaluation.fallback_probability == 0.0


def test_pruning_gives_an_interval_around_the_exact_value(pomdp):
    spec = load_spec("specs/phi2.toml", pomdp.town)
    policy = RandomStationaryPolicy(pomdp.town, np.random.default_rng(RANDOM_POLICY_SEED["phi2"]))
    exact = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=5, max_junctions=14))
    assert exact.gap == 0.0
    for kwargs in ({"prune_below": 1e-2}, {"max_nodes": 10}):
        rough = evaluate(pomdp, spec, policy,
                         EvaluationSettings(fallback_after=5, max_junctions=14, **kwargs))
        assert rough.end_mass["pruned"] > 0
        assert rough.lower <= exact.lower + 1e-12 <= rough.upper + 2e-12
        assert rough.final_trust_lower <= exact.expected_final_trust + 1e-9
        assert exact.expected_final_trust <= rough.final_trust_upper + 1e-9


def test_spec_accepted_at_the_start_is_worth_one_and_wrapping_is_not_repeated(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    policy = with_fallback(trust_free_policy(pomdp.town, spec), pomdp.town, spec, after=3)
    evaluation = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=20))
    assert isinstance(policy, FallbackPolicy)
    assert evaluation.fallback_after == 3
    assert evaluation.policy == "free+fallback3"


@pytest.mark.slow
@pytest.mark.parametrize(("name", "belief_rule"), [("phi1", "bayes"), ("phi1", "paper"), ("phi2", "paper")])
def test_baseline_value_agrees_with_large_monte_carlo(pomdp, name, belief_rule):
    """Under the paper's filter the AV's belief is not the posterior: 20000 episodes resolve the
    ~0.01 difference that using the AV's belief for observation probabilities would make."""
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    policy = trust_free_policy(pomdp.town, spec)
    evaluation = evaluate(pomdp, spec, policy, EvaluationSettings(belief_rule=belief_rule))
    satisfied, trust = simulate(pomdp, spec, policy, 20000, np.random.default_rng(23), 60, belief_rule)
    assert_agrees(evaluation, satisfied, trust)


def recursive_value(pomdp, spec, policy, max_junctions, belief_rule):
    """Plain recursion over every observation sequence: (P(satisfied), E[final trust]). A node's
    observations are worked out together (their DFA states in one labeller call): the recursion
    visits every node of every level, so its per-call costs are most of a test's time."""
    town, driver = pomdp.town, pomdp.driver
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    levels = np.asarray(driver.trust_levels, dtype=float)

    def children(q, road, posterior, belief):
        """(P(h, e), DFA state, AV belief, posterior) of each observation (h, e) on entering `road`."""
        inc = driver.incident_index(town.incident(road))
        p_h, p_e = driver.takeover_probability[inc], driver.failure_probability[inc]
        found = []
        for h in (0, 1):
            for e in (0, 1):
                # P(h, e, θ' | history) = Σθ posterior(θ) P(h|θ) P(e|θ) T(θ, θ')
                weight = posterior * (p_h if h else 1 - p_h) * (p_e if e else 1 - p_e)
                joint = weight @ driver.trust_transition[inc, h, e]
                p_obs = joint.sum()
                if p_obs <= 0:
                    continue
                if belief_rule == "bayes":
                    new_belief = joint / p_obs
                else:
                    raw = belief @ driver.trust_transition[inc, h, e]
                    new_belief = raw / raw.sum()
                found.append((p_obs, new_belief, joint / p_obs))
        if not found:
            return []
        told = labeller.step(np.full(len(found), q), np.full(len(found), town.state_index(road)),
                             np.stack([new_belief for _, new_belief, _ in found]))
        return [(p_obs, int(q2), new_belief, posterior2)
                for (p_obs, new_belief, posterior2), q2 in zip(found, told.tolist(), strict=True)]

    def visit(route, q, belief, posterior):
        if dfa.accepting[q]:
            return 1.0, float(posterior @ levels)
        context = DecisionContext(route=tuple(route), dfa_state=q, belief=belief)
        if dfa.rejecting[q] or policy.finished(context) or len(route) - 1 == max_junctions:
            return 0.0, float(posterior @ levels)
        road = town.successor(route[-1], policy.next_junction(context))
        sat = trust = 0.0
        for p_obs, q2, new_belief, posterior2 in children(q, road, posterior, belief):
            s, t = visit(route + [road], q2, new_belief, posterior2)
            sat += p_obs * s
            trust += p_obs * t
        return sat, trust

    belief = np.asarray(driver.initial_belief, dtype=float)
    start = labeller.step(np.array([dfa.initial]), np.array([town.state_index(spec.start)]), belief[None])
    return visit([spec.start], int(start[0]), belief, belief)


@pytest.mark.parametrize("name", ["phi1", "phi2"])
@pytest.mark.parametrize("belief_rule", ["bayes", "paper"])
def test_evaluate_equals_plain_recursion(pomdp, name, belief_rule):
    spec = load_spec(f"specs/{name}.toml", pomdp.town)
    inner = RandomStationaryPolicy(pomdp.town, np.random.default_rng(RANDOM_POLICY_SEED[name]))
    policy = with_fallback(inner, pomdp.town, spec, after=6)
    evaluation = evaluate(pomdp, spec, policy, EvaluationSettings(max_junctions=13, belief_rule=belief_rule))
    satisfied, final_trust = recursive_value(pomdp, spec, policy, 13, belief_rule)
    assert evaluation.gap == 0.0
    assert 0.05 < satisfied < 0.95 and evaluation.end_mass["destination"] > 0.01
    assert evaluation.lower == pytest.approx(satisfied, abs=1e-12)
    assert evaluation.expected_final_trust == pytest.approx(final_trust, abs=1e-9)


@pytest.mark.parametrize("belief_rule", ["bayes", "paper"])
def test_each_observation_probability_is_computed_once(pomdp, belief_rule, monkeypatch):
    """A level's children are sized by every observation's probability per node before the first
    observation's are written; those probabilities are then the children's masses, not computed
    again by the filter: one per node moved and observation."""
    computed, branched = [], []
    probability, branch = TrustPOMDP.observation_probability, unfolding.branch

    def counted(self, beliefs, *observation):
        computed.append(np.atleast_2d(beliefs).shape[0])
        return probability(self, beliefs, *observation)

    def spied(frontier, next_road, route_id, observations, children):
        branched.append(frontier.size * len(observations))
        return branch(frontier, next_road, route_id, observations, children)

    monkeypatch.setattr(TrustPOMDP, "observation_probability", counted)
    monkeypatch.setattr(unfolding, "branch", spied)
    spec = load_spec("specs/phi1.toml", pomdp.town)
    policy = RandomStationaryPolicy(pomdp.town, np.random.default_rng(RANDOM_POLICY_SEED["phi1"]))
    evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=12,
                                                     belief_rule=belief_rule))
    assert sum(branched) > 500
    assert sum(computed) == sum(branched)
