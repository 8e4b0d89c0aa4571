"""Exact evaluation with a true driver other than the AV's model, and with a reference reading."""

from __future__ import annotations

from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import trust_free_policy


def test_truth_equal_to_the_av_model_and_the_own_reference_change_nothing(town, pomdp):
    spec = load_spec("specs/phi1.toml", town)
    policy = trust_free_policy(town, spec)
    plain = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=20))
    same = evaluate(pomdp, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=20),
                    truth=build_pomdp(town, pomdp.driver), reference=(pomdp, spec))
    assert (same.lower, same.upper, same.expected_final_trust) == (plain.lower, plain.upper,
                                                                    plain.expected_final_trust)
    assert same.reference_accepted == plain.lower
    assert "reference_accepted" not in plain.to_dict()


def test_mixture_value_is_the_weighted_per_type_values(town):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    lifted = build_pomdp(town, lift_population(population))
    spec = lift_spec(load_spec("specs/phi1.toml", town), population)
    policy = trust_free_policy(town, spec)
    mixture = evaluate(lifted, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=12))
    per_type = [evaluate(lifted, spec, policy, EvaluationSettings(fallback_after=None, max_junctions=12),
                         truth=build_pomdp(town, t.model)) for t in population.types]
    weighted = sum(t.weight * v.lower for t, v in zip(population.types, per_type, strict=True))
    assert abs(mixture.lower - weighted) <= 1e-12
    trust = sum(t.weight * v.expected_final_trust for t, v in zip(population.types, per_type, strict=True))
    assert abs(mixture.expected_final_trust - trust) <= 1e-9


def test_a_deadline_cuts_the_open_histories_into_the_bracket(town, pomdp):
    import time

    spec = load_spec("specs/phi1.toml", town)
    policy = trust_free_policy(town, spec)
    settings = EvaluationSettings(fallback_after=None, max_junctions=20)
    exact = evaluate(pomdp, spec, policy, settings)
    assert exact.lower == exact.upper
    assert evaluate(pomdp, spec, policy, settings, deadline=time.perf_counter() + 3600).lower == exact.lower
    cut = evaluate(pomdp, spec, policy, settings, deadline=time.perf_counter())
    assert cut.lower <= exact.lower <= cut.upper and cut.upper - cut.lower > 0.5
    assert cut.end_mass["pruned"] == cut.upper - cut.lower


def test_the_mixture_weighs_the_types_with_weights_summing_to_one(town):
    """Weights a file writes within the tolerance of 1 (here 1 - 5e-10): the mixture's value is
    the per-type values weighed with the weights divided by their sum."""
    import json
    import math

    from trustroute.participants.driver_population import driver_population_from_dict

    data = json.loads(EXAMPLE_POPULATION_PATH.read_text())
    written = (0.4, 0.3, 0.3 - 5e-10)
    for entry, weight in zip(data["types"], written, strict=True):
        entry["weight"] = weight
    population = driver_population_from_dict(data, str(EXAMPLE_POPULATION_PATH))
    lifted = build_pomdp(town, lift_population(population))
    spec = lift_spec(load_spec("specs/phi1.toml", town), population)
    policy = trust_free_policy(town, spec)
    settings = EvaluationSettings(fallback_after=None, max_junctions=12)
    mixture = evaluate(lifted, spec, policy, settings)
    per_type = [evaluate(lifted, spec, policy, settings, truth=build_pomdp(town, t.model))
                for t in population.types]
    total = math.fsum(written)
    weighted = math.fsum(w / total * v.lower for w, v in zip(written, per_type, strict=True))
    assert mixture.lower > 0.1 and abs(mixture.lower - weighted) <= 1e-13
