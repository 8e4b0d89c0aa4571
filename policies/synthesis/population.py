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

One time limit: `time_limit` bounds the whole call (a TimeBudget, policies/synthesis/budget.py).
Each synthesis run gets an equal share of the time left among the runs still to come (the Bayes
run, the grid's candidates, the per-type bounds); a run that converges early leaves its time to
the next. `on_phase` hears one line per finished run with its bounds.

One type: the Bayes objective is `synthesize` on the type's own model and spec, bit for bit.
Specs with trust-state atoms go to policies/trust_state_synthesis/population.py instead (the one
synthesis entry, policies/synthesize_spec.py `synthesize_for_population`, decides by the case).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from math import comb
from typing import Literal

import numpy as np

from trustroute.networks.town import Town
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.evaluation.plain import Evaluation, evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import Spec, state_only_projection
from trustroute.policies.model.trust_pomdp import BeliefRule, TrustPOMDP, build_pomdp
from trustroute.policies.routing.aware_table import BeliefTablePolicy
from trustroute.policies.routing.episode_rules import DEFAULT_JUNCTION_CAP
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.belief_synthesis import BeliefSynthesis, synthesize
from trustroute.policies.synthesis.budget import TimeBudget
from trustroute.policies.synthesis.result import SynthesisResult
from trustroute.policies.synthesis.settings import DEFAULT_SYNTHESIS, SynthesisSettings
from trustroute.policies.work_clock import now as clock_now

Objective = Literal["bayes", "robust"]
OBJECTIVES: tuple[str, ...] = ("bayes", "robust")
MAX_GRID_CANDIDATES = 16


@dataclass(frozen=True)
class TypeValue:
    """Certified value [lower, upper] of a policy when the driver is of one type."""

    name: str
    weight: float
    lower: float
    upper: float

    def to_dict(self) -> dict:
        return {"name": self.name, "weight": self.weight, "lower": self.lower, "upper": self.upper}


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

    @property
    def gap(self) -> float:
        return self.upper - self.lower

    @property
    def mixture_value(self) -> tuple[float, float]:
        """Σ_k w_k V_k of the returned policy: [lower, upper]."""
        w = self.population.weights
        return (float(w @ [v.lower for v in self.type_values]),
                float(w @ [v.upper for v in self.type_values]))

    @property
    def worst_type_value(self) -> float:
        return min(v.lower for v in self.type_values)


def evaluation_cap(horizon: int | None) -> int:
    """The junction cap per-type values are evaluated with: synthesis' horizon (unbounded: the
    episode cap, so the values are lower bounds of the unbounded ones)."""
    return DEFAULT_JUNCTION_CAP if horizon is None else horizon


def per_type_values(pomdp: TrustPOMDP, spec: Spec, policy: RoutingPolicy, population: DriverPopulation,
                    max_junctions: int, belief_rule: BeliefRule = "bayes", fallback_after: int | None = None,
                    deadline: float | None = None) -> tuple[TypeValue, ...]:
    """Exact value of `policy` (its AV filtering on `pomdp`) for each type of `population` as the
    true driver; past `deadline` (on the synthesis' clock) the histories still open are cut, so a value
    is then certified [lower, upper] rather than exact."""
    out = []
    for t in population.types:
        truth = build_pomdp(pomdp.town, t.model)
        value: Evaluation = evaluate(pomdp, spec, policy,
                                     EvaluationSettings(fallback_after=fallback_after,
                                                        max_junctions=max_junctions, belief_rule=belief_rule),
                                     truth=truth, deadline=deadline)
        out.append(TypeValue(t.name, float(t.weight), value.lower, value.upper))
    return tuple(out)


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


def candidate_priors(weights: np.ndarray, n_types: int, grid_points: int,
                     schedule: RunSchedule) -> Iterator[np.ndarray]:
    """The robust search's candidate priors: the simplex grid less the population's own weights
    (run already), each while the schedule affords its run, else skipped and said so. Lazy: the
    schedule is asked after the run of the previous candidate has finished."""
    for prior in simplex_grid(n_types, grid_points):
        if np.allclose(prior, weights, rtol=0, atol=1e-12):
            continue
        if not schedule.affords(n_types):
            schedule.skip(candidate_name(prior))
            continue
        yield prior


def _count(k: int, m: int) -> int:
    return comb(m + k - 1, k - 1)


MIN_RUN_SECONDS = 0.05  # a run's share never below this: a search needs a first expansion
# A run given MIN_RUN_SECONDS takes up to about this many times as long: its fixed costs (the
# abstraction, the table) come before its first deadline check (measured: 0.05-0.18 s on the
# packaged town at H = 20).
LATER_RUN_FACTOR = 3.0


@dataclass
class RunSchedule:
    """The runs of one population synthesis under one TimeBudget: each run's time limit is an
    equal share of the time left among the runs still to come, after the work between runs (the
    exact per-type evaluations, at their mean cost so far) is set aside for the gaps to come."""

    budget: TimeBudget
    runs: int
    done: int = 0
    on_phase: Callable[[str], None] | None = None
    last_end: float | None = None
    between: float = 0.0  # seconds spent between runs so far
    gaps: int = 0

    def _close_gap(self) -> None:
        """Count the work since the last run ended (its evaluations) as one gap between runs."""
        if self.last_end is not None:
            self.between += clock_now() - self.last_end
            self.gaps += 1
            self.last_end = None

    def next_limit(self) -> float:
        self._close_gap()
        now = clock_now()
        remaining = max(self.runs - self.done, 1)
        per_gap = self.between / self.gaps if self.gaps else 0.0
        left = max(self.budget.deadline - now - per_gap * remaining, 0.0)
        return max(left / remaining, MIN_RUN_SECONDS)

    def affords(self, later_runs: int) -> bool:
        """Whether one more run with its following work still fits before the deadline, with
        `later_runs` runs after it that must run (the per-type bounds)."""
        self._close_gap()
        per_gap = self.between / self.gaps if self.gaps else 0.0
        return self.budget.fits(per_gap + MIN_RUN_SECONDS * (1 + later_runs))

    def skip(self, what: str) -> None:
        """A run left out for want of time (a candidate prior)."""
        self.runs -= 1
        if self.on_phase is not None:
            self.on_phase(f"[{self.budget.elapsed():.1f} s] {what}: skipped, the time limit is reached")

    def evaluation_deadline(self, later_runs: int) -> float:
        """The deadline of the exact evaluations after a run: the call's, less the shortest share
        of the `later_runs` runs that must still come (the per-type bounds), each allowed
        LATER_RUN_FACTOR times its share for its fixed costs."""
        return self.budget.deadline - LATER_RUN_FACTOR * MIN_RUN_SECONDS * later_runs

    def finished(self, what: str, lower: float, upper: float) -> None:
        self.done += 1
        self.last_end = clock_now()
        if self.on_phase is not None:
            self.on_phase(f"[{self.done}/{self.runs}, {self.budget.elapsed():.1f} s] {what}: "
                          f"[{lower:.6f}, {upper:.6f}]")


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


def synthesize_population(town: Town, population: DriverPopulation, spec: Spec,
                          objective: Objective = "bayes", settings: SynthesisSettings = DEFAULT_SYNTHESIS,
                          population_source: str = "",
                          on_iteration: Callable[[float, float], None] | None = None,
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
    # The AV's filter and the spec's belief labels: the type-aware model under the population's
    # weights. Candidates of the robust objective are synthesized under other priors λ but run on
    # this filter, their beliefs reweighted to λ (so the spec means the same for every candidate).
    pomdp = build_pomdp(town, lift_population(population))
    bayes = synthesize(pomdp, lifted_spec, replace(settings, time_limit=schedule.next_limit()),
                       on_iteration=on_iteration)
    schedule.finished("Bayes objective, the population's weights", bayes.lower, bayes.upper)
    # the per-type bounds of the robust objective must still run after the evaluations
    later = population.n_types if objective == "robust" else 0
    bayes_values = per_type_values(pomdp, lifted_spec, bayes.policy, population, cap, belief_rule,
                                   deadline=schedule.evaluation_deadline(later))
    weights = population.weights
    if objective == "bayes":
        return PopulationSynthesis(
            objective="bayes", population=population, result=bayes, pomdp=pomdp, spec=lifted_spec,
            prior=tuple(float(w) for w in weights), type_values=bayes_values, lower=bayes.lower,
            upper=bayes.upper, seconds=time.perf_counter() - started, bayes_lower=bayes.lower,
            bayes_upper=bayes.upper, bayes_type_values=bayes_values)

    def worst(values: tuple[TypeValue, ...]) -> float:
        return min(v.lower for v in values)

    best_policy, best_values, best_prior, best_stats = bayes.policy, bayes_values, weights, bayes.stats
    candidates = [{"prior": weights.tolist(), "worst_type_lower": worst(bayes_values),
                   "type_lower": [v.lower for v in bayes_values]}]
    if population.n_types > 1:
        for prior in candidate_priors(weights, population.n_types, grid_points, schedule):
            made = synthesize(build_pomdp(town, lift_population(population, prior)), lifted_spec,
                              replace(settings, time_limit=schedule.next_limit()), on_iteration=on_iteration)
            schedule.finished(candidate_name(prior), made.lower, made.upper)
            policy = BeliefTablePolicy(made.policy.table, town, lifted_spec, name="robust",
                                       horizon=horizon, reweight=reweighting(population, prior))
            values = per_type_values(pomdp, lifted_spec, policy, population, cap, belief_rule,
                                     deadline=schedule.evaluation_deadline(later))
            candidates.append({"prior": prior.tolist(), "worst_type_lower": worst(values),
                               "type_lower": [v.lower for v in values]})
            if worst(values) > worst(best_values):
                best_policy, best_values, best_prior, best_stats = policy, values, prior, made.stats
    # U_k: type k's own optimum; the state-only projection when labels read the AV's belief.
    own_spec = spec if not (spec.belief_atoms or spec.type_atoms) else state_only_projection(spec)
    type_upper = []
    for t in population.types:
        own = synthesize(build_pomdp(town, t.model), own_spec,
                         replace(settings, time_limit=schedule.next_limit(), belief_rule="bayes"))
        schedule.finished(f"bound of type {t.name}'s own optimum", own.lower, own.upper)
        type_upper.append(own.upper)
    upper = min(bayes.upper, min(type_upper))
    lower = worst(best_values)
    if lower > upper + 1e-9:
        raise RuntimeError(f"robust value {lower!r} above its bound {upper!r}: a soundness bug")
    upper = max(upper, lower)   # equal up to rounding
    # The returned policy's file bounds keep their meaning L <= Pr_max <= U under the type prior: L
    # its exact prior-weighted value (the lower ends), U the Bayes synthesis' bound.
    mixture = float(weights @ [v.lower for v in best_values])
    policy = BeliefTablePolicy(best_policy.table, town, lifted_spec, name="robust",
                               lower=min(mixture, bayes.upper), upper=bayes.upper, horizon=horizon,
                               reweight=best_policy.reweight)
    seconds = time.perf_counter() - started
    result = SynthesisResult(policy=policy, lower=min(mixture, bayes.upper), upper=bayes.upper,
                             seconds=seconds, stats=replace(best_stats, objective="robust"),
                             horizon=horizon, belief_rule=belief_rule)
    return PopulationSynthesis(
        objective="robust", population=population, result=result, pomdp=pomdp, spec=lifted_spec,
        prior=tuple(float(p) for p in best_prior), type_values=best_values, lower=lower,
        upper=upper, seconds=seconds, bayes_lower=bayes.lower, bayes_upper=bayes.upper,
        bayes_type_values=bayes_values, candidates=candidates, type_upper=tuple(type_upper),
        bayes_policy=bayes.policy)


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
                  "worst_type_value": min(v.lower for v in synthesis.bayes_type_values)},
        "seconds": synthesis.seconds,
    }
    if synthesis.objective == "robust":
        out["type_upper"] = list(synthesis.type_upper)
        out["candidates"] = synthesis.candidates
    return out
