"""A routing policy that drives a route given in advance (benchmarks, scene measurements, tests)."""

from __future__ import annotations

from collections.abc import Iterable

from trustroute.networks.road import Road
from trustroute.policies.routing.protocol import RoutingPolicy


class FixedRoute(RoutingPolicy):
    """Drives the given route of directed roads ("U-V"), then declares itself finished."""

    name = "fixed"

    def __init__(self, route: Iterable[str]) -> None:
        self.route = tuple(route)

    def finished(self, context) -> bool:
        return len(context.route) >= len(self.route)

    def next_junction(self, context) -> str:
        return Road.parse(self.route[len(context.route)]).to_junction
