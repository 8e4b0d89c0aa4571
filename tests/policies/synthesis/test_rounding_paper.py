"""Certified bounds under the authors' belief rule, and `evaluate`'s, hold exactly, rounding included.

On tiny random towns (threshold_cases.small_case, eventful: 3-5 junctions, H = 2-4, the default and
random driver models, a belief atom near its prior value), against the exact-rational brute force of
threshold_cases.py, with no tolerance:

- `belief_rule="paper"`: L <= the authors' belief MDP's exact optimum <= U (the paper update in
  exact arithmetic, whose belief also gives the observation probabilities), and L at most the
  returned policy's exact value in that MDP;
- `evaluate` (trustroute.app.synthesis: `evaluate_single`, `evaluate_population`) of the returned
  policy, under either rule: its certified [lower, upper] brackets the policy's exact value in the
  real process (the true driver's Bayes posterior gives the probabilities, the AV's rule the labels
  and the decisions), and with a population every per-type value brackets that type's;
- a population under the authors' rule: L <= the lifted authors' belief MDP's exact optimum <= U,
  and every per-type value (the AV on the authors' rule, the type's Bayes posterior driving)
  brackets that type's exact value.
"""

from __future__ import annotations

import functools
from fractions import Fraction

import pytest

from tests.policies.synthesis.test_rounding_population import population_case, type_exact_values
from tests.policies.synthesis.threshold_cases import exact_value, small_case, sweep
from trustroute.app.synthesis import evaluate_population, evaluate_single
from trustroute.policies.belief.problem import problem, problem_of
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.population import synthesize_population
from trustroute.policies.synthesis.settings import SynthesisSettings

SEEDS = sweep(40, fast=(1, 2, 3, 4))
POPULATION_SEEDS = sweep(12, fast=(1,))


@pytest.fixture(scope="module")
def paper_outcome(driver):
    @functools.cache
    def run(seed: int):
        pomdp, spec, horizon = small_case(seed, driver, eventful=True)
        result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0,
                                                           belief_rule="paper"))
        return pomdp, spec, horizon, result

    return run


@pytest.mark.parametrize("seed", SEEDS)
def test_paper_rule_bounds_contain_the_exact_optimum_of_the_authors_belief_mdp(paper_outcome, seed):
    pomdp, spec, horizon, result = paper_outcome(seed)
    optimum = exact_value(pomdp, spec, horizon, rule="paper")
    policy_value = exact_value(pomdp, spec, horizon, policy=result.policy, rule="paper")
    assert 0.0 <= result.lower <= result.upper <= 1.0
    assert Fraction(result.lower) <= optimum <= Fraction(result.upper), (seed, result.lower, optimum,
                                                                         result.upper)
    assert Fraction(result.lower) <= policy_value, (seed, result.lower, policy_value)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("rule", ["bayes", "paper"])
def test_evaluate_brackets_the_exact_value_of_the_policy(driver, paper_outcome, seed, rule):
    pomdp, spec, horizon, result = paper_outcome(seed)
    if rule == "bayes":
        result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0))
    value = evaluate_single(problem_of(pomdp, spec), result.policy,
                            EvaluationSettings(fallback_after=None, max_junctions=horizon, belief_rule=rule))
    exact = exact_value(pomdp, spec, horizon, policy=result.policy, rule=rule,
                        truth=pomdp if rule == "paper" else None)
    assert Fraction(value.lower) <= exact <= Fraction(value.upper), (seed, rule, value.lower, exact,
                                                                     value.upper)


@pytest.mark.parametrize("seed", POPULATION_SEEDS)
def test_paper_rule_population_bounds_and_per_type_values_hold_exactly(driver, seed):
    town, population, spec, horizon = population_case(seed, driver)
    found = synthesize_population(town, population, spec, "bayes",
                                  SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0,
                                                    belief_rule="paper"))
    optimum = exact_value(found.pomdp, found.spec, horizon, rule="paper")
    assert Fraction(found.lower) <= optimum <= Fraction(found.upper), (seed, found.lower, optimum,
                                                                       found.upper)
    exact = type_exact_values(town, found, horizon, rule="paper")
    for reported, truth in zip(found.type_values, exact, strict=True):
        assert Fraction(reported.lower) <= truth <= Fraction(reported.upper), (seed, reported, truth)


@pytest.mark.parametrize("seed", POPULATION_SEEDS)
def test_evaluate_of_a_population_brackets_the_exact_values(driver, seed):
    town, population, spec, horizon = population_case(seed, driver)
    found = synthesize_population(town, population, spec, "bayes",
                                  SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0))
    value, per_type = evaluate_population(problem(town, population, spec), found.result.policy,
                                          EvaluationSettings(fallback_after=None, max_junctions=horizon))
    exact = exact_value(found.pomdp, found.spec, horizon, policy=found.result.policy)
    assert Fraction(value.lower) <= exact <= Fraction(value.upper), (seed, value.lower, exact, value.upper)
    for reported, truth in zip(per_type, type_exact_values(town, found, horizon), strict=True):
        assert Fraction(reported.lower) <= truth <= Fraction(reported.upper), (seed, reported, truth)
