"""The brute-force reference: exact optimum over the action/observation tree for small horizons."""

from __future__ import annotations

import pytest

from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.protocol import RoutingPolicy
from trustroute.policies.synthesis.exact_search import exact_optimum


class FixedRoutePolicy(RoutingPolicy):
    """Drive a given route, ignoring beliefs (an open-loop policy)."""

    name = "route"

    def __init__(self, town, route):
        self.town, self.route = town, route

    def next_junction(self, context):
        nxt = self.route[context.junctions_driven + 1]
        return nxt.partition("-")[2]


def routes(town, start, length):
    if length == 0:
        return [[start]]
    return [[start] + rest for nxt in town.successors(start) for rest in routes(town, nxt, length - 1)]


@pytest.mark.slow
def test_exact_optimum_dominates_every_open_loop_route_and_grows_with_the_horizon(pomdp, packaged_optimum):
    town = pomdp.town
    spec = load_spec("specs/phi1.toml", town)
    horizon = 7
    optimum = packaged_optimum("phi1", horizon)
    best_route = max(evaluate(pomdp, spec, FixedRoutePolicy(town, r),
                              EvaluationSettings(fallback_after=None, max_junctions=horizon)).lower
                     for r in routes(town, spec.start, horizon))
    assert 0.5 < best_route <= optimum + 1e-12
    assert packaged_optimum("phi1", 5) == 0.0  # the task needs 6 junctions
    assert packaged_optimum("phi1", 6) <= optimum <= packaged_optimum("phi1", 8)


def test_horizon_outside_the_exact_range_is_refused(pomdp):
    spec = load_spec("specs/phi1.toml", pomdp.town)
    with pytest.raises(ValueError, match="exact search"):
        exact_optimum(pomdp, spec, 13)
