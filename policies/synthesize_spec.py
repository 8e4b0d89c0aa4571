"""Synthesis for any problem: the one entry point callers use (docs/trust_states.md).

The problem's case (policies/belief/problem.py) chooses the method: a formula that tests the
hidden trust (TRUST_STATE) goes to policies/trust_state_synthesis/synthesis.py (search over joint
(trust, DFA state) beliefs); every other problem (PLAIN, and DRIVER_TYPES on the type-aware model)
goes to policies/synthesis/belief_synthesis.py unchanged, so its bounds and policy file are exactly those of
`belief_synthesis.synthesize` (tests/policies/test_synthesize_spec.py compares them byte for byte).
"""

from __future__ import annotations

from collections.abc import Callable

from trustroute.policies.belief.problem import DRIVER_TYPES, PLAIN, TRUST_STATE, Problem, problem_of
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.arguments import check_synthesis_arguments
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.result import SynthesisResult


def belief_search(problem: Problem, tau: float, time_limit: float, horizon: int | None,
                  belief_rule: BeliefRule, on_iteration: Callable[[float, float], None] | None,
                  clusters: str) -> SynthesisResult:
    return synthesize(problem.pomdp, problem.spec, tau=tau, time_limit=time_limit, horizon=horizon,
                      belief_rule=belief_rule, on_iteration=on_iteration, clusters=clusters)


def joint_search(problem: Problem, tau: float, time_limit: float, horizon: int | None,
                 belief_rule: BeliefRule, on_iteration: Callable[[float, float], None] | None,
                 clusters: str) -> SynthesisResult:
    """`clusters` is for belief-MDP searches only."""
    check_synthesis_arguments(tau, horizon, belief_rule)
    from trustroute.policies.trust_state_synthesis.synthesis import synthesize_joint

    return synthesize_joint(problem.pomdp, problem.spec, tau=tau, time_limit=time_limit, horizon=horizon,
                            belief_rule=belief_rule, on_iteration=on_iteration)


METHODS: dict[str, Callable[..., SynthesisResult]] = {
    PLAIN: belief_search, DRIVER_TYPES: belief_search, TRUST_STATE: joint_search}


def synthesize_problem(problem: Problem, tau: float = 1e-3, time_limit: float = 60.0,
                       horizon: int | None = None, belief_rule: BeliefRule = "bayes",
                       on_iteration: Callable[[float, float], None] | None = None,
                       clusters: str = "auto") -> SynthesisResult:
    """lower <= Pr_max(spec) <= upper and a policy whose value is at least lower (see `synthesize`;
    `clusters` applies to belief-MDP searches, docs/synthesis.md "Cluster policies")."""
    return METHODS[problem.case](problem, tau, time_limit, horizon, belief_rule, on_iteration, clusters)


def synthesize_spec(pomdp: TrustPOMDP, spec: Spec, tau: float = 1e-3, time_limit: float = 60.0,
                    horizon: int | None = None, belief_rule: BeliefRule = "bayes",
                    on_iteration: Callable[[float, float], None] | None = None,
                    clusters: str = "auto") -> SynthesisResult:
    """`synthesize_problem` of the problem of `pomdp` and `spec`."""
    return synthesize_problem(problem_of(pomdp, spec), tau=tau, time_limit=time_limit, horizon=horizon,
                              belief_rule=belief_rule, on_iteration=on_iteration, clusters=clusters)
