"""The routing-policy interface every route chooser implements.

A policy is asked at each road, before the vehicle commits to a lane, for the next
junction. It sees only what the AV knows online: the roads driven so far, the
spec's DFA state after the current position, and the AV's Bayes belief over trust.
Policies are stateless between calls: everything they need is in the context, so
one policy object can drive many episodes (and processes) at once. The rules of an episode
around the policy (when it ends, the fallback) are in policies/routing/episode_rules.py.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True, eq=False)
class DecisionContext:
    """What the AV knows when it must choose the next junction.

    route: directed roads driven so far, the start road first and the current road last.
    dfa_state: state of the spec's DFA after reading the current position.
    belief: the AV's belief over trust levels at the current position (sums to 1).
    joint: for specs with trust-state atoms, the AV's joint belief J [n_trust, n_dfa_states] over
    (trust, DFA state) (policies/belief/trust_state_filter.py; dfa_state is then its most probable
    state); None otherwise.
    """

    route: tuple[str, ...]
    dfa_state: int
    belief: np.ndarray
    joint: np.ndarray | None = None

    @property
    def road(self) -> str:
        return self.route[-1]

    @property
    def junctions_driven(self) -> int:
        return len(self.route) - 1


@dataclass(frozen=True)
class Certificate:
    """What synthesis certified for a policy: lower <= its value <= upper for the objective of
    `horizon` junctions (None: unbounded); lower and upper None where nothing was certified."""

    lower: float | None = None
    upper: float | None = None
    horizon: int | None = None


UNCERTIFIED = Certificate()


@runtime_checkable
class RoutingPolicy(Protocol):
    """A route chooser: a name and the next junction at a DecisionContext.

    Policies subclass this protocol explicitly and inherit the defaults of the optional
    methods, so every caller (episode rules, exact evaluation, the model engine, the fallback,
    the study's expected values) calls them directly:

    - `finished(context)`: the policy declares the episode over here (destination reached);
      default never.
    - `route_determined(context)`: the decision and `finished` here depend on the roads driven
      only (any belief, any non-accepting DFA state), so evaluators may ask once per route;
      default no.
    - `fallback_active(context)`: the 20-junction fallback, not the policy, drives here;
      default no (only the fallback wrapper says yes).
    - `certified_bounds()`: the (lower, upper) synthesis certified for this policy, or None.
    - `route_memory(route)`: what of the roads driven this policy's decisions (`next_junction`,
      `finished`, `fallback_active`) read, now and later, besides the current road, the junctions
      driven, the DFA state told and the beliefs; two histories equal in all of these are driven
      alike from here on, so evaluators may merge them (policies/evaluation/trust_state.py). Default: the
      whole route (histories on different routes never merge).
    """

    name: str

    def next_junction(self, context: DecisionContext) -> str: ...

    def finished(self, context: DecisionContext) -> bool:
        return False

    def route_determined(self, context: DecisionContext) -> bool:
        return False

    def fallback_active(self, context: DecisionContext) -> bool:
        return False

    def certified_bounds(self) -> tuple[float, float] | None:
        return None

    def route_memory(self, route: tuple[str, ...]) -> Hashable:
        return route
