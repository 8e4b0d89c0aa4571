"""Every evaluation a benchmark reports is the certified one (policies/synthesis/rounding.py): the
bounds `trustroute evaluate`, `trustroute baseline` and a population synthesis report for the same
policy and settings, rounded outward from the values the unfolding computes, never those values
themselves. Each check also asserts that the rounding moved the computed bounds, so that it tells
the two apart."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import bench_city, bench_policies, bench_population, bench_synthesis
from tests.cli import run_cli
from trustroute import evaluate as api_evaluate
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.fallback import DEFAULT_FALLBACK_AFTER
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.synthesis.population import mixture_lower, mixture_upper, per_type_values


def evaluated(capsys, *arguments: str) -> dict:
    code, out, _ = run_cli(capsys, *arguments, "--json")
    assert code == 0
    return json.loads(out)


def assert_moved_outward(certified: tuple[float, float], computed: tuple[float, float]) -> None:
    assert certified[0] < computed[0] <= computed[1] < certified[1]


def test_the_trust_free_value_of_bench_policies_is_the_one_evaluate_reports(capsys, pomdp):
    row = bench_policies.trust_free_rows(pomdp, "phi1", episodes=20)[0]
    reported = evaluated(capsys, "evaluate", "specs/phi1.toml", "free")
    assert (row["value"], row["upper"]) == (reported["lower"], reported["upper"])
    spec = load_spec("specs/phi1.toml", pomdp.town)
    computed = evaluate(pomdp, spec, trust_free_policy(pomdp.town, spec))
    assert_moved_outward((row["value"], row["upper"]), (computed.lower, computed.upper))


@pytest.mark.parametrize("rule", ["bayes", "paper"])
def test_the_study_value_of_bench_synthesis_is_the_one_evaluate_reports(pomdp, rule):
    spec = load_spec("specs/phi2.toml", pomdp.town)
    policy = bench_policies._FixedRandomPolicy(pomdp.town, np.random.default_rng(3))
    row = bench_synthesis.with_fallback(pomdp, spec, policy, rule)
    settings = EvaluationSettings(fallback_after=DEFAULT_FALLBACK_AFTER, belief_rule=rule)
    computed = evaluate(pomdp, spec, policy, settings)
    reported = api_evaluate("specs/phi2.toml", policy, settings=settings)
    assert (row["with_fallback20_lower"], row["with_fallback20_upper"]) == (reported.lower, reported.upper)
    assert_moved_outward((row["with_fallback20_lower"], row["with_fallback20_upper"]),
                         (computed.lower, computed.upper))


def test_the_trust_free_baseline_of_bench_city_is_the_one_baseline_reports(capsys, pomdp):
    row = bench_city.baseline_row("paper", "phi1", "town01_carla")
    reported = evaluated(capsys, "baseline", "phi1")
    assert (row["value"], row["upper"]) == (reported["lower"], reported["upper"])
    assert (row["route_junctions"], row["route_m"]) == (len(reported["route"]) - 1, reported["length_m"])
    spec = load_spec("phi1", pomdp.town)
    computed = evaluate(pomdp, spec, trust_free_policy(pomdp.town, spec),
                        EvaluationSettings(fallback_after=None))
    assert_moved_outward((row["value"], row["upper"]), (computed.lower, computed.upper))


def test_the_per_type_values_of_bench_population_are_the_ones_a_population_synthesis_reports(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    free = trust_free_policy(pomdp.town, spec)
    row = bench_population.row_values(pomdp, spec, free, population, spec)
    certified = per_type_values(pomdp, spec, free, population, bench_population.HORIZON)
    assert [(row["per_type"][v.name]["lower"], row["per_type"][v.name]["upper"]) for v in certified] == \
        [(v.lower, v.upper) for v in certified]
    assert (row["lower"], row["upper"]) == (mixture_lower(population.weights, certified),
                                            mixture_upper(population.weights, certified))
    first = population.types[0]
    computed = evaluate(pomdp, spec, free, EvaluationSettings(fallback_after=None,
                                                              max_junctions=bench_population.HORIZON),
                        truth=build_pomdp(pomdp.town, first.model))
    assert_moved_outward((row["per_type"][first.name]["lower"], row["per_type"][first.name]["upper"]),
                         (computed.lower, computed.upper))
