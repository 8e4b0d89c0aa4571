"""Storm's exact engine (rationals, no tolerance) against our exact values of fixed policies.

A policy that drives a fixed route (the trust-free baseline, or the baseline continued by loops
back into its last waypoint) chooses by the road and the junctions driven alone, both observed in
the product POMDP (policies/peer/product_pomdp.py): under it the product is a finite Markov chain
(`induced_chain`), and the policy's value is a reachability probability in that chain, which
Storm's exact engine returns as a rational (`storm_exact_value`).

- On the paper's town with a driver model whose transition rows sum to 1 as printed (the packaged
  one's numbers to 3 decimals), the exact process of docs/synthesis.md, "Labels at thresholds" is
  that chain: Storm's rational must equal, as a fraction, the value of the same route by
  tests/policies/synthesis/exact_joint.py (our exact joint law of trust and DFA state in integers).
- With the packaged driver model (its rows sum to 1 within an ulp, so the export divides each row
  by its sum), Storm's rational must lie in the certified [L, U] of `trustroute baseline`.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.peer.decimal_model import RoutePolicy, decimal_model
from tests.policies.synthesis.exact_joint import exact_joint_value
from trustroute.app.problem import load_problem
from trustroute.app.synthesis import baseline
from trustroute.policies.logic.spec import load_spec, spec_from_text, state_only_projection
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.peer.product_pomdp import explicit_product, induced_chain, route_choices
from trustroute.policies.routing.free import baseline_route

pytest.importorskip("stormpy", reason="Storm tests need the optional extra: pip install -e '.[peer]'")

from trustroute.policies.peer.storm import storm_exact_value  # noqa: E402

# The paper's φ2 with hightrust read as a trust-state atom at v6, as specs/phi1_trust.toml reads φ1.
PHI2_TRUST = """name = "phi2_trust"
start = "L-H"
formula = "(!lowtrust) U (F (v4 & F (v5 & F (v6 & trusting))))"
[states]
v4 = ["A-B", "G-B", "C-B"]
v5 = ["D-K", "J-K", "L-K"]
v6 = ["A-E", "D-E", "L-E"]
[beliefs.lowtrust]
coeffs = [1, 0, 0, 0, 0, 0, 0]
offset = 1
[trust_states]
trusting = { trust = [6, 7] }
"""
# (spec, its last waypoint set, with the trust atom): the route's loops come back into that set.
SPECS = {"phi1_trust": "v3", "phi2_trust": "v6"}
EXTRA_JUNCTIONS = (0, 6)   # horizons: the baseline route's junctions, and 6 more of loops


@pytest.fixture(scope="module")
def decimal_pomdp(town, driver):
    """The packaged model on the paper's town, its takeover probabilities and trust transitions
    to 3 decimals, every transition row summing to 1 as printed."""
    return build_pomdp(town, decimal_model(driver))


def paper_spec(name: str, town, trust: bool):
    spec = (load_spec(f"specs/{name}.toml", town) if name == "phi1_trust"
            else spec_from_text(PHI2_TRUST, "<phi2_trust>", town))
    return spec if trust else state_only_projection(spec)


def loop_route(town, spec, targets: str, horizon: int) -> list[str]:
    """The baseline route, then (up to `horizon` junctions) the shortest ways back into the set
    `targets` from its end, again and again: each visit reads the trust atom there again."""
    route = baseline_route(town, spec)
    goal = set(spec.state_atoms[targets])
    while len(route) <= horizon:
        before: dict[str, str] = {}
        queue = deque(town.successors(route[-1]))
        for road in queue:
            before[road] = route[-1]
        while queue:
            road = queue.popleft()
            if road in goal:
                break
            for nxt in town.successors(road):
                if nxt not in before:
                    before[nxt] = road
                    queue.append(nxt)
        way = [road]
        while before[way[-1]] != route[-1]:
            way.append(before[way[-1]])
        route += way[::-1]
    return route[:horizon + 1]


def storm_route_value(pomdp, spec, route: list[str], horizon: int) -> Fraction:
    product = explicit_product(pomdp, spec, horizon, exact=True)
    return storm_exact_value(induced_chain(product, route_choices(product, pomdp, route)))


@pytest.mark.parametrize("extra", EXTRA_JUNCTIONS)
@pytest.mark.parametrize("trust", [True, False], ids=["trust_atom", "roads_only"])
@pytest.mark.parametrize("name", sorted(SPECS))
def test_storm_exact_equals_our_exact_value_of_a_route(decimal_pomdp, name, trust, extra):
    town = decimal_pomdp.town
    spec = paper_spec(name, town, trust)
    horizon = len(baseline_route(town, spec)) - 1 + extra
    route = loop_route(town, paper_spec(name, town, True), SPECS[name], horizon)
    ours = exact_joint_value(decimal_pomdp, spec, horizon, policy=RoutePolicy(town, route))
    storm = storm_route_value(decimal_pomdp, spec, route, horizon)
    assert isinstance(ours, Fraction) and storm == ours, (float(storm), float(ours))
    if trust:   # the trust atom read at the last waypoint: neither 0 nor 1
        assert 0 < ours < 1
    else:       # on roads alone the route satisfies the spec
        assert ours == 1


def test_storm_exact_sees_a_shift_of_1e_12_in_one_transition(decimal_pomdp):
    """The comparison above can fail: 1e-12 moved between two outcomes of one choice (each row
    still a distribution) moves Storm's rational off ours."""
    town = decimal_pomdp.town
    spec = paper_spec("phi1_trust", town, True)
    route = baseline_route(town, spec)
    horizon = len(route) - 1
    ours = exact_joint_value(decimal_pomdp, spec, horizon, policy=RoutePolicy(town, route))
    product = explicit_product(decimal_pomdp, spec, horizon, exact=True)
    chain = induced_chain(product, route_choices(product, decimal_pomdp, route))
    assert storm_exact_value(chain) == ours
    # a choice of the last junction into v3 with a goal outcome (trust 6 or 7) and another
    into_goal = chain.goal[chain.transition_target]
    last = chain.step[chain.choice_state[chain.transition_choice]] == horizon - 1
    choice = int(chain.transition_choice[last & into_goal][0])
    first = int(np.flatnonzero((chain.transition_choice == choice) & into_goal)[0])
    second = int(np.flatnonzero((chain.transition_choice == choice) & ~into_goal)[0])
    factors, codes = list(chain.exact_factors), chain.transition_factor.copy()
    for j, delta in ((first, Fraction(1, 10**12)), (second, -Fraction(1, 10**12))):
        factors.append(factors[codes[j]] + delta)
        codes[j] = len(factors) - 1
    shifted = replace(chain, exact_factors=tuple(factors), transition_factor=codes)
    assert storm_exact_value(shifted) > ours
    # Storm's exact reader would take the first shift alone (a row summing to 1 + 1e-12): refused
    codes[second] = chain.transition_factor[second]
    with pytest.raises(ValueError, match="do not sum to 1"):
        storm_exact_value(replace(chain, exact_factors=tuple(factors), transition_factor=codes))


@pytest.mark.parametrize("name", sorted(SPECS))
def test_storm_exact_lies_in_the_certified_bounds_of_the_baseline(pomdp, name):
    """The packaged model: our certified [L, U] of `trustroute baseline` (its float evaluation with
    rounding accounted) holds Storm's exact value of the same route."""
    spec = paper_spec(name, pomdp.town, True)
    found = baseline(load_problem(spec, pomdp.town))
    storm = storm_route_value(pomdp, spec, found.route, len(found.route) - 1)
    lower, upper = Fraction(found.value.lower), Fraction(found.value.upper)
    assert lower <= storm <= upper and upper - lower < Fraction(1, 10**9), (lower, float(storm), upper)
    assert 0 < storm < 1
