"""Synthesis over a driver population: the Bayes objective and the robust (worst-type) objective,
with per-type values and what is certified (docs/driver_types.md, "Synthesis over a population").

The AV's belief, which the spec's belief labels read, is always the type-aware filter under the
population's weights w (policies/belief/driver_types.py): the spec means the same for every policy.

Bayes: synthesize on the type-aware POMDP with initial belief w ⊗ b0. Its L and U are
synthesize's: L is a lower bound of the returned policy's value under the type prior (unexpanded
nodes valued by a lower bound of the trust-free completion), U a sound bound of the population
optimum max_π Σ_k w_k V_k(π). Per-type values V_k are exact evaluations (policies/evaluation/plain.py)
of the returned policy with the driver of type k (truth = type k's model, the AV filtering on the
lifted model) for the same horizon and no fallback, as synthesis scores it; Σ_k w_k V_k >= L.

Robust: maximise min_k V_k. Candidates are the Bayes policy and the policies synthesized as if
the type prior were λ, for λ on a simplex grid; such a policy runs on the w-filter with its
beliefs reweighted to λ (exact; policies/routing/aware_table.py), a function of the observations
like any policy, and each V_k is evaluated exactly with the true type k. The candidate with the
best worst type is returned. Certified: `lower` = min_k V_k(returned policy), exact (the lower
ends of the certified evaluations); `upper` = min(U_bayes, min_k U_k), U_k a bound of type k's
own optimum max_π V_k(π) (a synthesis on type k's model alone, of the spec's state-only
projection when the spec reads beliefs, since the AV's belief is not type k's own), because
max_π min_k V_k <= min_k max_π V_k and <= max_π Σ_k w_k V_k. The gap says how far the grid search
may be from the robust optimum.

One time limit: `time_limit` bounds the whole call (a TimeBudget, policies/synthesis/budget.py),
shared by its runs in this order (budget.py's RunSchedule): the per-type bounds (robust; each an
equal share of the time left, at most TYPE_BOUND_SHARE of it), the Bayes run (robust: BAYES_SHARE
of the time left; bayes: all but EVALUATION_SHARE, kept for its exact per-type evaluations), then
the grid's candidates while a run with time for its fixed costs still fits. A run that converges early leaves
its time to the next. The lifted runs take cluster policies only before their search ("early"):
after it they took half of its time for a lower L. `on_phase` hears one line per finished run with
its bounds.

One type: the Bayes objective is `synthesize` on the type's own model and spec, bit for bit.
Specs with trust-state atoms go to policies/trust_state_synthesis/population.py instead (the one
synthesis entry, policies/synthesize_spec.py `synthesize_for_population`, decides by the case).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from math import comb
from typing import Literal, TypeAlias

import numpy as np

from trustroute.networks.town import Town
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.labelling import gamma
from trustroute.policies.logic.spec import Spec, state_only_projection
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, build_pomdp
from trustroute.policies.routing.aware_table import BeliefTablePolicy, PolicyTable
from trustroute.policies.routing.decision_tables import fallback_only
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.belief_synthesis import BeliefSynthesis, synthesize
from trustroute.policies.synthesis.budget import MIN_RUN_SECONDS, RunSchedule, TimeBudget
from trustroute.policies.synthesis.cluster_policy import own_cap
from trustroute.policies.synthesis.refinement import reached_node_budget
from trustroute.policies.synthesis.result import RoundProgress, SearchRun, SynthesisResult, SynthesisStats
from trustroute.policies.synthesis.result import robust_progress as told_robust
from trustroute.policies.synthesis.rounding import (
    ModelRounding,
    evaluation_widened,
    model_rounding,
    rounded_down,
    rounded_up,
)
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.work_clock import now as clock_now
from trustroute.policies.work_clock import stopped_by

Objective = Literal["bayes", "robust"]
OBJECTIVES: tuple[str, ...] = ("bayes", "robust")
MAX_GRID_CANDIDATES = 16
# The shares of one population synthesis. The Bayes run's policy is the first candidate of the
# robust objective and its U bounds the robust optimum, and a run given less than its fixed costs
# (the lifted model's exact filter, product and abstraction: 2-4 s at H = 20 on the paper's town)
# never expands its root: so the Bayes run comes first with most of the time, a candidate prior
# starts only while the Bayes run's fixed costs fit and is given CANDIDATE_SETUP_FACTOR times
# them where the time allows, and the exact
# per-type evaluation of the Bayes objective's policy keeps EVALUATION_SHARE of the limit.
BAYES_SHARE = 0.5             # robust: share of the time left the Bayes run takes
TYPE_BOUND_SHARE = 0.1        # robust: share of the time left each per-type bound run takes at most
EVALUATION_SHARE = 0.2        # bayes: share of the time left kept for the per-type evaluations
CANDIDATE_SETUP_FACTOR = 2.0


@dataclass(frozen=True)
class TypeValue:
    """Certified value [lower, upper] of a policy when the driver is of one type; `exact`: its
    evaluation cut no history, so lower and upper differ by the certified rounding alone."""

    name: str
    weight: float
    lower: float
    upper: float
    exact: bool = False

    def to_dict(self) -> dict:
        return {"name": self.name, "weight": self.weight, "lower": self.lower, "upper": self.upper}

    @classmethod
    def certified(cls, name: str, weight: float, computed: tuple[float, float], truth: ModelRounding,
                  max_junctions: int) -> TypeValue:
        """A type's value from an evaluation's computed [lower, upper], rounded outward for its
        histories of at most `max_junctions` steps under the true driver's constants `truth`
        (rounding.py: an evaluation sums the same products of observation probabilities as a
        search; the true driver's posterior gives them)."""
        return cls(name, weight, *evaluation_widened(computed[0], computed[1], truth, max_junctions),
                   exact=computed[0] == computed[1])


def _mixture(weights: np.ndarray, ends: list[float]) -> tuple[float, float]:
    """Σ_k w_k e_k / Σ_k w_k in floats and the relative margin of its error. The exact type prior
    is the weights' decimals normalised (exact_labels.exact_prior): a population's weights sum to
    1.0 in floats (DriverPopulation divides them by their sum), their decimals only within
    roundings, and dividing by the sum keeps the mixture right for any weights. Each term carries
    its product and the sum's k - 1 additions (nonnegative terms: γ_k), its weight against the
    weight's decimal (u), the weights' correctly rounded sum (u) against the decimals' (u) and the
    division (u): γ_{k+4}."""
    return float(weights @ ends) / math.fsum(weights.tolist()), gamma(len(ends) + 4)


def mixture_lower(weights: np.ndarray, values: Iterable[TypeValue]) -> float:
    """Σ_k w̄_k V_k's lower end, w̄ the weights normalised, rounded down by its float error."""
    value, margin = _mixture(weights, [v.lower for v in values])
    return float(rounded_down(value, margin))


def mixture_upper(weights: np.ndarray, values: Iterable[TypeValue]) -> float:
    """Σ_k w̄_k V_k's upper end, w̄ the weights normalised, rounded up by its float error."""
    value, margin = _mixture(weights, [v.upper for v in values])
    return float(rounded_up(value, margin))


@dataclass(frozen=True, eq=False)
class PopulationSynthesis:
    """The returned policy (`result.policy`, acting on the lifted belief from `prior` ⊗ b0) and its
    certified objective `lower <= optimum <= upper`."""

    objective: str
    population: DriverPopulation
    result: BeliefSynthesis | SynthesisResult   # a JointSynthesis for trust-state specs
    pomdp: TrustPOMDP                 # the type-aware POMDP the policy's AV filters on
    spec: Spec                        # the lifted spec
    prior: tuple[float, ...]          # λ: the AV's type prior of the returned policy
    type_values: tuple[TypeValue, ...]
    lower: float
    upper: float
    seconds: float
    bayes_lower: float                # the Bayes-optimal synthesis' L and U, beside the robust value
    bayes_upper: float
    bayes_type_values: tuple[TypeValue, ...]
    candidates: list[dict] = field(default_factory=list)
    type_upper: tuple[float, ...] = ()  # U_k (robust objective)
    bayes_policy: RoutingPolicy | None = None   # the Bayes synthesis' policy (robust objective)
    candidates_not_needed: int = 0    # candidate priors not run: the best was within tau of `upper`
    candidates_skipped: int = 0       # candidate priors not run for want of time
    runs_cut: int = 0                 # runs (robust objective) that ended at their limit unconverged
    runs_at_node_budget: int = 0      # runs (robust objective) whose search stopped at its node budget

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    @property
    def mixture_value(self) -> tuple[float, float]:
        """Σ_k w_k V_k of the returned policy, certified: [lower, upper]."""
        w = self.population.weights
        return mixture_lower(w, self.type_values), mixture_upper(w, self.type_values)

    @property
    def worst_type_value(self) -> float:
        return worst_type(self.type_values)


def with_run_counts(found: PopulationSynthesis, schedule: RunSchedule) -> PopulationSynthesis:
    """`found` with the counts of its runs its schedule kept (the candidate priors not needed and
    skipped, the runs cut and at their node budget), as a robust synthesis of either kind reports them."""
    return replace(found, candidates_not_needed=schedule.not_needed, candidates_skipped=schedule.skipped,
                   runs_cut=schedule.cut, runs_at_node_budget=schedule.at_node_budget)


def evaluation_cap(horizon: int | None) -> int:
    """The junction cap per-type values are evaluated with: synthesis' horizon (unbounded: the
    episode cap, so the values are lower bounds of the unbounded ones)."""
    return DEFAULT_JUNCTION_CAP if horizon is None else horizon


def per_type_values(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy, population: DriverPopulation,
                    max_junctions: int, belief_rule: BeliefRule = "bayes", fallback_after: int | None = None,
                    deadline: float | None = None) -> tuple[TypeValue, ...]:
    """Exact value of `policy` (its AV filtering on `pomdp`) for each type of `population` as the
    true driver; past `deadline` (on the synthesis' clock) the histories still open are cut, so a value
    is then certified [lower, upper] rather than exact; each type has its share of the time left
    (`type_deadline`), so that a cut falls on every type alike."""
    settings = EvaluationSettings(fallback_after=fallback_after, max_junctions=max_junctions,
                                  belief_rule=belief_rule)
    found = candidate_values(pomdp, spec, policy, population, settings, deadline,
                             list(range(population.n_types)), beaten_at=-math.inf)
    return tuple(v for v in found if v is not None)   # none left out: nothing is beaten below -inf


def type_deadline(deadline: float | None, types_left: int) -> float | None:
    """The deadline of the next of `types_left` per-type evaluations: an equal share of the time
    left before `deadline` (a cut evaluation leaves its type's value [lower, upper]; one type
    taking all the time would leave the others at lower 0)."""
    if deadline is None:
        return None
    now = clock_now()
    return now + max(deadline - now, 0.0) / max(types_left, 1)


def simplex_grid(k: int, max_points: int = MAX_GRID_CANDIDATES) -> list[np.ndarray]:
    """Points of the probability simplex in K dimensions with coordinates multiples of 1/m, for
    the largest m giving at most `max_points` points (at least the vertices)."""
    m = 1
    while _count(k, m + 1) <= max_points:
        m += 1
    points = []
    for combo in itertools.product(range(m + 1), repeat=k):
        if sum(combo) == m:
            points.append(np.array(combo, dtype=float) / m)
    return points


def candidate_name(prior: np.ndarray) -> str:
    return f"candidate prior {np.round(prior, 3).tolist()}"


def candidate_priors(weights: np.ndarray, n_types: int, grid_points: int, schedule: RunSchedule,
                     settled: Callable[[], bool], favoured: int | None = None,
                     seconds: float = MIN_RUN_SECONDS) -> Iterator[np.ndarray]:
    """The robust search's candidate priors: the simplex grid less the population's own weights
    (run already), each while the schedule affords its run of `seconds`, else skipped and said so;
    none once `settled()` (the best candidate so far is within tau of the robust bound, so no
    candidate can be worth more than tau above it), and said so; with `favoured` (a type), those
    giving it the most weight first, since the time may not afford them all. Lazy: the schedule and
    `settled` are asked after the run of the previous candidate has finished."""
    grid = [prior for prior in simplex_grid(n_types, grid_points)
            if not np.allclose(prior, weights, rtol=0, atol=1e-12)]
    if favoured is not None:
        grid.sort(key=lambda prior: -prior[favoured])   # stable: the grid's order among equals
    for index, prior in enumerate(grid):
        if settled():
            schedule.settle(len(grid) - index)
            return
        if not schedule.affords(0, seconds):
            schedule.skip(candidate_name(prior))
            continue
        yield prior


def _count(k: int, m: int) -> int:
    return comb(m + k - 1, k - 1)


def run_count(population: DriverPopulation, objective: str, grid_points: int) -> int:
    """Synthesis runs of a population synthesis: the Bayes run; for the robust objective also the
    grid's candidates other than the weights and one per type."""
    if objective != "robust":
        return 1
    grid = simplex_grid(population.n_types, grid_points) if population.n_types > 1 else []
    others = sum(1 for prior in grid if not np.allclose(prior, population.weights, rtol=0, atol=1e-12))
    return 1 + others + population.n_types


def reweighting(population: DriverPopulation, prior: np.ndarray) -> np.ndarray:
    """r per hidden index: λ_k / w_k on type k's block (policies/routing/aware_table.py)."""
    n = population.types[0].model.n_trust
    return np.repeat(np.asarray(prior, dtype=float) / population.weights, n)


# the AV's model, the Bayes run and its per-type values
BayesRun: TypeAlias = tuple[TrustPOMDP, BeliefSynthesis, tuple["TypeValue", ...]]
# a robust candidate: its policy, per-type values, type prior λ and run statistics
Candidate: TypeAlias = tuple[BeliefTablePolicy, tuple["TypeValue", ...], np.ndarray, SynthesisStats]


def worst_type(values: Iterable[TypeValue]) -> float:
    """The robust value of a policy: the lower end of its worst type's value."""
    return min(v.lower for v in values)


def within_tau(values: Iterable[TypeValue], bound: float, tau: float) -> bool:
    """Whether a policy with these per-type values settles the robust search: its worst type is
    within tau of the robust bound, so no candidate can be worth more than tau above it."""
    return worst_type(values) >= bound - tau


def run_end(run: SynthesisResult) -> str:
    """What ended a run of the schedule, of either kind, in work_clock.stopped_by's words:
    "convergence", "node budget", its own cap (`own_cap`), else its limit (one of LIMITS: which
    one is the call's to name, from its clock)."""
    return stopped_by(run.stats.converged, None, reached_node_budget(run.stats), own_cap(run))


def setup_seconds(result: BeliefSynthesis) -> float:
    """A synthesis run's fixed costs before its search could expand (the exact filter, the product,
    the abstraction), as its search runs report them on the synthesis' clock: under a work limit
    the work they took, so that whether a candidate runs and how long it is given depend on the
    work done, not on the machine's load."""
    return max((run.abstraction_clock_seconds for run in result.stats.runs if isinstance(run, SearchRun)),
               default=0.0)


def type_bounds(town: Town, population: DriverPopulation, spec: Spec, settings: SynthesisSettings,
                schedule: RunSchedule) -> tuple[float, ...]:
    """U_k for every type: a sound bound of type k's own optimum, the synthesis on type k's model
    alone (of the spec's state-only projection when labels read the AV's belief)."""
    own_spec = spec if not (spec.belief_atoms or spec.type_atoms) else state_only_projection(spec)
    bounds = []
    for t in population.types:
        own = synthesize(build_pomdp(town, t.model), own_spec,
                         replace(settings, time_limit=schedule.capped_limit(TYPE_BOUND_SHARE),
                                 belief_rule="bayes"))
        schedule.finished(f"bound of type {t.name}'s own optimum", own.lower, own.upper,
                          ended=run_end(own))
        bounds.append(own.upper)
    return tuple(bounds)


def candidate_values(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy, population: DriverPopulation,
                     settings: EvaluationSettings, deadline: float | None, order: list[int], beaten_at: float
                     ) -> tuple[TypeValue | None, ...]:
    """A candidate's exact per-type values, type by type in `order`; once a type's upper end is at
    most `beaten_at` (the best worst type so far) the candidate cannot be returned and the types
    left are not evaluated (None)."""
    out: list[TypeValue | None] = [None] * population.n_types
    for i, k in enumerate(order):
        t = population.types[k]
        truth = build_pomdp(pomdp.town, t.model)
        value = evaluate(pomdp, spec, policy, settings, truth=truth,
                         deadline=type_deadline(deadline, len(order) - i))
        out[k] = TypeValue.certified(t.name, float(t.weight), (value.lower, value.upper),
                                     model_rounding(truth), settings.max_junctions)
        if value.upper <= beaten_at:
            break
    return tuple(out)


def complete(found: tuple[TypeValue | None, ...]) -> tuple[TypeValue, ...] | None:
    """Every type's value, or None when some type was not evaluated."""
    known = tuple(v for v in found if v is not None)
    return known if len(known) == len(found) else None


def candidate_record(prior: np.ndarray | None, found: tuple[TypeValue | None, ...], rows: int) -> dict:
    """A candidate's line in the summary: its prior (None: the free completion), its policy's
    decision rows, the lower ends of the types evaluated (None: not evaluated, once it was
    beaten, `"beaten": true`)."""
    known = [v for v in found if v is not None]
    record: dict = {"prior": None if prior is None else prior.tolist(), "rows": rows,
                    "worst_type_lower": worst_type(known),
                    "type_lower": [None if v is None else v.lower for v in found]}
    if len(known) < len(found):   # its worst type may be lower still
        record["beaten"] = True
    return record


def robust_candidates(town: Town, population: DriverPopulation, spec: Spec, settings: SynthesisSettings,
                      schedule: RunSchedule, bayes_run: BayesRun, bound: float,
                      on_iteration: RoundProgress | None) -> tuple[Candidate, list[dict]]:
    """The candidate with the best worst type: the Bayes policy (`bayes_run`: the AV's model, the
    run, its per-type values) and the λ-policies of the grid the time affords, those favouring
    the Bayes policy's worst type first, each given at least CANDIDATE_SETUP_FACTOR times the
    Bayes run's fixed costs, until the best is within tau of `bound` (the robust objective's
    certified upper bound). (policy, its per-type values, λ, its run's stats, every candidate's
    record.)"""
    pomdp, bayes, bayes_values = bayes_run
    weights, horizon = population.weights, settings.horizon
    best: Candidate = (
        bayes.policy, bayes_values, weights, bayes.stats)
    candidates = [candidate_record(weights, bayes_values, bayes.stats.policy_rows)]
    if population.n_types == 1:
        return best, candidates
    grid_points = MAX_GRID_CANDIDATES if settings.grid_points is None else settings.grid_points
    evaluation = EvaluationSettings(max_junctions=evaluation_cap(horizon), belief_rule=settings.belief_rule)
    setup = CANDIDATE_SETUP_FACTOR * setup_seconds(bayes)
    worst_first = sorted(range(population.n_types), key=lambda k: bayes_values[k].lower)
    # the free completion, what a table without rows drives: a run stopped before its first row
    # returns it, and it can serve the worst type better than a table made for the prior
    if fallback_only(bayes.policy) is None:     # else the Bayes policy is that completion
        free = BeliefTablePolicy(PolicyTable.empty(pomdp.n_trust), town, spec, name="robust", horizon=horizon)
        found = candidate_values(pomdp, spec, free, population, evaluation, schedule.budget.deadline,
                                 worst_first, worst_type(best[1]))
        candidates.append(candidate_record(None, found, 0))
        values = complete(found)
        if values is not None and worst_type(values) > worst_type(best[1]):
            best = (free, values, weights, replace(bayes.stats, policy_rows=0))
    # started while its fixed costs fit, given twice them where the time allows (small problems
    # converge within their fixed costs; larger ones need time to expand)
    def settled() -> bool:
        return within_tau(best[1], bound, settings.tau)
    candidate_progress = told_robust(on_iteration, lambda: worst_type(best[1]), bound, False)

    for prior in candidate_priors(weights, population.n_types, grid_points, schedule, settled,
                                  worst_first[0], setup / CANDIDATE_SETUP_FACTOR):
        made = synthesize(build_pomdp(town, lift_population(population, prior)), spec,
                          replace(settings, time_limit=schedule.next_limit(at_least=setup)),
                          on_iteration=candidate_progress)
        schedule.finished(candidate_name(prior), made.lower, made.upper, ended=run_end(made))
        policy = BeliefTablePolicy(made.policy.table, town, spec, name="robust",
                                   horizon=horizon, reweight=reweighting(population, prior))
        found = candidate_values(pomdp, spec, policy, population, evaluation,
                                 schedule.evaluation_deadline(0), worst_first, worst_type(best[1]))
        candidates.append(candidate_record(prior, found, made.stats.policy_rows))
        values = complete(found)
        if values is not None and worst_type(values) > worst_type(best[1]):
            best = (policy, values, prior, made.stats)
    return best, candidates


def synthesize_population(town: Town, population: DriverPopulation, spec: Spec,
                          objective: Objective = "bayes", settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                          population_source: str = "",
                          on_iteration: RoundProgress | None = None,
                          on_phase: Callable[[str], None] | None = None,
                          ) -> PopulationSynthesis:
    """Synthesize for `population` under `objective` (module docstring) within `settings.time_limit`
    seconds in all (the robust objective runs one synthesis per candidate prior and one per type;
    `settings.grid_points` candidate priors, default MAX_GRID_CANDIDATES)."""
    horizon, belief_rule, time_limit = settings.horizon, settings.belief_rule, settings.time_limit
    grid_points = MAX_GRID_CANDIDATES if settings.grid_points is None else settings.grid_points
    if objective not in OBJECTIVES:
        raise ValueError(f"unknown objective {objective!r}; use 'bayes' or 'robust'")
    started = time.perf_counter()
    schedule = RunSchedule(TimeBudget.start(time_limit), run_count(population, objective, grid_points),
                           on_phase=on_phase)
    lifted_spec = lift_spec(spec, population, population_source)
    cap = evaluation_cap(horizon)
    # U_k first: single-model runs, each at most TYPE_BOUND_SHARE of the time left, so that the
    # candidates after the Bayes run cannot leave them nothing.
    type_upper = type_bounds(town, population, spec, settings, schedule) if objective == "robust" else ()
    # The AV's filter and the spec's belief labels: the type-aware model under the population's
    # weights. Candidates of the robust objective are synthesized under other priors λ but run on
    # this filter, their beliefs reweighted to λ (so the spec means the same for every candidate).
    pomdp = build_pomdp(town, lift_population(population))
    if population.n_types > 1 and settings.clusters == "auto":
        settings = replace(settings, clusters="early")
    if objective == "robust":
        limit = schedule.next_limit(BAYES_SHARE)
    else:   # one type: the single-model synthesis with its whole limit (the same result)
        limit = schedule.capped_limit(1.0 - (EVALUATION_SHARE if population.n_types > 1 else 0.0))
    told = told_robust(on_iteration, lambda: None, min(type_upper), True) if type_upper else on_iteration
    bayes = synthesize(pomdp, lifted_spec, replace(settings, time_limit=limit), on_iteration=told)
    schedule.finished("Bayes objective, the population's weights", bayes.lower, bayes.upper,
                      ended=run_end(bayes))
    bayes_values = per_type_values(pomdp, lifted_spec, bayes.policy, population, cap, belief_rule,
                                   deadline=schedule.evaluation_deadline(0))
    weights = population.weights
    if objective == "bayes":
        return PopulationSynthesis(
            objective="bayes", population=population, result=bayes, pomdp=pomdp, spec=lifted_spec,
            prior=tuple(float(w) for w in weights), type_values=bayes_values, lower=bayes.lower,
            upper=bayes.upper, seconds=time.perf_counter() - started, bayes_lower=bayes.lower,
            bayes_upper=bayes.upper, bayes_type_values=bayes_values)
    upper = min(bayes.upper, min(type_upper))
    (best_policy, best_values, best_prior, best_stats), candidates = robust_candidates(
        town, population, lifted_spec, settings, schedule, (pomdp, bayes, bayes_values), upper,
        on_iteration)
    lower = worst_type(best_values)
    if lower > upper + 1e-9:
        raise RuntimeError(f"robust value {lower!r} above its bound {upper!r}: a soundness bug")
    upper = max(upper, lower)   # equal up to rounding
    # The returned policy's file bounds keep their meaning L <= Pr_max <= U under the type prior: L
    # its exact prior-weighted value (the lower ends), U the Bayes synthesis' bound.
    mixture = mixture_lower(weights, best_values)
    policy = BeliefTablePolicy(best_policy.table, town, lifted_spec, name="robust",
                               lower=min(mixture, bayes.upper), upper=bayes.upper, horizon=horizon,
                               reweight=best_policy.reweight)
    seconds = time.perf_counter() - started
    result = SynthesisResult(policy=policy, lower=min(mixture, bayes.upper), upper=bayes.upper,
                             seconds=seconds, stats=replace(best_stats, objective="robust"),
                             horizon=horizon, belief_rule=belief_rule)
    return with_run_counts(PopulationSynthesis(
        objective="robust", population=population, result=result, pomdp=pomdp, spec=lifted_spec,
        prior=tuple(float(p) for p in best_prior), type_values=best_values, lower=lower,
        upper=upper, seconds=seconds, bayes_lower=bayes.lower, bayes_upper=bayes.upper,
        bayes_type_values=bayes_values, candidates=candidates, type_upper=tuple(type_upper),
        bayes_policy=bayes.policy), schedule)


def policy_name(synthesis: PopulationSynthesis) -> str:
    """The name a policy file records: "aware" for one type (the single-model name), else the objective's."""
    return "aware" if synthesis.population.n_types == 1 else synthesis.objective


def document_entries(synthesis: PopulationSynthesis) -> dict | None:
    """The policy file's population keys (policies/routing/files.py POPULATION_KEYS); None for one
    type (the file is then the single-model one)."""
    if synthesis.population.n_types == 1:
        return None
    return {
        "population_hash": synthesis.population.content_hash,
        "population_types": list(synthesis.population.names),
        "population_weights": synthesis.population.weights.tolist(),
        "belief_prior": list(synthesis.prior),
        "objective": synthesis.objective,
        "objective_lower": synthesis.lower,
        "objective_upper": synthesis.upper,
        "type_values": [v.to_dict() for v in synthesis.type_values],
    }


def summary(synthesis: PopulationSynthesis) -> dict:
    """JSON-ready summary: the objective's bounds, per-type values, the Bayes values beside."""
    mixture = synthesis.mixture_value
    out = {
        "objective": synthesis.objective,
        "types": list(synthesis.population.names),
        "weights": synthesis.population.weights.tolist(),
        "belief_prior": list(synthesis.prior),
        "objective_lower": synthesis.lower,
        "objective_upper": synthesis.upper,
        "type_values": [v.to_dict() for v in synthesis.type_values],
        "mixture_value": {"lower": mixture[0], "upper": mixture[1]},
        "worst_type_value": synthesis.worst_type_value,
        "bayes": {"lower": synthesis.bayes_lower, "upper": synthesis.bayes_upper,
                  "type_values": [v.to_dict() for v in synthesis.bayes_type_values],
                  "worst_type_value": worst_type(synthesis.bayes_type_values)},
        "seconds": synthesis.seconds,
    }
    if synthesis.objective == "robust":
        out["type_upper"] = list(synthesis.type_upper)
        out["candidates"] = synthesis.candidates
        out["candidates_not_needed"] = synthesis.candidates_not_needed
        out["candidates_skipped"] = synthesis.candidates_skipped
        out["runs_cut"] = synthesis.runs_cut
    return out
