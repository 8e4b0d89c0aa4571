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

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from trustroute.networks.town import Town
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.problem import DRIVER_TYPES, PLAIN, TRUST_STATE, Problem, problem, problem_of
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import TrustPOMDP
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.population import MAX_GRID_CANDIDATES, synthesize_population
from trustroute.policies.synthesis.result import RoundProgress, SynthesisResult
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.trust_state_synthesis.population import synthesize_population_joint
from trustroute.policies.trust_state_synthesis.synthesis import synthesize_joint
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import work_clock

if TYPE_CHECKING:
    from trustroute.policies.synthesis.population import Objective, PopulationSynthesis


def belief_search(problem: Problem, settings: SynthesisSettings,
                  on_iteration: RoundProgress | None) -> SynthesisResult:
    return synthesize(problem.pomdp, problem.spec, settings, on_iteration=on_iteration)


def joint_search(problem: Problem, settings: SynthesisSettings,
                 on_iteration: RoundProgress | None) -> SynthesisResult:
    """The belief-MDP search's settings (`clusters`, `compress`, ...) do not apply here."""
    return synthesize_joint(problem.pomdp, problem.spec, settings, on_iteration=on_iteration)


METHODS: dict[str, Callable[..., SynthesisResult]] = {
    PLAIN: belief_search, DRIVER_TYPES: belief_search, TRUST_STATE: joint_search}


def synthesize_problem(problem: Problem, settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                       on_iteration: RoundProgress | None = None) -> SynthesisResult:
    """lower <= Pr_max(spec) <= upper and a policy whose value is at least lower (see `synthesize`;
    `settings.clusters` applies to belief-MDP searches, docs/synthesis.md "Cluster policies")."""
    return METHODS[problem.case](problem, settings, on_iteration)


def synthesize_spec(pomdp: TrustPOMDP, spec: Spec, settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                    on_iteration: RoundProgress | None = None) -> SynthesisResult:
    """`synthesize_problem` of the problem of `pomdp` and `spec`."""
    return synthesize_problem(problem_of(pomdp, spec), settings, on_iteration=on_iteration)


def synthesize_for_population(town: Town, population: DriverPopulation, spec: Spec,
                              objective: Objective = "bayes",
                              settings: SynthesisSettings = DEFAULT_SYNTHESIS, population_source: str = "",
                              on_iteration: RoundProgress | None = None,
                              on_phase: Callable[[str], None] | None = None,
                              ) -> PopulationSynthesis:
    """Synthesis for driver population `population` under `objective` ("bayes": the prior-weighted
    value; "robust": the worst type's), by the case of the problem (module docstring).
    settings.grid_points: candidate type priors of the robust objective (default
    policies/synthesis/population.py's). settings.time_limit bounds the whole call; on_phase hears
    a line per finished synthesis run with its bounds. settings.work_limit: the units of work of
    the whole call, its runs included (policies/work_clock.py)."""
    with work_clock(settings.work_limit, settings.time_limit) as limit:
        return _for_population(town, population, spec, objective,
                               replace(settings, time_limit=limit), population_source,
                               (on_iteration, on_phase))


def _for_population(town: Town, population: DriverPopulation, spec: Spec, objective: Objective,
                    settings: SynthesisSettings, population_source: str,
                    listeners: tuple[RoundProgress | None, Callable[[str], None] | None],
                    ) -> PopulationSynthesis:
    """`synthesize_for_population` on the clock installed for it."""
    on_iteration, on_phase = listeners
    entered = clock_now()
    found = problem(town, population, spec, population_source)
    # the limit is the whole call's: building the problem counts
    settings = replace(settings, time_limit=max(settings.time_limit - (clock_now() - entered), 0.0))
    if settings.grid_points is None:
        settings = replace(settings, grid_points=MAX_GRID_CANDIDATES)
    if found.case == TRUST_STATE:
        return synthesize_population_joint(found, objective, synthesize_spec, settings,
                                           on_iteration=on_iteration, on_phase=on_phase)
    return synthesize_population(town, population, spec, objective, settings,
                                 population_source=population_source,
                                 on_iteration=on_iteration, on_phase=on_phase)
