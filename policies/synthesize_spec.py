"""Synthesis for any problem: the one entry point callers use (docs/trust_states.md).

The problem's case (policies/belief/problem.py) chooses the method: a formula that tests the
hidden trust (TRUST_STATE) goes to policies/trust_state_synthesis/synthesis.py (search over joint
(trust, DFA state) beliefs); every other problem (PLAIN, and DRIVER_TYPES on the type-aware model)
goes to policies/synthesis/belief_synthesis.py unchanged, so its bounds and policy file are exactly those of
`belief_synthesis.synthesize` (tests/policies/test_synthesize_spec.py compares them byte for byte).

A driver population (`synthesize_for_population`, objectives "bayes" and "robust") goes by the same
case of its problem: TRUST_STATE to policies/trust_state_synthesis/population.py (the trust-state
search on the lifted model and spec), the others to policies/synthesis/population.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING

from trustroute.networks.town import Town
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.problem import DRIVER_TYPES, PLAIN, TRUST_STATE, Problem, problem, problem_of
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP
from trustroute.policies.synthesis.arguments import check_synthesis_arguments
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.result import SynthesisResult

if TYPE_CHECKING:
    from trustroute.policies.synthesis.population import Objective, PopulationSynthesis


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


def synthesize_for_population(town: Town, population: DriverPopulation, spec: Spec,
                              objective: Objective = "bayes",
                              tau: float = 1e-3, time_limit: float = 60.0, horizon: int | None = None,
                              belief_rule: BeliefRule = "bayes", population_source: str = "",
                              grid_points: int | None = None,
                              on_iteration: Callable[[float, float], None] | None = None,
                              on_phase: Callable[[str], None] | None = None,
                              ) -> PopulationSynthesis:
    """Synthesis for driver population `population` under `objective` ("bayes": the prior-weighted
    value; "robust": the worst type's), by the case of the problem (module docstring).
    grid_points: candidate type priors of the robust objective (default
    policies/synthesis/population.py's). time_limit bounds the whole call; on_phase hears a line
    per finished synthesis run with its bounds."""
    from trustroute.policies.synthesis.population import MAX_GRID_CANDIDATES, synthesize_population

    entered = time.perf_counter()
    found = problem(town, population, spec, population_source)
    # the limit is the whole call's: building the problem counts
    time_limit = max(time_limit - (time.perf_counter() - entered), 0.0)
    points = MAX_GRID_CANDIDATES if grid_points is None else grid_points
    if found.case == TRUST_STATE:
        from trustroute.policies.trust_state_synthesis.population import synthesize_population_joint

        check_synthesis_arguments(tau, horizon, belief_rule)
        return synthesize_population_joint(found, objective, synthesize_spec, tau=tau, time_limit=time_limit,
                                           horizon=horizon, belief_rule=belief_rule, grid_points=points,
                                           on_iteration=on_iteration, on_phase=on_phase)
    return synthesize_population(town, population, spec, objective, tau=tau, time_limit=time_limit,
                                 horizon=horizon, belief_rule=belief_rule,
                                 population_source=population_source, grid_points=points,
                                 on_iteration=on_iteration, on_phase=on_phase)
