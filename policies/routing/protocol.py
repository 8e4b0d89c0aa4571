"""The routing-policy interface every route chooser implements.

A policy is asked at each road, before the vehicle commits to a lane, for the next
junction. It sees only what the AV knows online: the roads driven so far, the
spec's DFA state after the current position, and the AV's Bayes belief over trust.
Policies are stateless between calls: everything they need is in the context, so
one policy object can drive many episodes (and processes) at once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True, eq=False)
class DecisionContext:
    """What the AV knows when it must choose the next junction.

    route: directed roads driven so far, the start road first and the current road last.
    dfa_state: state of the spec's DFA after reading the current position.
    belief: the AV's belief over trust levels at the current position (sums to 1).
    """

    route: tuple[str, ...]
    dfa_state: int
    belief: np.ndarray

    @property
    def road(self) -> str:
        return self.route[-1]

    @property
    def junctions_driven(self) -> int:
        return len(self.route) - 1


@runtime_checkable
class RoutingPolicy(Protocol):
    """Anything with a name that maps a DecisionContext to a next junction."""

    name: str

    def next_junction(self, context: DecisionContext) -> str: ...
