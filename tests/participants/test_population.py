"""Populations: infinite concentration is the nominal model exactly; finite concentration gives
valid models whose mean approaches the nominal one; the [population] table loader."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from tests.policies.model.test_trust_pomdp import random_model
from trustroute.core.errors import InputError
from trustroute.participants.driver_model import driver_model_from_dict
from trustroute.participants.population import (
    PopulationConfig,
    population_config_from_dict,
    sample_population,
)


def test_infinite_concentration_is_the_nominal_model(driver):
    population = sample_population(driver, 5, PopulationConfig(), np.random.default_rng(0))
    assert len(population) == 5
    for individual in population:
        for name in ("takeover_probability", "failure_probability", "trust_transition",
                     "initial_belief"):
            assert np.array_equal(getattr(individual, name), getattr(driver, name)), name
        assert individual.content_hash == driver.content_hash


def test_infinite_concentration_draws_nothing(driver):
    rng = np.random.default_rng(3)
    sample_population(driver, 10, PopulationConfig(), rng)
    assert rng.random() == np.random.default_rng(3).random()


def test_individuals_are_valid_models_with_the_nominal_support(driver):
    config = PopulationConfig(concentration=5.0, takeover_spread=0.7)
    for individual in sample_population(driver, 20, config, np.random.default_rng(1)):
        again = driver_model_from_dict(individual.to_dict(), "<individual>")     # passes the validator
        assert again.content_hash == individual.content_hash
        assert np.array_equal(individual.trust_transition > 0,
                              (driver.trust_transition > 0) & (individual.trust_transition > 0))
        assert not individual.depends_on_performance
        assert np.array_equal(individual.trust_transition[:, :, 0], individual.trust_transition[:, :, 1])
        assert individual.content_hash != driver.content_hash


def test_zeros_in_a_row_stay_zero(town):
    model = random_model(np.random.default_rng(4), 7, performance_dependent=True, sparse=True)
    assert (model.trust_transition == 0).any()
    for individual in sample_population(model, 10, PopulationConfig(concentration=3.0),
                                        np.random.default_rng(2)):
        assert not individual.trust_transition[model.trust_transition == 0].any()
        driver_model_from_dict(individual.to_dict(), "<individual>")
        # performance-dependent rows vary independently
        assert not np.array_equal(individual.trust_transition[:, :, 0], individual.trust_transition[:, :, 1])


@pytest.mark.parametrize("concentration", [20.0, 500.0])
def test_mean_approaches_the_nominal_model(driver, concentration):
    """Each Dirichlet entry has mean p and variance p(1-p)/(c+1): the population mean of K
    individuals lies within 5 standard errors of the nominal row, entry by entry."""
    k = 300
    population = sample_population(driver, k, PopulationConfig(concentration=concentration),
                                   np.random.default_rng(int(concentration)))
    stacked = np.stack([m.trust_transition for m in population])
    p = driver.trust_transition
    standard_error = np.sqrt(p * (1 - p) / ((concentration + 1) * k))
    assert (np.abs(stacked.mean(axis=0) - p) <= 5 * standard_error + 1e-12).all()
    # and the spread of individuals shrinks like 1/sqrt(c + 1)
    spread = stacked.std(axis=0)
    big = (p > 0.1) & (p < 0.9)
    ratio = spread[big] / np.sqrt(p[big] * (1 - p[big]) / (concentration + 1))
    assert 0.8 < np.median(ratio) < 1.2


def test_mean_error_shrinks_with_concentration(driver):
    errors = []
    for concentration in (5.0, 50.0, 5000.0):
        population = sample_population(driver, 100, PopulationConfig(concentration=concentration),
                                       np.random.default_rng(8))
        mean = np.mean([m.trust_transition for m in population], axis=0)
        errors.append(np.abs(mean - driver.trust_transition).max())
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.01


def test_takeover_logit_shift(driver):
    population = sample_population(driver, 400, PopulationConfig(takeover_spread=0.5),
                                   np.random.default_rng(6))
    nominal = driver.takeover_probability
    inner = (nominal > 0) & (nominal < 1)
    shifts = []
    for individual in population:
        p = individual.takeover_probability
        assert np.array_equal(p[~inner], nominal[~inner])                 # 0 (incident 'none') stays
        shift = np.log(p[inner] / (1 - p[inner])) - np.log(nominal[inner] / (1 - nominal[inner]))
        assert np.allclose(shift, shift[0], atol=1e-9)                    # one shift per driver
        shifts.append(shift[0])
        assert np.array_equal(individual.trust_transition, driver.trust_transition)
    assert abs(np.mean(shifts)) < 5 * 0.5 / math.sqrt(400)
    assert 0.45 < np.std(shifts) < 0.55


def test_initial_trust_distribution(driver):
    base = (0.0, 0.1, 0.2, 0.4, 0.2, 0.1, 0.0)
    nominal = sample_population(driver, 2, PopulationConfig(initial_trust=base), np.random.default_rng(0))
    assert all(np.array_equal(m.initial_belief, base) for m in nominal)
    varied = sample_population(driver, 200, PopulationConfig(concentration=30.0, initial_trust=base),
                               np.random.default_rng(0))
    beliefs = np.stack([m.initial_belief for m in varied])
    assert not beliefs[:, [0, 6]].any()
    assert np.allclose(beliefs.sum(axis=1), 1.0)
    assert np.abs(beliefs.mean(axis=0) - base).max() < 0.02
    with pytest.raises(ValueError, match="trust levels"):
        sample_population(driver, 1, PopulationConfig(initial_trust=(0.5, 0.5)), np.random.default_rng(0))


def test_reproducible_from_the_seed(driver):
    config = PopulationConfig(concentration=10.0, takeover_spread=0.3)
    a = sample_population(driver, 4, config, np.random.default_rng(42))
    b = sample_population(driver, 4, config, np.random.default_rng(42))
    assert [m.content_hash for m in a] == [m.content_hash for m in b]
    assert len({m.content_hash for m in a}) == 4


def test_config_rejects_bad_values():
    for kwargs in ({"concentration": 0.0}, {"concentration": float("nan")}, {"takeover_spread": -1.0},
                   {"report_accuracy": 1.2}, {"initial_trust": (0.5, 0.6)}):
        with pytest.raises(ValueError):
            PopulationConfig(**kwargs)


def test_population_table_from_toml():
    data = tomllib.loads("""
        [population]
        concentration = inf
        takeover_spread = 0.25
        report_accuracy = 0.9
        initial_trust = [0.0, 0.0, 0.25, 0.5, 0.25, 0.0, 0.0]
    """)
    config = population_config_from_dict(data["population"], "study.toml", n_trust=7)
    assert config == PopulationConfig(concentration=math.inf, takeover_spread=0.25, report_accuracy=0.9,
                                      initial_trust=(0.0, 0.0, 0.25, 0.5, 0.25, 0.0, 0.0))
    assert population_config_from_dict({}, "study.toml") == PopulationConfig()
    assert population_config_from_dict(None, "study.toml") == PopulationConfig()
    assert population_config_from_dict({"concentration": 50}, "s").concentration == 50.0


@pytest.mark.parametrize("table, place, problem", [
    ({"concentration": 0}, "population.concentration", "not a number > 0"),
    ({"concentration": "high"}, "population.concentration", "not a number > 0"),
    ({"concentration": True}, "population.concentration", "not a number > 0"),
    ({"takeover_spread": -0.1}, "population.takeover_spread", "finite number >= 0"),
    ({"report_accuracy": 1.5}, "population.report_accuracy", "not a probability"),
    ({"initial_trust": [0.5, 0.6, 0, 0, 0, 0, 0]}, "population.initial_trust", "sums to 1.1"),
    ({"initial_trust": "uniform"}, "population.initial_trust", "not a list of probabilities"),
    ({"initial_trust": [0.5, 0.5]}, "population.initial_trust", "has 2 entries"),
    ({"concentraton": 5}, "population.concentraton", "unknown key"),
])
def test_population_table_errors(table, place, problem):
    with pytest.raises(InputError) as error:
        population_config_from_dict(table, "study.toml", n_trust=7)
    assert error.value.source == "study.toml"
    assert error.value.place == place
    assert problem in error.value.problem
    with pytest.raises(InputError):
        population_config_from_dict([1, 2], "study.toml")
