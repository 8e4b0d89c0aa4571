"""A population synthesis on the paper's town with the three packaged types expands the lifted
root and closes the Bayes gap where the lifted search can, within one time limit shared by all
its runs: the Bayes run is given most of the time (a run given less than its fixed costs never
expands its root), the per-type bounds come first with a capped share, and the returned policy's
per-type values are its exact values (checked by Monte Carlo with sampled hidden trust). The
lifted runs take the search's whole share: no cluster policies after it (cluster mode "early")."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.policies.synthesis.test_population_synthesis import monte_carlo
from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.participants.driver_population import (
    EXAMPLE_POPULATION_PATH,
    DriverPopulation,
    DriverType,
    load_driver_population,
)
from trustroute.policies.belief.driver_types import lift_population
from trustroute.policies.belief.product_mdp import build_product
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.decision_tables import fallback_only
from trustroute.policies.synthesis import population as population_synthesis
from trustroute.policies.synthesis.belief_cells import observation_symbols, reachable_states, suffix_cells
from trustroute.policies.synthesis.belief_synthesis import cluster_order
from trustroute.policies.synthesis.budget import RunSchedule, TimeBudget
from trustroute.policies.synthesis.population import (
    BAYES_SHARE,
    MAX_GRID_CANDIDATES,
    run_count,
    synthesize_population,
)
from trustroute.policies.synthesis.settings import SynthesisSettings


@pytest.fixture(scope="module")
def three_types():
    return load_driver_population(EXAMPLE_POPULATION_PATH)


@pytest.mark.wallclock   # the shares of a wall-clock time limit
def test_the_bayes_run_gets_most_of_the_robust_limit(town, three_types, monkeypatch):
    # With an equal share for each of the 19 runs (the Bayes run, 15 grid priors, 3 per-type
    # bounds) the lifted Bayes run got a twentieth of the limit, less than its fixed costs at H = 20.
    spec = load_spec(PACKAGED_SPECS / "phi1.toml", town, three_types.types[0].model.n_trust)
    real = population_synthesis.synthesize
    calls: list[tuple[int, float, float]] = []   # (hidden states, start, limit)
    modes: dict[int, set[str]] = {7: set(), 21: set()}

    def recording(pomdp, spec, settings, **kwargs):
        calls.append((pomdp.n_trust, time.perf_counter(), settings.time_limit))
        modes[pomdp.n_trust].add(settings.clusters)
        return real(pomdp, spec, settings, **kwargs)

    monkeypatch.setattr(population_synthesis, "synthesize", recording)
    limit = 6.0
    started = time.perf_counter()
    found = synthesize_population(town, three_types, spec, "robust",
                                  SynthesisSettings(horizon=3, time_limit=limit))
    lifted = [(at, run_limit) for n, at, run_limit in calls if n == 21]
    bounds = [(at, run_limit) for n, at, run_limit in calls if n == 7]
    assert len(bounds) == three_types.n_types
    assert max(at for at, _ in bounds) < lifted[0][0]          # the per-type bounds come first
    bayes_at, bayes_limit = lifted[0]
    left = started + limit - bayes_at
    # half of the time left, less the (small) gaps measured between the bound runs, set aside
    # for the runs to come: at least 0.8 of it (an equal share was a nineteenth)
    assert bayes_limit >= 0.8 * BAYES_SHARE * left, (bayes_limit, left)
    for _, at, run_limit in calls:
        assert at + run_limit <= started + limit + 1e-3
    assert found.lower <= found.upper
    # no cluster policies after an unconverged lifted search (they took half of its time)
    assert modes == {7: {"auto"}, 21: {"early"}}


def test_the_lifted_abstraction_spans_the_reachable_face(town, three_types, pomdp):
    # `flat` starts at trust 4 and never moves: its other six corners are no belief's support,
    # and "flat at trust 7" (a fixed point of every update, reading hightrust) is no cell's vertex.
    lifted = build_pomdp(town, lift_population(three_types))
    symbols = observation_symbols(lifted)
    reached = reachable_states(symbols).reshape(3, 7)
    assert reached[0].all() and reached[2].all()
    assert reached[1].tolist() == [False, False, False, True, False, False, False]
    cells = suffix_cells(symbols, 2)
    absent = np.flatnonzero(~reachable_states(symbols))
    assert (cells.vertices[:, absent, :] == 0).all()
    # one driver with the uniform prior: the whole simplex, as before
    assert (suffix_cells(observation_symbols(pomdp), 1).vertices[0] == np.eye(pomdp.n_trust)).all()


def test_robust_synthesis_expands_the_root_and_closes_the_bayes_gap(town, three_types):
    # H = 6: the lifted Bayes search converges in about 1 s of CPU; with 19 equal shares of 14 s
    # it was never given that and returned only its fallback ([0, 1], 0 rows).
    spec = load_spec(PACKAGED_SPECS / "phi1.toml", town, three_types.types[0].model.n_trust)
    horizon = 6
    found = synthesize_population(town, three_types, spec, "robust",
                                  SynthesisSettings(horizon=horizon, time_limit=14.0))
    assert found.bayes_policy is not None and fallback_only(found.bayes_policy) is None
    assert found.bayes_upper - found.bayes_lower <= 1e-3
    # L of a converged Bayes search with exact completion trees is its policy's exact value: the
    # per-type exact evaluations, weighted by the prior, give it back
    weights = three_types.weights
    bayes_mixture = float(weights @ [v.lower for v in found.bayes_type_values])
    assert bayes_mixture == pytest.approx(found.bayes_lower, abs=1e-9)
    assert all(v.upper - v.lower <= 1e-9 for v in found.type_values)          # exact, not cut
    assert found.lower == min(v.lower for v in found.type_values)
    assert found.lower >= min(v.lower for v in found.bayes_type_values)
    assert found.lower <= found.upper <= found.bayes_upper
    rng = np.random.default_rng(5)
    for j, value in enumerate(found.type_values):
        sampled = monte_carlo(found, town, horizon, rng, 300, j)
        se = max(sampled.std(ddof=1) / np.sqrt(sampled.size), 1e-3)
        assert abs(sampled.mean() - value.lower) <= 4 * se, (value.name, sampled.mean(), value.lower)


def test_early_cluster_mode_never_follows_the_search(pomdp):
    # "auto" solves cluster policies after a search that ends with a gap on a problem whose free
    # route's tree is small; "early" does not, and keeps "auto"'s choice before the search.
    tables = build_product(pomdp, load_spec(PACKAGED_SPECS / "phi1.toml", pomdp.town, pomdp.n_trust))
    symbols = observation_symbols(pomdp)
    assert cluster_order(tables, symbols, 20, "auto", "auto") == "after"
    assert cluster_order(tables, symbols, 20, "auto", "early") == "never"
    assert cluster_order(tables, symbols, 20, "auto", "on") == "first"


def test_a_candidate_gets_its_fixed_costs_after_costly_evaluations():
    # taking off first the evaluations predicted for every run to come would leave, after one
    # evaluation of 7 s with 15 runs to come, a run the floor of 0.05 s, never expanding
    schedule = RunSchedule(TimeBudget.start(30.0), runs=19, done=4, between=7.0, gaps=1)
    assert schedule.affords(0, 4.0)
    assert schedule.next_limit(at_least=4.0) >= 4.0
    assert schedule.next_limit(at_least=40.0) <= 30.0 - 7.0        # its own evaluation still fits


def test_the_robust_search_stops_once_its_best_candidate_reaches_the_bound(town, driver):
    # Two copies of one type: the Bayes policy serves both alike, so its worst type is its value,
    # which the Bayes bound U certifies optimal within tau: no candidate prior can do better, and
    # none is run (without that stop, all 16 would run, each a synthesis of its own).
    twins = DriverPopulation(types=(DriverType("one", 0.5, driver), DriverType("two", 0.5, driver)))
    spec = load_spec(PACKAGED_SPECS / "phi1.toml", town, driver.n_trust)
    phases: list[str] = []
    found = synthesize_population(town, twins, spec, "robust",
                                  SynthesisSettings(horizon=6, time_limit=60, work_limit=1_000_000),
                                  on_phase=phases.append)
    grid = run_count(twins, "robust", MAX_GRID_CANDIDATES) - 1 - twins.n_types
    assert found.candidates_not_needed == grid == 16
    assert [c["prior"] for c in found.candidates] == [[0.5, 0.5], None]   # the Bayes policy, the free one
    assert found.gap <= 1e-3 and found.lower == pytest.approx(found.bayes_lower, abs=1e-12)
    assert sum("candidate priors are not run" in line for line in phases) == 1
    assert not any(line.startswith("[") and "candidate prior [" in line for line in phases)
