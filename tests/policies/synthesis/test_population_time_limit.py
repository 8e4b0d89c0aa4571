"""One time limit for a whole population synthesis: every synthesis run of the robust objective
(the Bayes run, the grid's candidates, the per-type bounds) ends by the call's deadline, and each
run is announced with its bounds (on_phase)."""

from __future__ import annotations

import time

import pytest

from trustroute.core.packaged import PACKAGED_SPECS
from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.synthesis import population as population_synthesis
from trustroute.policies.synthesis.population import run_count, synthesize_population
from trustroute.policies.synthesis.settings import SynthesisSettings

# time limits on the wall clock, and what a run does with its share of one
pytestmark = pytest.mark.wallclock


def test_every_run_ends_by_the_one_deadline(town, monkeypatch):
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    spec = load_spec(PACKAGED_SPECS / "phi1.toml", town, population.types[0].model.n_trust)
    real = population_synthesis.synthesize
    calls: list[tuple[float, float]] = []

    def recording(pomdp, spec, settings, **kwargs):
        calls.append((time.perf_counter(), settings.time_limit))
        return real(pomdp, spec, settings, **kwargs)

    monkeypatch.setattr(population_synthesis, "synthesize", recording)
    limit, lines = 4.0, []
    started = time.perf_counter()
    # H = 6: no candidate reaches the robust bound, so every candidate prior runs (about 1.2 s in
    # all); within 5 junctions every value is 0 and the search stops after the Bayes run
    found = synthesize_population(town, population, spec, "robust",
                                  SynthesisSettings(horizon=6, time_limit=limit, grid_points=6),
                                  on_phase=lines.append)
    assert len(calls) == run_count(population, "robust", 6) == len(lines) > population.n_types + 1
    for at, run_limit in calls:
        assert at + run_limit <= started + limit + 1e-3, (at - started, run_limit)
    assert all(line.count("[") >= 2 for line in lines)  # its place, elapsed time and bounds
    assert found.lower <= found.upper
    assert run_count(population, "bayes", 6) == 1


@pytest.mark.slow
def test_the_exact_evaluations_keep_the_deadline_at_h20(town):
    # H = 20 on the lifted three-type model: one exact per-type evaluation of a policy takes about
    # as long as the whole limit: not held to the deadline, they take 4.8 s under a 2 s limit
    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    spec = load_spec(PACKAGED_SPECS / "phi1.toml", town, population.types[0].model.n_trust)
    for objective in ("bayes", "robust"):
        limit = 2.0
        started = time.perf_counter()
        found = synthesize_population(town, population, spec, objective,
                                      SynthesisSettings(horizon=20, time_limit=limit))
        # the command's target: the limit plus 10 %, at least 1 s (docs/synthesis.md, "Time limit")
        assert time.perf_counter() - started <= limit + max(0.1 * limit, 1.0), objective
        assert 0.0 <= found.lower <= found.upper <= 1.0
