"""Exact evaluation of any routing policy in the trust POMDP: P(spec satisfied), final trust.

Unfolds the policy's tree of episodes level by level (one level per junction), in numpy.
A node is one history of observations: its route, the spec's DFA state q_t, the AV's belief
b_t (which drives decisions and belief labels) and the true posterior over trust given the
observations (Bayes; equal to the AV's belief under the default rule). Because trust is hidden
and the posterior is the exact conditional law of θ given the history, the probability of each
observation at a node is Σθ posterior(θ) P(h, e | θ, inc) and the expected final trust is
Σ P(node) posterior_node · levels over the nodes where episodes end — no sampling anywhere.

A branch ends by the episode rules (policies/routing/episode_rules.py): when the DFA accepts
(satisfied), when it can no longer accept (rejected), when the policy declares it finished
(destination reached: the trust-free route or the fallback completion is done), or at the
episode's junction cap. Branches with tiny probability are
pruned and their mass reported, so the result is a certified interval [lower, upper]
(lower = mass proven satisfied, upper = lower + pruned mass).

Policies are asked once per distinct (route, DFA state, AV belief). A policy may also offer
`route_determined(context) -> bool` (True: its decision and `finished` here are the same for
every belief and non-accepting DFA state on this route, as for the trust-free policy and the
fallback phase); it is then asked once per route, which keeps deep trees fast.
"""

from __future__ import annotations

import time

import numpy as np

from trustroute.policies.evaluation.ledgers import (
    DEFAULT_MAX_NODES,
    DEFAULT_PRUNE_BELOW,
    Evaluation,
    PathLedger,
    accepted_bounds,
)
from trustroute.policies.evaluation.node_state import Observation, observed_root
from trustroute.policies.evaluation.settings import DEFAULT_EVALUATION, EvaluationSettings
from trustroute.policies.evaluation.unfolding import EpisodeActor, Limits, outcomes, root, unfold
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP
from trustroute.policies.routing.episode_rules import episode_policy
from trustroute.policies.routing.fallback import FallbackPolicy
from trustroute.policies.routing.protocol import RoutingPolicy

__all__ = ["DEFAULT_MAX_NODES", "DEFAULT_PRUNE_BELOW", "Evaluation", "accepted_bounds", "evaluate"]


def evaluate(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy,
             settings: EvaluationSettings = DEFAULT_EVALUATION, truth: TrustPOMDP | None = None,
             reference: tuple[TrustPOMDP, Spec] | None = None, deadline: float | None = None) -> Evaluation:
    """Exact (or tightly certified) satisfaction probability of `policy` for `spec`.

    settings (policies/evaluation/settings.py; `merge` and `time_limit` are the trust-state
    unfolding's):
    fallback_after: wrap the policy with the study's rule after that many junctions
    (None: evaluate the policy as given; a policy already wrapped is not wrapped again).
    max_junctions: the episode's hard cap; an episode still running there is unsatisfied.
    belief_rule: the AV's filter ("bayes", or the authors' "paper" update); observation
    probabilities and the final trust always use the true (Bayes) posterior.
    prune_below / max_nodes: branches below this probability, or beyond this frontier size
    (smallest first), are not followed; their mass widens [lower, upper].
    truth: the driver the episodes are driven with, when it is not the AV's model (a driver type,
    another population, docs/driver_types.md "Exact values per type"): observations are drawn
    from its exact posterior (starting from its initial belief) while the AV's belief, which drives
    decisions and labels, runs `pomdp`'s filter; an observation the AV deems impossible leaves the
    AV's belief unchanged, as in the episode tracker. The final trust is the truth's.
    reference (pomdp_ref, spec_ref): also read the spec with another belief, the Bayes filter of
    pomdp_ref on the same observations (e.g. the posterior under the true population), without
    changing what the vehicle does: `reference_accepted` is the mass of episodes that this
    reading accepts by the time the vehicle's episode ends (docs/driver_types.md, "Limits").
    deadline (a time on the synthesis' clock, policies/work_clock.py; None: none): the histories
    still open at the first junction begun past it are cut, their mass widening [lower, upper] (a
    time-limited caller's).
    """
    started = time.perf_counter()
    fallback_after, max_junctions = settings.fallback_after, settings.max_junctions
    belief_rule = settings.belief_rule
    prune_below = DEFAULT_PRUNE_BELOW if settings.prune_below is None else settings.prune_below
    max_nodes = DEFAULT_MAX_NODES if settings.max_nodes is None else settings.max_nodes
    town = pomdp.town
    policy = episode_policy(policy, town, spec, fallback_after)
    fallback_level = policy.after if isinstance(policy, FallbackPolicy) else None
    compiled = compile_spec(spec, town)
    true_pomdp = pomdp if truth is None else truth
    model = Observation(pomdp=pomdp, compiled=compiled, belief_rule=belief_rule, truth=truth,
                        reference=None if reference is None
                        else (reference[0], compile_spec(reference[1], town)))
    ledger = PathLedger(levels=np.asarray(true_pomdp.driver.trust_levels, dtype=float),
                        prune_below=prune_below, max_nodes=max_nodes, reference=reference is not None)
    actor = EpisodeActor(policy=policy, town=town, max_junctions=max_junctions,
                         fallback_level=fallback_level, accepting=compiled.accepting,
                         routes=[(spec.start,)])
    counts = unfold(root(town.state_index(spec.start), observed_root(model)), actor, ledger,
                    Limits(max_junctions=max_junctions, deadline=deadline),
                    outcomes(pomdp.driver.depends_on_performance
                             or true_pomdp.driver.depends_on_performance))
    return ledger.evaluation(counts.nodes, counts.max_frontier, policy=policy.name,
                             seconds=time.perf_counter() - started, belief_rule=belief_rule,
                             fallback_after=fallback_level, max_junctions=max_junctions)
