"""Population synthesis for specs that test the hidden trust, against brute force over the trust
paths of every type, Storm, and its policy file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.trust_paths import optimum, policy_value_by_type, robust_optimum
from tests.policies.trust_specs import random_problem
from trustroute.participants.driver_population import DriverPopulation, DriverType
from trustroute.policies.belief.problem import TRUST_STATE, problem
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.evaluation.trust_state import evaluate_joint_by_type
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.files import load_population_policy, save_policy
from trustroute.policies.routing.trust_state_table import JointTablePolicy
from trustroute.policies.synthesis.population import document_entries, policy_name, reweighting
from trustroute.policies.synthesis.rounding import joint_rounding, relative_margin, widen
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesize_spec import synthesize_for_population
from trustroute.policies.trust_state_synthesis.population import belief_free_spec

TOLERANCE = 1e-9


def random_population_problem(rng, driver, n_types: int, kind: str = "trust"):
    """(town, population of `n_types` random driver types with random weights, spec) on a random
    small town; the spec's atoms as `random_problem`'s `kind`."""
    pomdp, spec = random_problem(rng, driver, kind)
    models = [pomdp.driver] + [random_driver(rng, pomdp.driver.incident_types) for _ in range(n_types - 1)]
    weights = rng.dirichlet(np.ones(n_types)) * 0.7 + 0.3 / n_types
    weights[-1] = 1.0 - float(weights[:-1].sum())
    population = DriverPopulation(types=tuple(DriverType(f"type{k}", float(w), m)
                                              for k, (w, m) in enumerate(zip(weights, models, strict=True))))
    return pomdp.town, population, spec


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n_types=st.integers(2, 3), kind=st.sampled_from(["trust", "mixed"]),
       horizon=st.integers(2, 4))
def test_bayes_bounds_bracket_the_brute_force_population_optimum(driver, seed, n_types, kind, horizon):
    rng = np.random.default_rng(seed)
    town, population, spec = random_population_problem(rng, driver, n_types, kind)
    found = problem(town, population, spec)
    assert found.case == TRUST_STATE
    made = synthesize_for_population(town, population, spec, "bayes",
                                     SynthesisSettings(horizon=horizon, time_limit=20))
    # The brute-force optimum over every history-dependent policy, path by path of every type.
    reference = optimum(found.pomdp, found.spec, horizon)
    assert made.lower - TOLERANCE <= reference <= made.upper + TOLERANCE
    assert isinstance(made.result.policy, JointTablePolicy)
    # The returned policy's value by brute force, per type (its type block of the paths).
    by_type = policy_value_by_type(found.pomdp, found.spec, made.result.policy, horizon, n_types)
    assert float(by_type.sum()) >= made.lower - TOLERANCE
    assert float(by_type.sum()) <= reference + TOLERANCE
    for value, mass, weight in zip(made.type_values, by_type, population.weights, strict=True):
        assert value.lower - TOLERANCE <= mass / weight <= value.upper + TOLERANCE
    mixture = made.mixture_value
    assert mixture[0] - TOLERANCE <= float(by_type.sum()) <= mixture[1] + TOLERANCE


@pytest.mark.slow
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), n_types=st.integers(2, 3), kind=st.sampled_from(["trust", "mixed"]),
       horizon=st.integers(2, 3))
def test_robust_bounds_bracket_the_brute_force_worst_type_optimum(driver, seed, n_types, kind, horizon):
    rng = np.random.default_rng(seed)
    town, population, spec = random_population_problem(rng, driver, n_types, kind)
    found = problem(town, population, spec)
    made = synthesize_for_population(town, population, spec, "robust",
                                     SynthesisSettings(horizon=horizon, time_limit=20))
    reference = robust_optimum(found.pomdp, found.spec, horizon, population.weights)
    assert made.lower - TOLERANCE <= reference <= made.upper + TOLERANCE
    by_type = policy_value_by_type(found.pomdp, found.spec, made.result.policy, horizon, n_types)
    assert float((by_type / population.weights).min()) >= made.lower - TOLERANCE
    # U_k bounds type k's own optimum, of the spec without its belief literals.
    own = belief_free_spec(spec)
    for bound, kind_ in zip(made.type_upper, population.types, strict=True):
        assert optimum(build_pomdp(town, kind_.model), own, horizon) <= bound + TOLERANCE


def test_belief_free_spec_keeps_road_and_trust_atoms_and_drops_belief_literals(town):
    spec = load_spec("specs/phi1_trust.toml", town)
    projected = belief_free_spec(spec)
    assert projected.belief_atoms == {} and projected.trust_atoms == spec.trust_atoms
    assert projected.state_atoms == spec.state_atoms
    assert "lowtrust" not in projected.formula_text and "trusting" in projected.formula_text
    assert belief_free_spec(projected) is projected


@pytest.mark.slow
@pytest.mark.parametrize("objective", ["bayes", "robust"])
def test_population_joint_policy_file_round_trips(tmp_path, driver, objective):
    rng = np.random.default_rng(3)
    town, population, spec = random_population_problem(rng, driver, 3)
    made = synthesize_for_population(town, population, spec, objective,
                                     SynthesisSettings(horizon=3, time_limit=10))
    path = save_policy(made.result, tmp_path / "policy.json", town, made.pomdp.driver, made.spec,
                       population=document_entries(made), name=policy_name(made))
    document = json.loads(path.read_text())
    assert document["kind"] == "joint-belief" and document["objective"] == objective
    assert document["population_hash"] == population.content_hash
    assert document["belief_prior"] == list(made.prior)
    loaded, model, lifted_spec = load_population_policy(path, town, population, spec)
    assert isinstance(loaded, JointTablePolicy)
    assert model.content_hash == made.pomdp.driver.content_hash
    assert (loaded.reweight is None) == (made.result.policy.reweight is None)
    if objective == "robust":   # here a grid prior beats the Bayes policy's worst type
        assert loaded.reweight is not None and document["belief_prior"] != document["population_weights"]
        assert made.lower > min(v.lower for v in made.bayes_type_values)
    _, again = evaluate_joint_by_type(made.pomdp, lifted_spec, loaded,
                                      EvaluationSettings(fallback_after=None, max_junctions=3))
    _, first = evaluate_joint_by_type(made.pomdp, made.spec, made.result.policy,
                                      EvaluationSettings(fallback_after=None, max_junctions=3))
    assert again == first
    # the certified type values are those evaluations rounded outward (policies/synthesis/rounding.py)
    rounding = joint_rounding(made.pomdp, compile_spec(made.spec, made.pomdp.town).dfa.n_states)
    margin = relative_margin(rounding, 3, "bayes")
    certified = [(v.lower, v.upper) for v in made.type_values]
    assert [widen(lower, upper, margin) for lower, upper in first] == certified


def test_reweighting_a_joint_policy_is_the_posterior_under_the_other_prior(driver):
    rng = np.random.default_rng(4)
    town, population, spec = random_population_problem(rng, driver, 2)
    prior = np.array([0.9, 0.1])
    other = problem(town, population, spec)
    made = synthesize_for_population(town, population, spec, "bayes",
                                     SynthesisSettings(horizon=2, time_limit=5))
    policy = JointTablePolicy(made.result.policy.table, other.pomdp, other.spec,
                              made.result.policy.guide_horizon, reweight=reweighting(population, prior))
    joint = rng.dirichlet(np.ones(14 * 3)).reshape(1, 14, 3)
    beliefs = joint.sum(axis=2)
    weighted_joint, weighted = policy.reweighted(joint, beliefs)
    r = np.repeat(prior / population.weights, 7)
    assert np.allclose(weighted, beliefs * r / (beliefs * r).sum())
    assert np.allclose(weighted_joint, joint * r[None, :, None] / (joint * r[None, :, None]).sum())
    assert np.allclose(weighted_joint.sum(axis=2), weighted)


def test_three_type_population_on_phi1_trust_routes_to_the_trust_state_search(town):
    from trustroute.participants.driver_population import load_driver_population

    population = load_driver_population("participants/data/driver_population_three_types.json")
    spec = load_spec("specs/phi1_trust.toml", town)
    made = synthesize_for_population(town, population, spec, "bayes",
                                     SynthesisSettings(horizon=5, time_limit=10))
    assert isinstance(made.result.policy, JointTablePolicy)
    assert made.lower <= made.upper
    assert [v.name for v in made.type_values] == list(population.names)
