"""Trust-free baseline: shortest route completing the state-only task, checked by brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest

from trustroute.networks.road import Road
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.routing.free import baseline_route, completion_route, trust_free_policy
from trustroute.policies.routing.protocol import DecisionContext

# Waypoint junctions of the paper's specs: every road into G is in v1, into J in v2, and so on.
WAYPOINTS = {"phi1": ("E-A", ("G", "J", "L")), "phi2": ("L-H", ("B", "K", "E"))}


def brute_force_shortest(town, start, junctions, max_roads=12):
    """Shortest no-U-turn route from `start` arriving at `junctions` in order (all routes enumerated)."""
    best = (math.inf, None)

    def extend(route, need, length):
        nonlocal best
        if length >= best[0]:
            return
        if not need:
            best = (length, list(route))
            return
        if len(route) > max_roads:
            return
        for nxt in town.successors(route[-1]):
            arrived = Road.parse(nxt).to_junction
            extend(route + [nxt], need[1:] if arrived == need[0] else need, length + town.length(nxt))

    extend([start], tuple(junctions), 0.0)
    return best


@pytest.mark.parametrize("name", ["phi1", "phi2"])
def test_baseline_is_the_brute_force_shortest_route(town, name):
    spec = load_spec(f"specs/{name}.toml", town)
    start, junctions = WAYPOINTS[name]
    assert spec.start == start
    length, expected = brute_force_shortest(town, start, junctions)
    route = baseline_route(town, spec)
    assert route[0] == start
    assert town.route_length(route) == pytest.approx(length, abs=1e-9)
    assert route == expected
    for a, b in zip(route, route[1:], strict=False):  # legal moves only
        assert b in town.successors(a)


def test_phi1_baseline_is_the_expected_route(town):
    spec = load_spec("specs/phi1.toml", town)
    assert baseline_route(town, spec) == ["E-A", "A-F", "F-G", "G-I", "I-J", "J-K", "K-L"]


@pytest.mark.parametrize("name", ["phi1", "phi2"])
def test_free_policy_follows_the_baseline_and_replans_off_it(town, name):
    spec = load_spec(f"specs/{name}.toml", town)
    policy = trust_free_policy(town, spec)
    assert policy.name == "free"
    route = baseline_route(town, spec)
    belief = np.full(7, 1 / 7)
    for t in range(len(route) - 1):
        context = DecisionContext(route=tuple(route[: t + 1]), dfa_state=0, belief=belief)
        assert not policy.finished(context)
        assert town.successor(route[t], policy.next_junction(context)) == route[t + 1]
    assert policy.finished(DecisionContext(route=tuple(route), dfa_state=0, belief=belief))

    # Off the route: take a different first move, then the policy must re-plan the shortest completion.
    start, junctions = WAYPOINTS[name]
    detour = next(s for s in town.successors(start) if s != route[1])
    arrived = Road.parse(detour).to_junction
    need = junctions[1:] if arrived == junctions[0] else junctions
    length, expected = brute_force_shortest(town, detour, need)
    assert completion_route(town, spec, [start, detour]) == expected
    context = DecisionContext(route=(start, detour), dfa_state=0, belief=belief)
    assert town.successor(detour, policy.next_junction(context)) == expected[1]


def test_completion_route_after_the_task_is_done_is_just_the_current_road(town):
    spec = load_spec("specs/phi1.toml", town)
    route = baseline_route(town, spec)
    assert completion_route(town, spec, route) == [route[-1]]
