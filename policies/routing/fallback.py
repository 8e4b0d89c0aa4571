"""The study's 20-junction rule as a wrapper around any routing policy.

A trust-aware policy may loop to build trust. After `after` junctions without the spec
accepted, the vehicle switches to the shortest route completing the remaining state-only
task (docs/model.md, "Episodes"); the projected DFA state is recomputed
from the roads driven, so the wrapper needs nothing but the DecisionContext.

Episode ends a policy can declare: `policy_finished(policy, context)` is True when the
policy has nothing left to drive (the trust-free route or the fallback completion is done,
i.e. the destination is reached, or the state-only task can no longer be completed).
"""

from __future__ import annotations

from trustroute.networks.town import Town
from trustroute.policies.logic.dfa import DFA, build_dfa
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.free import StateOnlyTask, state_only_task
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

DEFAULT_FALLBACK_AFTER = 20


def policy_finished(policy: RoutingPolicy, context: DecisionContext) -> bool:
    """True when `policy` declares the episode over at this context (policies without
    a `finished` method never do)."""
    finished = getattr(policy, "finished", None)
    return bool(finished(context)) if finished is not None else False


def fallback_fired(policy: RoutingPolicy, context: DecisionContext) -> bool:
    """True when `policy` is a fallback wrapper whose fallback drives at this context."""
    active = getattr(policy, "fallback_active", None)
    return bool(active(context)) if active is not None else False


class FallbackPolicy:
    """Delegate to `inner` for the first `after` junctions, then complete the state-only task."""

    def __init__(self, inner: RoutingPolicy, task: StateOnlyTask, dfa: DFA, after: int) -> None:
        if after < 0:
            raise ValueError(f"fallback after {after} junctions: must be >= 0")
        self.inner = inner
        self.task = task
        self.dfa = dfa
        self.after = int(after)
        self.name = f"{inner.name}+fallback{after}"
        # A trust-free inner policy already completes the state-only task: reuse its route cache.
        self._projected = getattr(inner, "projected_state", None) or (
            lambda route: task.projected_state(route))

    def fallback_active(self, context: DecisionContext) -> bool:
        """True from the `after`-th junction on while the spec is not accepted."""
        return (context.junctions_driven >= self.after
                and not bool(self.dfa.accepting[context.dfa_state]))

    def route_determined(self, context: DecisionContext) -> bool:
        """True when the decision here depends on the roads driven only (for any belief and any
        non-accepting DFA state): in the fallback phase, or when the inner policy says so."""
        if context.junctions_driven >= self.after:
            return True
        method = getattr(self.inner, "route_determined", None)
        return bool(method(context)) if method is not None else False

    def finished(self, context: DecisionContext) -> bool:
        if self.fallback_active(context):
            q = self._projected(tuple(context.route))
            return self.task.next_junction(context.road, q) is None
        return policy_finished(self.inner, context)

    def next_junction(self, context: DecisionContext) -> str:
        if not self.fallback_active(context):
            return self.inner.next_junction(context)
        junction = self.task.next_junction(context.road, self._projected(tuple(context.route)))
        return junction if junction is not None else self.inner.next_junction(context)


def with_fallback(policy: RoutingPolicy, town: Town, spec: Spec,
                  after: int = DEFAULT_FALLBACK_AFTER) -> FallbackPolicy:
    """Wrap `policy` with the study's rule: after `after` junctions, follow the shortest
    route completing the remaining state-only task of `spec`."""
    return FallbackPolicy(policy, state_only_task(town, spec), build_dfa(spec), after)
