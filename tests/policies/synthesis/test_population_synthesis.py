"""Synthesis over driver populations on small towns with 2 and 3 types.

- the population optimum by brute-force enumeration over observation-dependent route choices lies
  in [L, U] (and each type's own optimum bounds the robust value, U_k bounds it); the enumeration
  keeps one unnormalised trust filter per type (the types' own arrays, not the lifted model) and
  reads labels on the trust and type marginals;
- the returned policy's exact per-type values weigh up to at least L, and Monte Carlo with sampled
  types and simulated hidden trust (participants.SyntheticDriver) agrees with L and with every
  per-type value within 4 standard errors;
- the robust objective certifies min_k V_k <= its upper bound, and its bound is sound against the
  brute-force robust optimum's upper side (max_π min_k V_k <= min_k max_π V_k).
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_town
from trustroute.participants.driver_model import DriverModel
from trustroute.participants.driver_population import DriverPopulation, DriverType
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.routing.episode_rules import decide, episode_policy
from trustroute.policies.routing.protocol import DecisionContext
from trustroute.policies.synthesis.population import synthesize_population
from trustroute.policies.synthesis.settings import SynthesisSettings

TOLERANCE = 1e-9
INCIDENTS = ("obstacle", "pedestrian", "truck", "none")


def population_of(rng: np.random.Generator, k: int) -> DriverPopulation:
    weights = rng.dirichlet(np.full(k, 2.0))
    return DriverPopulation(types=tuple(DriverType(f"t{j}", float(w), random_driver(rng, INCIDENTS))
                                        for j, w in enumerate(weights)))


def small_spec(rng: np.random.Generator, town, population: DriverPopulation, with_type_atom: bool):
    """Waypoint a near the start, then b further on with a trust-belief atom (and optionally a
    type-belief atom), thresholds near their prior values so that they can go either way."""
    start = str(rng.choice(town.states))
    rings = [{start}]
    for _ in range(3):
        rings.append({nxt for road in rings[-1] for nxt in town.successors(road)})
    a = sorted(rings[1])[: 2]
    b = sorted(rings[2] | rings[3])[: 3]
    coeffs = rng.integers(0, 2, size=7).astype(float)
    coeffs[int(rng.integers(7))] = 1.0
    prior = sum(t.weight * t.model.initial_belief for t in population.types)
    offset = float(coeffs @ prior + rng.uniform(-0.1, 0.1))
    formula = "F (a & F (b & high))" if not with_type_atom else "F (a & F (b & (high | sure)))"
    text = (f'name = "small"\nstart = "{start}"\nformula = "{formula}"\n'
            f"[states]\na = {a}\nb = {b}\n".replace("'", '"')
            + f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset}\n")
    if with_type_atom:
        above = float(min(0.95, population.types[0].weight + 0.05))
        text += f'[type_beliefs]\nsure = {{ types = ["t0"], above = {above} }}\n'
    return spec_from_text(text, "<small spec>", town)


def labels(spec, dfa, town, population: DriverPopulation, x: int, alpha: np.ndarray) -> np.ndarray:
    """Valuation of dfa.atoms at road x with per-type unnormalised joint alpha [K, n]."""
    total = alpha.sum()
    trust = alpha.sum(axis=0) / total
    types = alpha.sum(axis=1) / total
    road = town.states[x]
    out = np.zeros(len(dfa.atoms), dtype=bool)
    for j, atom in enumerate(dfa.atoms):
        if atom in spec.state_atoms:
            out[j] = road in spec.state_atoms[atom]
        elif atom in spec.belief_atoms:
            atom_def = spec.belief_atoms[atom]
            out[j] = float(np.asarray(atom_def.coeffs) @ trust) > atom_def.offset
        else:
            definition = spec.type_atoms[atom]
            mass = sum(types[population.names.index(t)] for t in definition.types)
            out[j] = mass > definition.above
    return out


def step_alpha(model: DriverModel, alpha_k: np.ndarray, incident: int, h: int, e: int) -> np.ndarray:
    p_h = model.takeover_probability[incident] if h else 1 - model.takeover_probability[incident]
    p_e = model.failure_probability[incident] if e else 1 - model.failure_probability[incident]
    return (alpha_k * p_h * p_e) @ model.trust_transition[incident, h, e]


def brute_force(town, population: DriverPopulation, spec, horizon: int) -> tuple[float, list[float]]:
    """(population optimum max_π Σ_k w_k V_k, and each type's own optimum max_π V_k) over every
    observation-dependent choice of next junction, by enumeration."""
    dfa = build_dfa(spec)
    models = population.models
    start = town.state_index(spec.start)
    successors = [[town.state_index(s) for s in town.successors(road)] for road in town.states]
    incident_of = [models[0].incident_index(town.incident(road)) for road in town.states]

    def value(t: int, x: int, q: int, alpha: np.ndarray, weights: np.ndarray) -> float:
        if dfa.accepting[q]:
            return float(weights @ alpha.sum(axis=1))
        if dfa.rejecting[q] or t == horizon:
            return 0.0
        best = 0.0
        for x2 in successors[x]:
            total = 0.0
            for h in (0, 1):
                for e in (0, 1):
                    alpha2 = np.stack([step_alpha(m, alpha[k], incident_of[x2], h, e)
                                       for k, m in enumerate(models)])
                    if not alpha2.sum() > 0:
                        continue
                    q2 = int(dfa.step_many(np.array([q]), labels(spec, dfa, town, population, x2,
                                                                   alpha2)[None])[0])
                    total += value(t + 1, x2, q2, alpha2, weights)
            best = max(best, total)
        return best

    alpha0 = np.stack([t.weight * t.model.initial_belief for t in population.types])
    q0 = int(dfa.step_many(np.array([dfa.initial]), labels(spec, dfa, town, population, start,
                                                           alpha0)[None])[0])
    k = population.n_types
    optimum = value(0, start, q0, alpha0, np.ones(k))
    # type j's own optimum (labels still read the AV's belief under the type prior): weight the
    # accepted mass by 1/w_j on block j only.
    own = [value(0, start, q0, alpha0, np.eye(k)[j] / population.types[j].weight) for j in range(k)]
    return optimum, own


def monte_carlo(synthesis, town, horizon: int, rng: np.random.Generator, n: int,
                type_index: int | None) -> np.ndarray:
    """Satisfied (0/1) of n episodes: the type drawn from the prior (or fixed), the driver's hidden
    trust simulated, the AV filtering and deciding as on the vehicle."""
    pomdp, spec, population = synthesis.pomdp, synthesis.spec, synthesis.population
    compiled = compile_spec(spec, town)
    policy = episode_policy(synthesis.result.policy, town, spec, None)
    out = np.zeros(n)
    for i in range(n):
        k = int(rng.choice(population.n_types, p=population.weights)) if type_index is None else type_index
        driver = SyntheticDriver(population.types[k].model, rng)
        route = [spec.start]
        belief = np.asarray(pomdp.initial_belief, dtype=float)
        q = compiled.initial_state(belief)
        for _ in range(horizon + 1):
            if compiled.accepting[q]:
                out[i] = 1.0
                break
            if compiled.rejecting[q]:
                break
            decision = decide(policy, DecisionContext(route=tuple(route), dfa_state=q, belief=belief),
                              town, horizon)
            if decision.end is not None:
                break
            road = town.successor(route[-1], decision.junction)
            incident = town.incident(road)
            h = driver.decides_takeover(incident)
            e = driver.performance(incident)
            driver.move_trust(incident, h, e)
            posterior, _ = pomdp.belief_update(belief, pomdp.driver.incident_index(incident), int(h),
                                               int(e == "fail"))
            if posterior[0].sum() > 0:
                belief = posterior[0]
            q = compiled.step_road(q, road, belief)
            route.append(road)
    return out


CASES = [(2, 11, False), (3, 14, True)]


@pytest.mark.slow
@pytest.mark.parametrize("k, seed, with_type_atom", CASES)
def test_population_optimum_in_bounds_and_monte_carlo_agrees(k, seed, with_type_atom):
    rng = np.random.default_rng(seed)
    town = random_town(rng)
    population = population_of(rng, k)
    spec = small_spec(rng, town, population, with_type_atom)
    horizon = 3
    optimum, own = brute_force(town, population, spec, horizon)
    found = synthesize_population(town, population, spec, "bayes",
                                  SynthesisSettings(tau=1e-12, horizon=horizon, time_limit=30))
    assert found.lower - TOLERANCE <= optimum <= found.upper + TOLERANCE, (found.lower, optimum, found.upper)
    mixture_lower, mixture_upper = found.mixture_value
    assert mixture_lower >= found.lower - TOLERANCE          # L is a value the policy reaches
    assert mixture_upper <= optimum + TOLERANCE              # and no policy beats the optimum
    for value, best in zip(found.type_values, own, strict=True):
        assert value.lower <= best + TOLERANCE               # type k's value within its own optimum
    # Monte Carlo: sampled types, simulated hidden trust
    n = 2000
    sampled = monte_carlo(found, town, horizon, rng, n, None)
    se = max(sampled.std(ddof=1) / np.sqrt(n), 1e-3)
    assert found.gap <= 1e-9                                  # solved exactly: L is the optimum's value
    assert abs(sampled.mean() - found.lower) <= 4 * se, (sampled.mean(), found.lower)
    assert abs(sampled.mean() - mixture_lower) <= 4 * se
    for j, value in enumerate(found.type_values):
        per_type = monte_carlo(found, town, horizon, rng, 600, j)
        se_j = max(per_type.std(ddof=1) / np.sqrt(per_type.size), 1e-3)
        assert abs(per_type.mean() - value.lower) <= 4 * se_j, (value.name, per_type.mean(), value.lower)
    # robust: certified worst-type value, sound upper bound
    robust = synthesize_population(town, population, spec, "robust",
                                   SynthesisSettings(tau=1e-12, horizon=horizon, time_limit=30,
                                                     grid_points=3))
    assert robust.lower == pytest.approx(min(v.lower for v in robust.type_values), abs=0)
    assert robust.lower >= min(v.lower for v in found.type_values) - TOLERANCE   # at least the Bayes policy's
    assert robust.lower <= min(optimum, *own) + TOLERANCE      # a value some policy reaches
    for bound, best in zip(robust.type_upper, own, strict=True):
        assert bound >= best - TOLERANCE                         # U_k bounds type k's own optimum
    assert robust.upper >= robust.lower


def test_within_tau_settles_exactly_at_the_bound_less_tau():
    """The robust search stops once the worst type is within tau of the bound: at bound - tau
    exactly it stops (the threshold is hit, not approached), a hair below it goes on, and the worst
    type is the minimum over types, not the mean."""
    from fractions import Fraction

    from trustroute.policies.synthesis.population import TypeValue, within_tau
    bound, tau = 0.75, 0.25                      # dyadic: bound - tau is exactly 0.5
    assert float(Fraction(bound) - Fraction(tau)) == 0.5
    at = (TypeValue("a", 0.5, 0.5, 0.6), TypeValue("b", 0.5, 0.9, 1.0))
    below = (TypeValue("a", 0.5, np.nextafter(0.5, 0.0), 0.6), TypeValue("b", 0.5, 0.9, 1.0))
    assert within_tau(at, bound, tau)
    assert not within_tau(below, bound, tau)
    mean_above = (TypeValue("a", 0.5, 0.4, 0.6), TypeValue("b", 0.5, 1.0, 1.0))  # mean 0.7
    assert not within_tau(mean_above, bound, tau)
