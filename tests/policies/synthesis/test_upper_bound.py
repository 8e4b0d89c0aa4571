"""The vectorised abstract Bellman backup equals the operator written out road by road: on the
paper's town, on the type-aware model of three driver types (whose cells have corners that no
belief reaches, and whose quiet roads read one symbol), and on random towns whose roads have
different numbers of successors."""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_spec, random_town
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.belief.product_mdp import build_product
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.belief_cells import observation_symbols, suffix_cells
from trustroute.policies.synthesis.upper_bound import Abstraction, abstract_backup, build_abstraction


def backup_by_road(abstraction: Abstraction, value_next: np.ndarray) -> np.ndarray:
    """T̄ value_next from its definition: per road x, per successor x2, per symbol, per label value."""
    tables, symbols, cells = abstraction.tables, abstraction.symbols, abstraction.cells
    n_x, n_q, n_c = value_next.shape
    out = np.zeros_like(value_next)
    out[:, tables.accepting, :] = 1.0
    for x in range(n_x):
        for q in np.flatnonzero(~(tables.accepting | tables.rejecting)):
            for c in range(n_c):
                best = 0.0
                for x2 in tables.successors[x]:
                    if x2 < 0:
                        continue
                    incident = int(tables.pomdp.road_incident[x2])
                    per_vertex = np.zeros(cells.vertices.shape[1])
                    for o in symbols.by_incident[incident]:
                        c2 = cells.next_cell[c, o]
                        value = max((value_next[x2, tables.next_q[q, x2, bits], c2]
                                     for bits in range(abstraction.possible_bits.shape[2])
                                     if abstraction.possible_bits[c, o, bits]), default=0.0)
                        per_vertex += value * (cells.vertices[c] @ symbols.likelihood[o])
                    best = max(best, float(per_vertex.max()))
                out[x, q, c] = min(best, 1.0)
    return out


@pytest.mark.parametrize("name", ["phi1", "phi1_strict", "phi2_strict"])
def test_vectorised_backup_matches_definition(pomdp, town, name):
    tables = build_product(pomdp, load_spec(f"specs/{name}.toml", town))
    symbols = observation_symbols(pomdp)
    abstraction = build_abstraction(tables, symbols, suffix_cells(symbols, 1))
    rng = np.random.default_rng(7)
    value_next = rng.uniform(size=(tables.n_x, tables.n_q, abstraction.cells.n_cells))
    expected = backup_by_road(abstraction, value_next)
    got = abstract_backup(abstraction, value_next)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


def backup_agrees(tables, pomdp, k: int, seed: int) -> None:
    symbols = observation_symbols(pomdp)
    abstraction = build_abstraction(tables, symbols, suffix_cells(symbols, k))
    value_next = np.random.default_rng(seed).uniform(size=(tables.n_x, tables.n_q, abstraction.cells.n_cells))
    expected = backup_by_road(abstraction, value_next)
    np.testing.assert_allclose(abstract_backup(abstraction, value_next), expected, rtol=1e-12, atol=1e-12)


def test_vectorised_backup_matches_definition_with_three_driver_types(town):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    pomdp = build_pomdp(town, lift_population(population))
    spec = lift_spec(load_spec("specs/phi1.toml", town), population)
    symbols = observation_symbols(pomdp)
    assert any(len(members) == 1 for members in symbols.by_incident)
    assert (suffix_cells(symbols, 1).vertices.sum(axis=-1) == 0).any()   # corners no belief reaches
    backup_agrees(build_product(pomdp, spec), pomdp, 1, 8)


# towns (seeds from 9100) where some road has fewer successors than another
@pytest.mark.parametrize("seed", [1, 2, 6, 8])
def test_vectorised_backup_matches_definition_on_random_towns(driver, seed):
    rng = np.random.default_rng(9100 + seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    tables = build_product(pomdp, random_spec(rng, town, pomdp.initial_belief))
    assert (tables.successors < 0).any()
    backup_agrees(tables, pomdp, 2, seed)
