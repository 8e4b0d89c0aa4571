"""benchmarks/bench_lookahead.py: the belief-lookahead controller is a policy the exact evaluator
values, and where its lookahead reaches the horizon it is the optimum, so its exact value lies in
the converged synthesis' certified [L, U]."""

from __future__ import annotations

import trustroute
from benchmarks.bench_lookahead import POPULATION, LookaheadPolicy, row
from trustroute.app.inputs import population_of
from trustroute.policies.belief.driver_types import lift_population, lift_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.population import per_type_values

HORIZON = 6


def test_a_lookahead_to_the_horizon_reaches_the_converged_optimum():
    town = trustroute.load_town()
    population = population_of(POPULATION)
    pomdp = build_pomdp(town, lift_population(population))
    spec = lift_spec(trustroute.load_spec("phi1", town), population)
    optimum = trustroute.synthesize("phi1", town, population=population, horizon=HORIZON, tau=1e-9,
                                    time_limit=60)
    assert optimum.gap <= 1e-9
    policy = LookaheadPolicy(pomdp, spec, HORIZON, depth=HORIZON)
    values = per_type_values(pomdp, spec, policy, population, HORIZON)
    found = row("phi1", HORIZON, "lookahead", values, population.weights, 0.0)
    lower, upper = found["bayes"]
    assert optimum.lower - 1e-9 <= lower <= upper <= optimum.upper + 1e-9
    assert lower > 0   # a horizon where the spec can be met: the comparison is not 0 = 0
    # a shallower lookahead is a policy too, never above the optimum
    shallow = per_type_values(pomdp, spec, LookaheadPolicy(pomdp, spec, HORIZON, depth=1), population,
                              HORIZON)
    assert row("phi1", HORIZON, "lookahead", shallow, population.weights, 0.0)["bayes"][0] <= optimum.upper
