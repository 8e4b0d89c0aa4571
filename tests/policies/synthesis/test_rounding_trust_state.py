"""Certified bounds of specs that test the hidden trust hold exactly, rounding included, for one
driver model and for driver populations.

On the small random problems of tests/policies/trust_specs.py (4-5 junctions, random driver models
with AV failures, road, belief and trust-state atoms; populations of 2-3 such types as
tests/policies/trust_state_synthesis/test_population.py draws them, on odd seeds with the weights
scaled off 1 by up to the population file's tolerance, 1e-9, then divided by their sum), H = 1-3,
against the exact-rational brute force over the joint law of hidden index and DFA state
(exact_joint.py), with no tolerance:

- one model: L <= the exact optimum <= U, L at most the returned policy's exact value, and
  `evaluate`'s certified [lower, upper] of that policy brackets its exact value;
- Bayes objective: the same on the lifted model; every per-type value brackets that type's exact
  value of the returned policy; the reported mixture lower is at most the exact prior-weighted
  value (and its upper at least it); `evaluate` of the policy brackets its exact value under the
  type prior and per type;
- robust objective: the same of its returned policy, its lower end at most the worst type's exact
  value, and each U_k at least type k's own exact optimum (of the spec without belief literals).
"""

from __future__ import annotations

import functools
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.synthesis.exact_joint import exact_joint_value
from tests.policies.synthesis.test_rounding_population import assert_type_values_sound
from tests.policies.synthesis.threshold_cases import sweep
from tests.policies.trust_specs import random_problem
from tests.policies.trust_state_synthesis.test_population import random_population_problem
from trustroute.app.synthesis import evaluate_population, evaluate_single
from trustroute.participants.driver_population import DriverPopulation
from trustroute.policies.belief.problem import problem, problem_of
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesize_spec import synthesize_for_population, synthesize_spec
from trustroute.policies.trust_state_synthesis.population import belief_free_spec

SEEDS = sweep(24, fast=(2, 4))
POPULATION_SEEDS = sweep(16, fast=(1, 5))
ROBUST_SEEDS = sweep(8, fast=(1,))
KINDS = ("trust", "mixed")


def settings(horizon: int, **more) -> SynthesisSettings:
    return SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0, **more)


def evaluation(horizon: int) -> EvaluationSettings:
    return EvaluationSettings(fallback_after=None, max_junctions=horizon)


def population_problem(seed: int, driver):
    """(town, population, spec, horizon): 2-3 types, odd seeds with weights scaled off 1 by up to
    1e-9 (the population divides them by their sum)."""
    rng = np.random.default_rng(seed)
    town, population, spec = random_population_problem(rng, driver, 2 + seed % 2, KINDS[seed // 2 % 2])
    if seed % 2:
        scale = 1.0 + float(rng.uniform(-1e-9, 1e-9)) / 2
        population = DriverPopulation(types=tuple(replace(t, weight=t.weight * scale)
                                                  for t in population.types))
    return town, population, spec, 1 + seed % 3


def assert_population_sound(found, horizon: int, seed: int) -> list[Fraction]:
    """Per-type values and the mixture against the exact values of the returned policy."""
    exact = [exact_joint_value(found.pomdp, found.spec, horizon, policy=found.result.policy, block=k)
             for k in range(found.population.n_types)]
    assert_type_values_sound(found, exact, seed)
    return exact


@pytest.mark.parametrize("seed", SEEDS)
def test_one_model_bounds_contain_the_exact_optimum(driver, seed):
    rng = np.random.default_rng(seed)
    pomdp, spec = random_problem(rng, driver, KINDS[seed % 2])
    horizon = 1 + seed % 3
    result = synthesize_spec(pomdp, spec, settings(horizon))
    optimum = exact_joint_value(pomdp, spec, horizon)
    assert Fraction(result.lower) <= optimum <= Fraction(result.upper), (seed, result.lower, optimum,
                                                                         result.upper)
    policy_value = exact_joint_value(pomdp, spec, horizon, policy=result.policy)
    assert Fraction(result.lower) <= policy_value, (seed, result.lower, policy_value)
    value = evaluate_single(problem_of(pomdp, spec), result.policy, evaluation(horizon))
    assert Fraction(value.lower) <= policy_value <= Fraction(value.upper), (seed, value.lower, policy_value,
                                                                            value.upper)


@pytest.fixture(scope="module")
def bayes_population(driver):
    @functools.cache
    def run(seed: int):
        town, population, spec, horizon = population_problem(seed, driver)
        found = synthesize_for_population(town, population, spec, "bayes", settings(horizon))
        return problem(town, population, spec), found, horizon

    return run


@pytest.mark.parametrize("seed", POPULATION_SEEDS)
def test_bayes_population_bounds_contain_the_exact_optimum(bayes_population, seed):
    _, found, horizon = bayes_population(seed)
    optimum = exact_joint_value(found.pomdp, found.spec, horizon)
    assert Fraction(found.lower) <= optimum <= Fraction(found.upper), (seed, found.lower, optimum,
                                                                       found.upper)
    assert_population_sound(found, horizon, seed)


@pytest.mark.parametrize("seed", POPULATION_SEEDS)
def test_evaluate_of_a_population_brackets_the_exact_values(bayes_population, seed):
    given, found, horizon = bayes_population(seed)
    value, per_type = evaluate_population(given, found.result.policy, evaluation(horizon))
    exact = exact_joint_value(found.pomdp, found.spec, horizon, policy=found.result.policy)
    assert Fraction(value.lower) <= exact <= Fraction(value.upper), (seed, value.lower, exact, value.upper)
    for k, reported in enumerate(per_type):
        truth = exact_joint_value(found.pomdp, found.spec, horizon, policy=found.result.policy, block=k)
        assert Fraction(reported.lower) <= truth <= Fraction(reported.upper), (seed, reported, truth)


@pytest.mark.parametrize("seed", ROBUST_SEEDS)
def test_robust_population_values_bracket_the_exact_ones(driver, seed):
    town, population, spec, horizon = population_problem(seed, driver)
    found = synthesize_for_population(town, population, spec, "robust", settings(horizon, grid_points=3))
    exact = assert_population_sound(found, horizon, seed)
    assert Fraction(found.lower) <= min(exact), (seed, found.lower, exact)
    own_spec = belief_free_spec(spec)
    for bound, t in zip(found.type_upper, population.types, strict=True):
        own = exact_joint_value(build_pomdp(town, t.model), own_spec, horizon)
        assert own <= Fraction(bound), (seed, t.name, own, bound)
