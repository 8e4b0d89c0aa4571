"""Certified bounds of driver populations hold exactly, rounding included.

On tiny random towns (3-5 junctions, H <= 4) with populations of 2-3 driver types (random models,
the default one among them; some specs with a type-belief atom; some type weights scaled off 1 by up
to the population file's tolerance, 1e-9, which the population divides by their sum), against the
exact-rational brute force of threshold_cases.py (`exact_value` on the lifted model, and with each
type as the true driver), with no tolerance:

- Bayes objective: L <= the lifted model's exact optimum (the prior-weighted optimum) <= U, and L
  at most the returned policy's exact prior-weighted value;
- every reported per-type value [lower, upper] brackets that type's exact value of the returned
  policy, and the reported mixture lower is at most the exact prior-weighted value (the exact type
  weights: the decimals they print as, normalised, as the lifted prior is);
- robust objective: the same of its returned policy, its lower end at most the worst type's exact
  value, and each U_k at least type k's own exact optimum;
- the mixture alone (`mixture_lower`, `mixture_upper`), its type values each one float that is the
  exact value: brackets the exact prior-weighted value. The synthesized type values lie below and
  above their exact values by their own margin, which hides the mixture's float error; a certified
  bound may equal the exact value, and then only the mixture's own margin holds it.
"""

from __future__ import annotations

import functools
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.threshold_cases import (
    _without_failures,
    exact_value,
    random_town,
    small_spec,
    sweep,
)
from trustroute.participants.driver_population import DriverPopulation, DriverType
from trustroute.policies.belief.exact_labels import decimal
from trustroute.policies.logic.spec import state_only_projection
from trustroute.policies.model.trust_pomdp import BeliefRule, build_pomdp
from trustroute.policies.synthesis.population import (
    TypeValue,
    mixture_lower,
    mixture_upper,
    summary,
    synthesize_population,
)
from trustroute.policies.synthesis.settings import SynthesisSettings

SEEDS = sweep(40, fast=(1, 4, 10))
ROBUST_SEEDS = sweep(12, fast=(1,))


def population_case(seed: int, default_driver):
    """(town, population, spec, horizon): an eventful town (threshold_cases.small_case), 2-3 types
    alike (all with AV failures, the default model first, or all without), weights from a Dirichlet
    law, on half the seeds scaled off 1 by up to 1e-9 (the population divides them by their sum);
    the belief atom's offset near its prior value, half the specs with a type-belief atom on the
    first type; H = 2-4."""
    rng = np.random.default_rng(seed)
    town = random_town(rng, quiet=float(rng.uniform(0.0, 0.25)), junctions=(3, 5))
    k = 2 if rng.random() < 0.75 else 3
    incidents = default_driver.incident_types
    if rng.random() < 0.3:
        models = [default_driver] + [random_driver(rng, incidents) for _ in range(k - 1)]
    else:
        models = [_without_failures(random_driver(rng, incidents)) for _ in range(k)]
    weights = rng.dirichlet(np.full(k, 2.0))
    if rng.random() < 0.5:
        weights = weights * (1.0 + float(rng.uniform(-1e-9, 1e-9)) / 2)
    population = DriverPopulation(types=tuple(DriverType(f"t{j}", float(w), m)
                                              for j, (w, m) in enumerate(zip(weights, models, strict=True))))
    type_atom = ""
    if rng.random() < 0.5:
        type_atom = f'[type_beliefs]\nsure = {{ types = ["t0"], above = {float(rng.uniform(0.2, 0.8))!r} }}\n'
    marginal = sum(t.weight * t.model.initial_belief for t in population.types)
    spec = small_spec(rng, town, type_atom, prior=marginal)
    return town, population, spec, int(rng.integers(2, 5))


def exact_weights(population: DriverPopulation) -> list[Fraction]:
    """The type prior of the exact process: the weights' decimals, normalised."""
    entries = [decimal(w) for w in population.weights]
    return [e / sum(entries) for e in entries]


def type_exact_values(town, found, horizon: int, rule: BeliefRule = "bayes") -> list[Fraction]:
    """The returned policy's exact value with each type as the true driver (the AV filtering on
    the lifted model under `rule`)."""
    return [exact_value(found.pomdp, found.spec, horizon, policy=found.result.policy, rule=rule,
                        truth=build_pomdp(town, t.model)) for t in found.population.types]


def assert_type_values_sound(found, exact: list[Fraction], seed: int) -> None:
    for value, truth in zip(found.type_values, exact, strict=True):
        assert Fraction(value.lower) <= truth <= Fraction(value.upper), (seed, value, truth)
    mixture = sum((w * v for w, v in zip(exact_weights(found.population), exact, strict=True)), Fraction(0))
    reported = summary(found)["mixture_value"]
    assert Fraction(reported["lower"]) <= mixture <= Fraction(reported["upper"]), (seed, reported, mixture)
    assert Fraction(found.result.lower) <= mixture, (seed, found.result.lower, mixture)


@pytest.fixture(scope="module")
def bayes_outcome(driver):
    @functools.cache
    def run(seed: int):
        town, population, spec, horizon = population_case(seed, driver)
        found = synthesize_population(town, population, spec, "bayes",
                                      SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0))
        optimum = exact_value(found.pomdp, found.spec, horizon)
        policy_value = exact_value(found.pomdp, found.spec, horizon, policy=found.result.policy)
        return town, found, horizon, optimum, policy_value

    return run


@pytest.mark.parametrize("seed", SEEDS)
def test_bayes_bounds_contain_the_exact_population_optimum(bayes_outcome, seed):
    _, found, _, optimum, policy_value = bayes_outcome(seed)
    assert 0.0 <= found.lower <= found.upper <= 1.0
    assert Fraction(found.lower) <= optimum <= Fraction(found.upper), (seed, found.lower, optimum,
                                                                       found.upper)
    assert Fraction(found.lower) <= policy_value, (seed, found.lower, policy_value)


@pytest.mark.parametrize("seed", SEEDS)
def test_bayes_per_type_values_bracket_the_exact_ones(bayes_outcome, seed):
    town, found, horizon, _, _ = bayes_outcome(seed)
    assert_type_values_sound(found, type_exact_values(town, found, horizon), seed)


@pytest.mark.parametrize("seed", ROBUST_SEEDS)
def test_robust_values_bracket_the_exact_ones(driver, seed):
    town, population, spec, horizon = population_case(seed, driver)
    found = synthesize_population(town, population, spec, "robust",
                                  SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0,
                                                    grid_points=3))
    exact = type_exact_values(town, found, horizon)
    assert_type_values_sound(found, exact, seed)
    assert Fraction(found.lower) <= min(exact), (seed, found.lower, exact)
    own_spec = state_only_projection(spec) if (spec.belief_atoms or spec.type_atoms) else spec
    for bound, t in zip(found.type_upper, population.types, strict=True):
        own = exact_value(build_pomdp(town, t.model), own_spec, horizon)
        assert own <= Fraction(bound), (seed, t.name, own, bound)
    assert found.lower <= found.upper


@pytest.mark.parametrize("seed", range(40))
def test_the_mixture_brackets_the_exact_value_of_type_values_with_no_slack(driver, seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(2, 6))
    population = DriverPopulation(types=tuple(DriverType(f"t{j}", float(w), driver)
                                              for j, w in enumerate(rng.dirichlet(np.full(k, 2.0)))))
    ends = rng.uniform(0.0, 1.0, k).tolist()
    values = [TypeValue(t.name, t.weight, v, v) for t, v in zip(population.types, ends, strict=True)]
    exact = sum((w * Fraction(v.lower) for w, v in zip(exact_weights(population), values, strict=True)),
                Fraction(0))
    lower, upper = mixture_lower(population.weights, values), mixture_upper(population.weights, values)
    assert Fraction(lower) <= exact <= Fraction(upper), (seed, lower, float(exact), upper)
