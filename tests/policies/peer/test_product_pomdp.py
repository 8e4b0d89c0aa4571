"""The exported product POMDP: a well-formed POMDP, the states an independent search reaches."""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.trust_specs import random_problem
from trustroute.core import defaults
from trustroute.core.errors import InputError
from trustroute.policies.logic.dfa import build_dfa
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.peer.product_pomdp import check_product_size, explicit_product


def dfa_step(dfa, spec, driver, q, road, theta):
    """The DFA's step on position `road` at trust index `theta`, atom by atom from the spec."""
    valuation = {}
    for atom in dfa.atoms:
        if atom in spec.state_atoms:
            valuation[atom] = road in spec.state_atoms[atom]
        elif atom in spec.trust_atoms:
            definition = spec.trust_atoms[atom]
            valuation[atom] = ((definition.roads is None or road in definition.roads)
                               and driver.trust_levels[theta] in definition.trust)
        else:
            valuation[atom] = False
    return dfa.step(q, valuation)


def reachable_count(pomdp, spec, horizon):
    """Breadth-first search over (x, θ, q, h, e, k) with the DFA stepped atom by atom."""
    town, driver = pomdp.town, pomdp.driver
    dfa = build_dfa(spec)

    def step(q, road, theta):
        return dfa_step(dfa, spec, driver, q, road, theta)

    outcomes = [(h, e) for h in (0, 1) for e in ((0, 1) if driver.depends_on_performance else (0,))]
    frontier = {(spec.start, t, step(dfa.initial, spec.start, t), 0, 0, 0)
                for t in range(driver.n_trust) if driver.initial_belief[t] > 0}
    seen = set(frontier)
    while frontier:
        new = set()
        for road, t, q, _, _, k in frontier:
            if horizon is not None and k == horizon:
                continue
            for junction in town.actions(road):
                road2 = town.successor(road, junction)
                inc = driver.incident_index(town.incident(road2))
                for h, e in outcomes:
                    takeover = driver.takeover_probability[inc, t]
                    failure = driver.failure_probability[inc, t]
                    p = (takeover if h else 1 - takeover) * (failure if e else 1 - failure)
                    for t2 in range(driver.n_trust):
                        if p * driver.trust_transition[inc, h, e, t, t2] > 0:
                            k2 = k + 1 if horizon is not None else 0
                            state = (road2, t2, step(q, road2, t2), h, e, k2)
                            if state not in seen:
                                seen.add(state)
                                new.add(state)
        frontier = new
    return len(seen) + 1   # and the begin state


@pytest.mark.parametrize("seed,horizon", [(1, None), (2, 3), (3, 2), (4, None)])
def test_product_is_a_pomdp_with_the_reachable_states(driver, seed, horizon):
    pomdp, spec = random_problem(np.random.default_rng(seed), driver, "trust")
    product = explicit_product(pomdp, spec, horizon)
    assert product.n_states == reachable_count(pomdp, spec, horizon)
    sums = np.bincount(product.transition_choice, weights=product.transition_probability)
    assert np.allclose(sums, 1.0, atol=1e-12)
    # States with one observation offer the same actions (the road and the counter are observed).
    actions: dict[int, set[str]] = {}
    for state in range(product.n_states):
        labels = {product.choice_label[c] for c in np.flatnonzero(product.choice_state == state)}
        assert actions.setdefault(int(product.observation[state]), labels) == labels
    drn = product.to_drn()
    assert drn.count("\nstate ") == product.n_states and " init" in drn.splitlines()[11]


def test_specs_testing_belief_atoms_are_refused_and_untested_ones_allowed(pomdp):
    with pytest.raises(InputError, match="belief atoms \\(hightrust\\)"):
        explicit_product(pomdp, load_spec("specs/phi1.toml", pomdp.town), 4)
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    assert not explicit_product(pomdp, spec, 5).goal.any()   # the route needs 6 junctions
    assert explicit_product(pomdp, spec, 6).goal.any()


def _per_step(pomdp, spec) -> tuple[int, ...]:
    """The grid of one step of the product: roads, trust levels, DFA states, last (h, e)."""
    outcomes = 4 if pomdp.driver.depends_on_performance else 2
    return (pomdp.n_states, pomdp.n_trust, build_dfa(spec).n_states, outcomes)


def test_the_largest_product_that_fits_is_taken_and_one_step_more_is_refused(pomdp):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    per_step = _per_step(pomdp, spec)
    largest = defaults.MAX_PEER_PRODUCT // int(np.prod(per_step)) - 1   # steps 0..H
    check_product_size(spec, (*per_step, largest + 1), largest)
    with pytest.raises(InputError) as refused:
        check_product_size(spec, (*per_step, largest + 2), largest + 1)
    assert refused.value.place == "--horizon"
    assert refused.value.fix.startswith(f"pass --horizon {largest} or less")


def test_the_export_checks_its_size_before_it_builds(pomdp, monkeypatch):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    step = int(np.prod(_per_step(pomdp, spec)))
    monkeypatch.setattr(defaults, "MAX_PEER_PRODUCT", step * 11)        # horizons up to 10
    assert explicit_product(pomdp, spec, 10).n_states > 0
    with pytest.raises(InputError, match=r"--horizon: .* grid states .*\(fix: pass --horizon 10 or less"):
        explicit_product(pomdp, spec, 11)
    monkeypatch.setattr(defaults, "MAX_PEER_PRODUCT", step - 1)         # not even one step
    with pytest.raises(InputError, match=r"product: .*\(fix: use a smaller town"):
        explicit_product(pomdp, spec, None)
