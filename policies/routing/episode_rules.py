"""The rules of an episode, written once: when it ends and how the next junction is asked.

At every position of an episode, in this order:
1. the spec's DFA accepts -> "accepted";
2. the DFA can no longer accept -> "rejected";
3. the policy (wrapped with the 20-junction fallback) declares itself finished -> "destination";
4. `junction_cap` junctions driven -> "cap";
5. otherwise the policy picks the next junction, which must be a legal move of the town; the
   decision records whether the fallback (not the policy) drove.

The episode tracker (both engines), the model engine's batch path and Monte Carlo and the exact
evaluation (policies/evaluation/plain.py) all use these functions, so they cannot disagree on when
an episode ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trustroute.core import defaults
from trustroute.core.fields import Integer
from trustroute.networks.town import Town
from trustroute.policies.logic.compiled import CompiledSpec
from trustroute.policies.logic.spec import Spec
from trustroute.policies.routing.fallback import FallbackPolicy, with_fallback
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy

END_REASONS: tuple[str, ...] = ("accepted", "rejected", "destination", "cap")
DEFAULT_JUNCTION_CAP = defaults.JUNCTION_CAP   # an episode still running after this many junctions ends
# the caps a study config or an environment takes
JUNCTION_CAPS = Integer(minimum=1, maximum=defaults.MAX_JUNCTIONS)
RUNNING, ACCEPTED, REJECTED = 0, 1, 2


@dataclass(frozen=True)
class Decision:
    """What happens at a position the DFA has not ended: the episode ends (`end` is
    "destination" or "cap"), or the vehicle drives to `junction` (`fallback`: the fallback chose)."""

    end: str | None
    junction: str | None = None
    fallback: bool = False


def episode_policy(policy: RoutingPolicy, town: Town, spec: Spec,
                   fallback_after: int | None) -> RoutingPolicy:
    """The policy an episode runs: wrapped with the fallback after `fallback_after` junctions
    (None: as given; a policy already wrapped is not wrapped again)."""
    if fallback_after is None or isinstance(policy, FallbackPolicy):
        return policy
    return with_fallback(policy, town, spec, after=fallback_after)


def dfa_verdicts(compiled: CompiledSpec, q: np.ndarray) -> np.ndarray:
    """Per DFA state in q: ACCEPTED, REJECTED (can no longer accept) or RUNNING (rules 1-2)."""
    q = np.asarray(q, dtype=np.int64)
    accepted = compiled.accepting[q]
    return np.where(accepted, ACCEPTED, np.where(compiled.rejecting[q], REJECTED, RUNNING))


def dfa_verdict(compiled: CompiledSpec, q: int) -> str | None:
    """"accepted", "rejected" or None (the episode goes on) at DFA state q (rules 1-2)."""
    if compiled.accepting[q]:
        return "accepted"
    if compiled.rejecting[q]:
        return "rejected"
    return None


def end_before_choice(policy: RoutingPolicy, context: DecisionContext, junction_cap: int) -> str | None:
    """Rules 3-4 at a position the DFA has not ended: "destination", "cap", or None (a junction is
    to be chosen)."""
    if policy.finished(context):
        return "destination"
    if context.junctions_driven >= junction_cap:
        return "cap"
    return None


def checked_choice(policy: RoutingPolicy, context: DecisionContext, town: Town, junction: str) -> Decision:
    """Rule 5 on a junction chosen at `context` (by `policy`, or by whoever steps the episode): it
    must be a legal move of the town; the decision records whether the fallback drove."""
    legal = town.actions(context.road)
    if junction not in legal:
        raise ValueError(f"policy {policy.name!r} chose {junction!r}, not a legal move from "
                         f"{context.road} (legal: {', '.join(legal)})")
    return Decision(None, junction, bool(policy.fallback_active(context)))


def decide(policy: RoutingPolicy, context: DecisionContext, town: Town, junction_cap: int) -> Decision:
    """Rules 3-5 at a position the DFA has not ended."""
    end = end_before_choice(policy, context, junction_cap)
    if end is not None:
        return Decision(end)
    return checked_choice(policy, context, town, policy.next_junction(context))
