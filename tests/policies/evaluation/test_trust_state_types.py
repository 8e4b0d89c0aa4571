"""Specs that test the hidden trust with a population of several driver types: the joint belief
over ((type, trust), DFA state) against brute force over trust paths of every type."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.trust_paths import policy_value, policy_value_by_type
from tests.policies.trust_specs import random_problem
from trustroute.participants.driver_population import DriverPopulation, DriverType
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.belief.problem import TRUST_STATE, problem
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import evaluate_joint, evaluate_joint_by_type
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.routing.protocol import RoutingPolicy


class TypeReadingPolicy(RoutingPolicy):
    """A fixed random map (road, P(first type) >= 1/2, told DFA state) -> next junction: it reads
    the AV's type-aware belief and the state it is told."""

    name = "type-reading"

    def __init__(self, town, rng, n_trust):
        self.town, self.n_trust = town, n_trust
        self.table = {(road, first, q): town.actions(road)[int(rng.integers(len(town.actions(road))))]
                      for road in town.states for first in (False, True) for q in range(16)}

    def next_junction(self, context):
        first = bool(context.belief[:self.n_trust].sum() >= 0.5)
        return self.table[(context.road, first, int(context.dfa_state) % 16)]


def two_type_problem(rng, driver):
    pomdp, spec = random_problem(rng, driver, "trust")
    other = random_driver(rng, pomdp.driver.incident_types)
    weight = float(rng.uniform(0.2, 0.8))
    population = DriverPopulation(types=(DriverType("first", weight, pomdp.driver),
                                         DriverType("second", 1.0 - weight, other)))
    return pomdp.town, population, spec


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), cap=st.integers(2, 3))
def test_mixture_and_per_type_values_equal_brute_force_over_trust_paths(driver, seed, cap):
    rng = np.random.default_rng(seed)
    town, population, spec = two_type_problem(rng, driver)
    found = problem(town, population, spec)
    assert found.case == TRUST_STATE
    lifted, weights = found.pomdp, population.weights
    for policy in (TypeReadingPolicy(town, rng, 7), trust_free_policy(town, found.spec)):
        mixture, per_type = evaluate_joint_by_type(lifted, found.spec, policy,
                                                   EvaluationSettings(fallback_after=None, max_junctions=cap))
        by_type = policy_value_by_type(lifted, found.spec, policy, cap, 2)
        assert mixture.gap == 0.0
        assert mixture.lower == pytest.approx(policy_value(lifted, found.spec, policy, cap), abs=1e-10)
        assert mixture.lower == pytest.approx(float(by_type.sum()), abs=1e-10)
        for (lower, upper), mass, weight in zip(per_type, by_type, weights, strict=True):
            assert lower == upper
            assert lower == pytest.approx(mass / weight, abs=1e-10)
        assert sum(w * v[0] for w, v in zip(weights, per_type, strict=True)) == pytest.approx(
            mixture.lower, abs=1e-10)
    # The trust-free route does not read the belief: type k's value is that of type k's own model.
    for (lower, _), kind in zip(per_type, population.types, strict=True):
        alone = policy_value(build_pomdp(town, kind.model), spec, trust_free_policy(town, spec), cap)
        assert lower == pytest.approx(alone, abs=1e-10)


@pytest.mark.slow
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_pruned_per_type_brackets_hold_the_brute_force_values(driver, seed):
    rng = np.random.default_rng(seed)
    town, population, spec = two_type_problem(rng, driver)
    lifted, lifted_spec = build_pomdp(town, lift_population(population)), lift_spec(spec, population)
    policy = TypeReadingPolicy(town, rng, 7)
    by_type = policy_value_by_type(lifted, lifted_spec, policy, 4, 2) / population.weights
    for options in ({"max_nodes": 3}, {"prune_below": 1e-3}, {"max_nodes": 1, "merge": False}):
        mixture, per_type = evaluate_joint_by_type(lifted, lifted_spec, policy,
                                                   EvaluationSettings(fallback_after=None, max_junctions=4,
                                                                      **options))
        for (lower, upper), exact in zip(per_type, by_type, strict=True):
            assert lower - 1e-10 <= exact <= upper + 1e-10
        assert mixture.lower - 1e-10 <= float(by_type @ population.weights) <= mixture.upper + 1e-10


def test_one_type_is_the_single_model_evaluation(pomdp):
    from trustroute.policies.logic.spec import load_spec

    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    population = DriverPopulation(types=(DriverType("only", 1.0, pomdp.driver),))
    assert lift_spec(spec, population) is spec
    policy = trust_free_policy(pomdp.town, spec)
    alone = evaluate_joint(pomdp, spec, policy, EvaluationSettings(max_junctions=12))
    mixture, per_type = evaluate_joint_by_type(pomdp, spec, policy, EvaluationSettings(max_junctions=12))
    assert mixture.to_dict() | {"seconds": 0} == alone.to_dict() | {"seconds": 0}
    # the same masses summed per type (another order): equal up to rounding
    assert per_type[0] == pytest.approx((alone.lower, alone.upper), abs=1e-12)
    assert len(per_type) == 1
