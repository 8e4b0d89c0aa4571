"""Exact evaluation of a routing policy for specs that test the hidden trust (docs/trust_states.md).

The one unfolding of policies/evaluation/unfolding.py (one level per junction, one node per history
of observations, decisions asked once per distinct (route, DFA state told, AV belief)), with the
hidden node state (policies/evaluation/node_state.py, `HiddenState`): the exact joint belief J(θ, q)
of policies/belief/trust_state_filter.py at every node instead of one DFA state, and the JointLedger
(policies/evaluation/ledgers.py). The spec is satisfied on a branch with probability J(accepting)
when the branch ends; accepting states are absorbing, so that mass only grows along a branch and is
counted once, at its end. A branch ends when its live mass (q neither accepting nor rejecting) is 0
(settled), when the policy declares it finished, at the junction cap, or when it is pruned; the live
mass of a finished or capped branch is unsatisfied, that of a pruned branch unknown (the width of
[lower, upper]).

The AV does not know q: the policy is told the most probable DFA state (the exact one when the
spec has no trust-state atoms). Problems whose DFA state is observed (policies/belief/problem.py:
every case but TRUST_STATE) are evaluated by policies/evaluation/plain.py itself, so their results
are exactly plain.py's. A driver population's type-aware model makes θ the hidden (type, trust)
index: `evaluate_joint_by_type` reads every type's value off the same unfolding.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from trustroute.policies.belief.driver_types import n_types_of
from trustroute.policies.belief.problem import dfa_is_hidden
from trustroute.policies.belief.trust_state_filter import joint_filter
from trustroute.policies.evaluation.ledgers import (
    DEFAULT_MAX_NODES,
    DEFAULT_PRUNE_BELOW,
    BoundLedger,
    Evaluation,
    JointLedger,
    TypeMasses,
    UnboundedLedger,
)
from trustroute.policies.evaluation.node_state import hidden_root
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import DEFAULT_EVALUATION, EvaluationSettings
from trustroute.policies.evaluation.unfolding import (
    EpisodeActor,
    Limits,
    SlotActor,
    outcomes,
    root,
    unfold,
)
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.routing.episode_rules import episode_policy
from trustroute.policies.routing.fallback import FallbackPolicy
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.work_clock import CAPS, installed, stopped_by
from trustroute.policies.work_clock import now as clock_now

# Defaults for specs with trust-state atoms (docs/trust_states.md, "Bounded evaluation"): the
# unfolding keeps the JOINT_MAX_NODES likeliest nodes of each level, which bounds its cost by
# about cap x 4 x JOINT_MAX_NODES node updates (the default cap in a few seconds on phi1_trust);
# histories below JOINT_PRUNE_BELOW are dropped as in policies.evaluation.plain.
JOINT_MAX_NODES = 5_000
JOINT_PRUNE_BELOW = DEFAULT_PRUNE_BELOW


def evaluate_joint(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy,
                   settings: EvaluationSettings = DEFAULT_EVALUATION, force_joint: bool = False,
                   truth: TrustPOMDP | None = None,
                   reference: tuple[TrustPOMDP, Spec] | None = None) -> Evaluation:
    """Certified P(spec satisfied) of `policy`, for any mix of road, belief and trust-state atoms.

    Arguments as policies.evaluation.plain.evaluate (settings: policies/evaluation/settings.py).
    `force_joint` runs the joint unfolding even when the
    spec has no trust-state atoms (tests compare it with evaluate there). A true driver other than
    the AV's model (`truth`) or a second reading (`reference`) is evaluated for specs without
    trust-state atoms only. `settings.merge` (default) merges, level by level, the histories that reach the
    same road and beliefs on routes the policy reads alike (`RoutingPolicy.route_memory`): the same
    value as the tree unfolding (`merge=False`, which tests compare), on far fewer nodes.

    Pruning (the unfolding is exponential in the cap: distinct histories almost never reach equal
    beliefs): a branch whose live mass is below `prune_below`, a node beyond the `max_nodes` of
    its level with the most live mass,
    and every branch still open `time_limit` seconds after the start are not followed; their
    accepted mass counts, their live mass is unknown (end_mass["pruned"] = upper - lower). The
    defaults are policies.evaluation.plain's for specs without trust-state atoms (which go there unchanged)
    and JOINT_PRUNE_BELOW, JOINT_MAX_NODES (no time limit) otherwise; `pruning` reports them and
    what they cut."""
    if not force_joint and not dfa_is_hidden(pomdp.driver, spec):
        if settings.time_limit is not None:
            raise ValueError("a time limit applies to specs with trust-state atoms only")
        return evaluate(pomdp, spec, policy, settings, truth=truth, reference=reference)
    if truth is not None or reference is not None:
        raise ValueError("a separate true driver or reference reading is not evaluated for specs with "
                         "trust-state atoms")
    return joint_unfolding(pomdp, spec, policy, settings)[0]


def joint_unfolding(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy, settings: EvaluationSettings,
                    by_type: bool = False) -> tuple[Evaluation, TypeMasses | None]:
    """The unfolding of `evaluate_joint` on the joint-belief node state; with `by_type`, also the
    masses of each driver type of a type-aware model (its hidden index is (type, trust))."""
    started = time.perf_counter()
    fallback_after, max_junctions = settings.fallback_after, settings.max_junctions
    belief_rule = settings.belief_rule
    merge, time_limit = settings.merge, settings.time_limit
    prune_below = JOINT_PRUNE_BELOW if settings.prune_below is None else settings.prune_below
    max_nodes = JOINT_MAX_NODES if settings.max_nodes is None else settings.max_nodes
    town = pomdp.town
    policy = episode_policy(policy, town, spec, fallback_after)
    fallback_level = policy.after if isinstance(policy, FallbackPolicy) else None
    # A policy that decides batches of nodes at once (JointTablePolicy.prefetch) is given each
    # level's nodes in one call before the episode rules ask it node by node.
    inner = policy.inner if isinstance(policy, FallbackPolicy) else policy
    batched = inner if isinstance(inner, JointTablePolicy) else None
    compiled = compile_spec(spec, town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    start = town.state_index(spec.start)
    accepting = np.asarray(compiled.dfa.accepting, dtype=bool)
    types = None
    if by_type:
        types = TypeMasses(n_types=n_types_of(pomdp.driver), accepting=accepting,
                           live=~(accepting | np.asarray(compiled.dfa.rejecting, dtype=bool)))
    ledger = JointLedger(levels=np.asarray(pomdp.driver.trust_levels, dtype=float),
                         prune_below=prune_below, max_nodes=max_nodes, types=types)
    actor = EpisodeActor(policy=policy, town=town, max_junctions=max_junctions,
                         fallback_level=fallback_level, accepting=accepting,
                         batched=batched, routes=[(spec.start,)])
    limits = Limits(max_junctions=max_junctions, merge=merge,   # (the deadline on the unfolding's clock)
                    deadline=None if time_limit is None else clock_now() + time_limit)
    counts = unfold(root(start, hidden_root(filter_, start, belief_rule)), actor, ledger, limits,
                    outcomes(pomdp.driver.depends_on_performance))
    evaluation = ledger.evaluation(counts.nodes, counts.max_frontier, time_limit=time_limit,
                                   policy=policy.name, seconds=time.perf_counter() - started,
                                   belief_rule=belief_rule, fallback_after=fallback_level,
                                   max_junctions=max_junctions)
    return evaluation, types


def evaluate_joint_by_type(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy,
                           settings: EvaluationSettings = DEFAULT_EVALUATION
                           ) -> tuple[Evaluation, list[tuple[float, float]]]:
    """`evaluate_joint` on the joint belief over ((type, trust), DFA state) of a driver
    population's type-aware model (policies/belief/driver_types.py) and lifted spec, which may test
    the hidden trust: the value under the type prior, and [lower, upper] of P(satisfied | type k)
    for each type, read off the same unfolding (J's block of type k holds P(type k, θ, q | history);
    a cut node's live mass of type k widens type k's bracket only)."""
    evaluation, types = joint_unfolding(pomdp, spec, policy, settings, by_type=True)
    assert types is not None
    prior = np.asarray(pomdp.initial_belief, dtype=float)
    weights = prior.reshape(types.n_types, -1).sum(axis=1)
    return evaluation, types.bounds(weights)


TABLE_CHUNK = 5_000     # nodes moved per batch in evaluate_joint_table (the deadline is checked between)


@dataclass(frozen=True)
class TableValue:
    """Certified [lower, upper] of a table policy's value (`evaluate_joint_table`); `stopped`: what
    ended its unfolding (ledgers.UNFOLDING_STOPS)."""

    lower: float
    upper: float
    stopped: str

    @property
    def converged(self) -> bool:
        return self.stopped == "convergence"

    def stopped_by(self) -> str:
        """`stopped` as the one rule names it (work_clock.stopped_by) on the clock installed now:
        a cap by its name, the deadline as the work limit or the time limit."""
        return stopped_by(self.converged, installed(), cap=self.stopped if self.stopped in CAPS else None)


def evaluate_joint_table(pomdp: TrustPOMDP, spec: Spec, policy, max_junctions: int,
                         belief_rule: BeliefRule = "bayes",
                         max_nodes: int = DEFAULT_MAX_NODES,
                         deadline: float | None = None) -> TableValue:
    """Certified [lower, upper] of P(accepted within `max_junctions`) for a policy whose decision
    at a node is a function of (junctions driven, road, joint belief, AV belief) alone, asked in
    batches: `policy.action_slots(t, x, joint, beliefs)` (routing.trust_state_table.JointTablePolicy),
    without the fallback. Histories that reach bit-identical (road, J, posterior, AV belief) at the
    same level are merged (their decisions and futures are the same), so this is the unfolding of
    `evaluate_joint` on far fewer nodes; beyond `max_nodes` per level the least likely nodes are
    dropped, their live mass unknown ("node cap"); by `deadline` (on the synthesis' clock) the
    unfolding stops (a batch of TABLE_CHUNK nodes or a level's merge is not begun when, at the last
    one's pace, it would end past it) and the live mass of every open node is unknown ("deadline")."""
    town = pomdp.town
    compiled = compile_spec(spec, town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    start = town.state_index(spec.start)
    ledger = BoundLedger(max_junctions=max_junctions, max_nodes=max_nodes)
    actor = SlotActor(slots=policy.action_slots, successor_table=pomdp.successor_table)
    limits = Limits(max_junctions=max_junctions, deadline=deadline, chunk=TABLE_CHUNK, paced=True,
                    merge=True)
    unfold(root(start, hidden_root(filter_, start, belief_rule)), actor, ledger, limits,
           outcomes(pomdp.driver.depends_on_performance))
    return TableValue(*ledger.bounds(), stopped=ledger.stopped)


UNBOUNDED_TOLERANCE = 1e-9    # live mass still open at which an unbounded evaluation has converged
UNBOUNDED_MAX_LEVELS = 100_000  # a guard only: the tolerance or the deadline ends it first


@dataclass(frozen=True)
class UnboundedValue(TableValue):
    """Certified [lower, upper] of P(accepted eventually) under a policy, after `junctions`
    junctions; `stopped`: "convergence" (the live mass still open and dropped was at most the
    tolerance when it stopped), "node cap", "junction cap" or "deadline" (UnboundedLedger)."""

    junctions: int


def evaluate_joint_table_unbounded(pomdp: TrustPOMDP, spec: Spec, policy, belief_rule: BeliefRule = "bayes",
                                   max_nodes: int = DEFAULT_MAX_NODES, deadline: float | None = None,
                                   tolerance: float = UNBOUNDED_TOLERANCE,
                                   max_junctions: int = UNBOUNDED_MAX_LEVELS) -> UnboundedValue:
    """`evaluate_joint_table` over unbounded time: the same merged unfolding of the policy's
    chain of joint beliefs, without a junction cap. The accepted mass after k junctions is k
    steps of value iteration from below on that chain (monotone in k, each a lower bound of the
    policy's value); the live mass still open bounds what is missing. It stops when that mass is
    at most `tolerance` or at `deadline`; nodes dropped beyond `max_nodes` per level leave their
    live mass unknown ("node cap" when it exceeds the tolerance). lower is lowered and upper raised
    by a margin for floating-point rounding (ledgers.ROUNDING_MARGIN_PER_LEVEL). `max_junctions`
    stops it after that many junctions ("junction cap": an iterate of the value iteration, its open
    live mass unknown; tests compare it)."""
    town = pomdp.town
    compiled = compile_spec(spec, town)
    filter_ = joint_filter(pomdp, compiled.dfa, compiled.labeller)
    start = town.state_index(spec.start)
    ledger = UnboundedLedger(max_junctions=max_junctions, max_nodes=max_nodes, tolerance=tolerance)
    actor = SlotActor(slots=policy.action_slots, successor_table=pomdp.successor_table)
    limits = Limits(max_junctions=max_junctions, deadline=deadline, chunk=TABLE_CHUNK,
                    paced=True, merge=True)
    unfold(root(start, hidden_root(filter_, start, belief_rule)), actor, ledger, limits,
           outcomes(pomdp.driver.depends_on_performance))
    lower, upper = ledger.bounds()
    return UnboundedValue(lower=lower, upper=upper, stopped=ledger.stopped, junctions=ledger.levels_done)
