"""Synthesis over a driver population for specs that test the hidden trust (docs/driver_types.md,
"Trust-state specs with a population").

The type-aware model (policies/belief/driver_types.py) makes the hidden index (type, trust), and a
trust-state atom reads the trust level of that index (`base_trust_index`), so the problem of a
population and a trust-state spec is the trust-state problem of the lifted model and lifted spec:
its joint belief J((type, trust), q) is the AV's exact posterior over type, trust and DFA state.

Bayes: `synthesize_joint` on the lifted problem. Its L and U are the trust-state synthesis' own:
L the returned policy's certified value under the type prior, U a sound bound of the population
optimum max_π Σ_k w_k V_k(π). Per-type values V_k are read off one joint unfolding of the returned
policy (`evaluate_joint_by_type`: J's block of type k), with the horizon and no fallback, as the
synthesis scores it.

Robust: maximise min_k V_k, as policies/synthesis/population.py does for the belief-MDP search.
The candidates are the Bayes policy and, for every type prior λ of the simplex grid, the trust-state
synthesis as if the prior were λ; such a policy runs on the AV's filter under the weights w with
its joint belief and belief reweighted to λ (policies/routing/trust_state_table.py, exact: the
likelihood of the observations given the type does not depend on the prior), a function of the
observations like any policy, and its V_k are read off one joint unfolding on the w-model. The
candidate with the best worst type is returned. Certified: `lower` = min_k V_k of the returned policy
(the lower ends of its per-type values), `upper` = min(U_bayes, min_k U_k) with U_k a sound bound of
type k's own optimum (`synthesize_spec` on type k's model alone, of `belief_free_spec`: the spec
without its belief literals when it reads beliefs, since the AV's belief is not type k's own
posterior). The spec's belief labels read the w-filter for every candidate, so a λ-policy's table
rows (made on λ-beliefs) are matched where the two readings agree and the relaxation decides
elsewhere; its value is evaluated exactly either way.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from trustroute.policies.belief.driver_types import lift_population
from trustroute.policies.belief.exact_labels import exact_filter
from trustroute.policies.belief.problem import Problem
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import evaluate_joint_by_type
from trustroute.policies.logic.formula import TRUE, Formula, Literal, format_formula, map_literals
from trustroute.policies.logic.spec import Spec
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, build_pomdp
from trustroute.policies.routing.protocol import Certificate, RoutingPolicy
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.synthesis.budget import RunSchedule, TimeBudget
from trustroute.policies.synthesis.population import (
    BAYES_SHARE,
    EVALUATION_SHARE,
    MAX_GRID_CANDIDATES,
    OBJECTIVES,
    TYPE_BOUND_SHARE,
    PopulationSynthesis,
    TypeValue,
    candidate_name,
    candidate_priors,
    evaluation_cap,
    mixture_lower,
    reweighting,
    run_count,
    run_end,
    with_run_counts,
    within_tau,
    worst_type,
)
from trustroute.policies.synthesis.result import RoundProgress, SynthesisResult, robust_progress
from trustroute.policies.synthesis.rounding import problem_rounding
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.trust_state_synthesis.synthesis import (
    EVALUATION_NODES,
    JointSynthesis,
    synthesize_joint,
)
from trustroute.policies.work_clock import now as clock_now


def joint_type_values(problem: Problem, policy: RoutingPolicy, max_junctions: int,
                      belief_rule: BeliefRule = "bayes", fallback_after: int | None = None,
                      pomdp: TrustPOMDP | None = None, deadline: float | None = None
                      ) -> tuple[TypeValue, ...]:
    """Certified value of `policy` for each type of the problem's population as the true driver,
    from one joint unfolding on the lifted model (`evaluate_joint_by_type`); branches still open
    at `deadline` (on the synthesis' clock, policies/work_clock.py) are cut, widening [lower, upper]."""
    population = problem.population
    if population is None:
        raise ValueError("per-type values need a problem with a driver population")
    time_limit = None if deadline is None else max(deadline - clock_now(), 0.0)
    _, bounds = evaluate_joint_by_type(pomdp or problem.pomdp, problem.spec, policy,
                                       EvaluationSettings(fallback_after=fallback_after,
                                                          max_junctions=max_junctions,
                                                          belief_rule=belief_rule,
                                                          max_nodes=EVALUATION_NODES,
                                                          time_limit=time_limit))
    return certified_type_values(problem, bounds, max_junctions, pomdp)


def certified_type_values(problem: Problem, bounds: Sequence[tuple[float, float]], max_junctions: int,
                          pomdp: TrustPOMDP | None = None) -> tuple[TypeValue, ...]:
    """Each type's computed [lower, upper] from the joint unfolding on the lifted model, rounded
    outward for the lifted (θ, q) filter's histories of at most `max_junctions` steps."""
    population = problem.population
    assert population is not None
    rounding = problem_rounding(problem, pomdp)
    return tuple(TypeValue.certified(t.name, float(t.weight), found, rounding, max_junctions)
                 for t, found in zip(population.types, bounds, strict=True))


def belief_free_spec(spec: Spec) -> Spec:
    """The spec whose optimum on type k's model alone bounds V_k(π) of every population policy π:
    the spec itself, or, when its labels read the AV's belief (which is not type k's own posterior),
    the spec with every belief and type-belief literal (positive or negated) replaced by true, its
    road and trust-state atoms kept. The projection holds wherever some belief makes the spec's
    literal hold, so a run satisfying the spec satisfies it."""
    if not (spec.belief_atoms or spec.type_atoms):
        return spec

    def replace_belief(literal: Literal) -> Formula:
        return TRUE if literal.atom in spec.belief_atoms or literal.atom in spec.type_atoms else literal

    formula = map_literals(spec.formula, replace_belief)
    return Spec(name=f"{spec.name} (belief-free)", start=spec.start, formula_text=format_formula(formula),
                formula=formula, state_atoms=dict(spec.state_atoms), belief_atoms={},
                source_path=spec.source_path, trust_atoms=dict(spec.trust_atoms))


def type_optimum_bounds(problem: Problem, settings: SynthesisSettings, schedule: RunSchedule,
                        synthesize: Callable[..., SynthesisResult]) -> tuple[float, ...]:
    """U_k for every type: a sound bound of max_π V_k(π), the synthesis (`synthesize`, the one
    synthesis entry) on type k's model alone of `belief_free_spec` of the spec as given."""
    population = problem.population
    assert population is not None
    own_spec = belief_free_spec(problem.given_spec)
    bounds = []
    for t in population.types:
        own = synthesize(build_pomdp(problem.town, t.model), own_spec,
                         replace(settings, time_limit=schedule.capped_limit(TYPE_BOUND_SHARE),
                                 belief_rule="bayes"))
        schedule.finished(f"bound of type {t.name}'s own optimum", own.lower, own.upper,
                          ended=run_end(own))
        bounds.append(own.upper)
    return tuple(bounds)


def robust_candidates(problem: Problem, bayes: JointSynthesis, values: tuple[TypeValue, ...],
                      settings: SynthesisSettings, schedule: RunSchedule, bound: float,
                      on_iteration: RoundProgress | None
                      ) -> tuple[JointTablePolicy, tuple[TypeValue, ...], np.ndarray, list[dict]]:
    """The candidate with the best worst type: the Bayes policy and, for every prior λ of the
    simplex grid, the trust-state synthesis as if the type prior were λ, run on the AV's filter
    (weights w) with J and b reweighted to λ, until the best is within tau of `bound` (the robust
    objective's certified upper bound). (policy, its per-type values, λ, every candidate's
    record)."""
    population = problem.population
    assert population is not None
    horizon, belief_rule, grid_points = settings.horizon, settings.belief_rule, settings.grid_points
    assert grid_points is not None
    weights = population.weights
    cap = evaluation_cap(horizon)

    def record(prior: np.ndarray, found: tuple[TypeValue, ...]) -> dict:
        return {"prior": prior.tolist(), "worst_type_lower": worst_type(found),
                "type_lower": [v.lower for v in found]}

    best: tuple[JointTablePolicy, tuple[TypeValue, ...], np.ndarray] = (bayes.policy, values, weights)
    candidates = [record(weights, values)]
    def settled() -> bool:
        return within_tau(best[1], bound, settings.tau)
    candidate_progress = robust_progress(on_iteration, lambda: worst_type(best[1]), bound, False)

    for prior in candidate_priors(weights, population.n_types, grid_points, schedule, settled):
        model = build_pomdp(problem.town, lift_population(population, prior))
        # the candidate's model differs from the population's in its prior only: its exact
        # filters take the symbol matrices of the population model's rather than convert them again
        for rule, source in problem.pomdp.exact_filters.items():
            exact_filter(model, rule, like=source)
        made = synthesize_joint(model, problem.spec,
                                replace(settings, time_limit=schedule.next_limit()),
                                on_iteration=candidate_progress)
        schedule.finished(candidate_name(prior), made.lower, made.upper,
                          ended=run_end(made))
        policy = JointTablePolicy(made.policy.table, problem.pomdp, problem.spec, made.policy.guide_horizon,
                                  name="robust", certificate=Certificate(horizon=horizon),
                                  guide=made.policy.guide, reweight=reweighting(population, prior))
        found = joint_type_values(problem, policy, cap, belief_rule, deadline=schedule.budget.deadline)
        candidates.append(record(prior, found))
        if worst_type(found) > worst_type(best[1]):
            best = (policy, found, prior)
    return (*best, candidates)


def synthesize_population_joint(problem: Problem, objective: str, synthesize: Callable[..., SynthesisResult],
                                settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                                on_iteration: RoundProgress | None = None,
                                on_phase: Callable[[str], None] | None = None,
                                ) -> PopulationSynthesis:
    """The population synthesis (module docstring) of a TRUST_STATE problem with a population.
    `synthesize`: the one synthesis entry (policies/synthesize_spec.py `synthesize_spec`), for the
    per-type bounds of the robust objective; settings.grid_points: its candidate type priors (None:
    MAX_GRID_CANDIDATES). settings.time_limit bounds the whole call, shared among its synthesis
    runs (policies/synthesis/budget.py RunSchedule); on_phase hears a line per finished run."""
    if objective not in OBJECTIVES:
        raise ValueError(f"unknown objective {objective!r}; use 'bayes' or 'robust'")
    population = problem.population
    if population is None:
        raise ValueError("population synthesis needs a problem with a driver population")
    grid_points = MAX_GRID_CANDIDATES if settings.grid_points is None else settings.grid_points
    settings = replace(settings, grid_points=grid_points)
    horizon, belief_rule = settings.horizon, settings.belief_rule
    started = time.perf_counter()
    schedule = RunSchedule(TimeBudget.start(settings.time_limit),
                           run_count(population, objective, grid_points), on_phase=on_phase)
    # the per-type bounds first (capped shares), then the Bayes run with most of the time
    # (policies/synthesis/population.py: a run given less than its fixed costs finds nothing)
    robust = objective == "robust"
    type_upper = type_optimum_bounds(problem, settings, schedule, synthesize) if robust else ()
    if robust:
        limit = schedule.next_limit(BAYES_SHARE)
    else:   # the rest for its per-type evaluation (one type: the single-model run's whole limit)
        limit = schedule.capped_limit(1.0 - (EVALUATION_SHARE if population.n_types > 1 else 0.0))
    told = robust_progress(on_iteration, lambda: None, min(type_upper), True) if robust else on_iteration
    bayes = synthesize_joint(problem.pomdp, problem.spec, replace(settings, time_limit=limit),
                             on_iteration=told)
    schedule.finished("Bayes objective, the population's weights", bayes.lower, bayes.upper,
                      ended=run_end(bayes))
    values = joint_type_values(problem, bayes.policy, evaluation_cap(horizon), belief_rule,
                               deadline=schedule.budget.deadline)
    found = PopulationSynthesis(
        objective="bayes", population=population, result=bayes, pomdp=problem.pomdp, spec=problem.spec,
        prior=tuple(float(w) for w in population.weights), type_values=values, lower=bayes.lower,
        upper=bayes.upper, seconds=time.perf_counter() - started, bayes_lower=bayes.lower,
        bayes_upper=bayes.upper, bayes_type_values=values)
    if objective == "bayes":
        return found
    upper = min(bayes.upper, *type_upper)
    policy, best_values, prior, candidates = robust_candidates(
        problem, bayes, values, settings, schedule, upper, on_iteration)
    lower = worst_type(best_values)
    if lower > upper + 1e-9:
        raise RuntimeError(f"robust value {lower!r} above its bound {upper!r}: a soundness bug")
    # The policy file's bounds keep their meaning L <= Pr_max <= U under the type prior: L the
    # returned policy's prior-weighted value (the lower ends), U the Bayes synthesis' bound.
    mixture = min(mixture_lower(population.weights, best_values), bayes.upper)
    policy.lower, policy.upper = mixture, bayes.upper
    result = replace(bayes, policy=policy, lower=mixture, seconds=time.perf_counter() - started)
    made = replace(found, objective="robust", result=result, prior=tuple(float(p) for p in prior),
                   type_values=best_values, lower=lower, upper=max(upper, lower),
                   seconds=time.perf_counter() - started, candidates=candidates, type_upper=type_upper,
                   bayes_policy=bayes.policy)
    return with_run_counts(made, schedule)
