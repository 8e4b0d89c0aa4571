"""Problem: the case of a routing problem, decided once from the driver (or population) and spec."""

from __future__ import annotations

from trustroute.participants.driver_population import (
    EXAMPLE_POPULATION_PATH,
    load_driver_population,
    single_type_population,
)
from trustroute.policies.belief.problem import (
    DRIVER_TYPES,
    PLAIN,
    TRUST_STATE,
    case_of,
    dfa_is_hidden,
    problem,
    problem_of,
)
from trustroute.policies.logic.spec import load_spec


def test_the_cases(town, driver, pomdp):
    phi1, trust = load_spec("specs/phi1.toml", town), load_spec("specs/phi1_trust.toml", town)
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    assert problem(town, driver, phi1).case == PLAIN
    assert problem(town, driver, trust).case == TRUST_STATE
    types = problem(town, population, phi1)
    assert types.case == DRIVER_TYPES and types.population is population and types.given_spec is phi1
    assert types.driver.n_trust == 7 * population.n_types and types.pomdp.driver is types.driver
    hidden_types = problem(town, population, trust)
    assert hidden_types.case == TRUST_STATE and hidden_types.dfa_hidden
    assert case_of(types.driver, types.spec) == DRIVER_TYPES
    assert not dfa_is_hidden(driver, phi1) and dfa_is_hidden(hidden_types.driver, hidden_types.spec)


def test_one_type_is_the_single_model_problem(town, driver, pomdp):
    phi1 = load_spec("specs/phi1.toml", town)
    alone = problem(town, single_type_population(driver), phi1)
    assert alone.case == PLAIN and alone.driver is driver and alone.spec is phi1
    given = problem_of(pomdp, phi1)
    assert given.pomdp is pomdp and given.case == PLAIN
