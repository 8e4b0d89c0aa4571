"""The 20-junction rule: delegate before `after` junctions, then the shortest state-only completion."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.networks.road import Road
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.labelling import Labeller
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.fallback import with_fallback
from trustroute.policies.routing.free import completion_route
from trustroute.policies.routing.protocol import DecisionContext, RoutingPolicy


class AlwaysFirst(RoutingPolicy):
    """Always the first legal move (loops for ever on the default town): never completes alone."""

    name = "first"

    def __init__(self, town):
        self.town = town

    def next_junction(self, context):
        return self.town.actions(context.road)[0]


def drive(town, spec, policy, junctions):
    """Drive `policy` for up to `junctions` junctions with a uniform belief; return the contexts seen."""
    dfa = build_dfa(spec)
    labeller = Labeller(spec, dfa, town)
    belief = np.full(7, 1 / 7)
    route = [spec.start]
    q = int(labeller.step(np.array([dfa.initial]), np.array([town.state_index(spec.start)]),
                          belief[None])[0])
    contexts = []
    for _ in range(junctions + 1):
        context = DecisionContext(route=tuple(route), dfa_state=q, belief=belief)
        contexts.append(context)
        if dfa.accepting[q] or policy.finished(context):
            break
        nxt = town.successor(route[-1], policy.next_junction(context))
        q = int(labeller.step(np.array([q]), np.array([town.state_index(nxt)]), belief[None])[0])
        route.append(nxt)
    return contexts


@pytest.mark.parametrize("after", [0, 3, 20])
def test_fallback_delegates_then_completes_the_state_only_task(town, after):
    spec = load_spec("specs/phi1.toml", town)
    inner = AlwaysFirst(town)
    policy = with_fallback(inner, town, spec, after=after)
    contexts = drive(town, spec, policy, after + 30)
    for context in contexts[:after]:
        assert not policy.fallback_active(context)
        assert policy.next_junction(context) == inner.next_junction(context)
    switch = contexts[after]
    assert policy.fallback_active(switch)
    expected = completion_route(town, spec, switch.route)
    assert expected is not None
    # From the switch on, the vehicle drives exactly the shortest completion and then stops.
    final = contexts[-1]
    assert list(final.route[after:]) == expected
    assert policy.finished(final)
    arrivals = [Road.parse(r).to_junction for r in final.route]
    # The state-only task of φ1 (G, then J, then L) is done at the end.
    g = arrivals.index("G")
    j = arrivals.index("J", g)
    assert "L" in arrivals[j:]


def test_fallback_is_inactive_once_the_spec_is_accepted(town):
    spec = load_spec("specs/phi1.toml", town)
    dfa = build_dfa(spec)
    accepting = int(np.flatnonzero(dfa.accepting)[0])
    policy = with_fallback(AlwaysFirst(town), town, spec, after=0)
    context = DecisionContext(route=("E-A",), dfa_state=accepting, belief=np.full(7, 1 / 7))
    assert not policy.fallback_active(context)
    assert policy.name == "first+fallback0"


def test_negative_after_is_rejected(town):
    spec = load_spec("specs/phi1.toml", town)
    with pytest.raises(ValueError):
        with_fallback(AlwaysFirst(town), town, spec, after=-1)
