"""The study's 20-junction rule as a wrapper around any routing policy.

A trust-aware policy may loop to build trust. After `after` junctions without the spec
accepted, the vehicle switches to the shortest route completing the remaining state-only
task (docs/model.md, "Episodes"); the projected DFA state is recomputed
from the roads driven, so the wrapper needs nothing but the DecisionContext.

Episode ends a policy can declare: `policy.finished(context)` is True when the policy has
nothing left to drive (the trust-free route or the fallback completion is done, i.e. the
destination is reached, or the state-only task can no longer be completed). The order of the
episode's rules is in policies/routing/episode_rules.py.
"""

from __future__ import annotations

from collections.abc import Hashable

from trustroute.core import defaults
from trustroute.networks.town import Town
from trustroute.policies.logic.compiled import compile_spec
from trustroute.policies.logic.dfa import DFA
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.free import StateOnlyTask, TrustFreePolicy, state_only_task
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

DEFAULT_FALLBACK_AFTER = defaults.FALLBACK_AFTER


class FallbackPolicy(RoutingPolicy):
    """Delegate to `inner` for the first `after` junctions, then complete the state-only task."""

    def __init__(self, inner: RoutingPolicy, task: StateOnlyTask, dfa: DFA, after: int) -> None:
        if after < 0:
            raise ValueError(f"fallback after {after} junctions: must be >= 0")
        self.inner = inner
        self.task = task
        self.dfa = dfa
        self.after = int(after)
        self.name = f"{inner.name}+fallback{after}"
        # The trust-free policy of the same task already drives the shortest completion the rule
        # switches to, move for move, and ends where it ends: the rule never takes over from it, so
        # its long routes are not reported as fallen back.
        self.takes_over = not (isinstance(inner, TrustFreePolicy) and inner.task.same_moves(task))

    def fallback_active(self, context: DecisionContext) -> bool:
        """True from the `after`-th junction on while the spec is not accepted, unless the inner
        policy is the trust-free one of the same task (`takes_over`)."""
        return (self.takes_over and context.junctions_driven >= self.after
                and not bool(self.dfa.accepting[context.dfa_state]))

    def route_determined(self, context: DecisionContext) -> bool:
        """True when the decision here depends on the roads driven only (for any belief and any
        non-accepting DFA state): in the fallback phase, or when the inner policy says so."""
        if context.junctions_driven >= self.after:
            return True
        return bool(self.inner.route_determined(context))

    def route_memory(self, route: tuple[str, ...]) -> Hashable:
        """The inner policy's memory and the state-only task's projected state (all the fallback
        reads of the route)."""
        return self.inner.route_memory(route), self.task.projected_state(route)

    def finished(self, context: DecisionContext) -> bool:
        if self.fallback_active(context):
            q = self.task.projected_state(context.route)
            return self.task.next_junction(context.road, q) is None
        return bool(self.inner.finished(context))

    def next_junction(self, context: DecisionContext) -> str:
        if not self.fallback_active(context):
            return self.inner.next_junction(context)
        junction = self.task.next_junction(context.road, self.task.projected_state(context.route))
        return junction if junction is not None else self.inner.next_junction(context)


def with_fallback(policy: RoutingPolicy, town: Town, spec: Spec,
                  after: int = DEFAULT_FALLBACK_AFTER) -> FallbackPolicy:
    """Wrap `policy` with the study's rule: after `after` junctions, follow the shortest
    route completing the remaining state-only task of `spec`."""
    return FallbackPolicy(policy, state_only_task(town, spec), compile_spec(spec, town).dfa, after)
