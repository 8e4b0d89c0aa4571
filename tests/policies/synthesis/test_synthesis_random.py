"""(d) On random small towns and random driver models, the bounds bracket the brute-force optimum.

Towns (4-5 junctions) and driver models (with AV failures, so up to 4 symbols per incident and
no identity incident) are drawn by hypothesis; specs mix state and belief atoms. For H <= 4 the
exact optimum of policies.exact_search must lie in [lower, upper] of the solver, the raw abstraction
bound at the root must be above it, and the unbounded problem's upper bound must be above it too.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.policies.evaluation.test_random_models import random_driver
from trustroute.networks.town import INCIDENT_TYPES, MIN_ROAD_LENGTH, town_from_dict
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.free import trust_free_policy
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.exact_search import exact_optimum
from trustroute.policies.synthesis.settings import SynthesisSettings

FORMULAS = ("F (a & F (b & high))", "(!high) U a", "F (a & high)", "(!high) U (a & X (F (b & high)))")
TOLERANCE = 1e-9


def random_junctions(rng: np.random.Generator, names: list[str]) -> dict[str, list[float]]:
    """Junction positions uniform in a 500 m square. A town's roads are at least MIN_ROAD_LENGTH
    long, so the positions are redrawn (rarely) while two junctions nearly coincide."""
    n = len(names)
    points = rng.uniform(0, 500, size=(n, 2))
    while (np.linalg.norm(points[:, None] - points[None], axis=-1) + np.eye(n) * 1e9).min() < MIN_ROAD_LENGTH:
        points = rng.uniform(0, 500, size=(n, 2))
    return {name: [float(v) for v in point] for name, point in zip(names, points, strict=True)}


def random_town(rng: np.random.Generator):
    n = int(rng.integers(4, 6))
    names = [chr(ord("A") + i) for i in range(n)]
    junctions = random_junctions(rng, names)
    roads = {tuple(sorted((names[i], names[int(rng.integers(i))]))) for i in range(1, n)}  # a tree
    for _ in range(int(rng.integers(1, n))):
        u, v = rng.choice(n, size=2, replace=False)
        roads.add(tuple(sorted((names[u], names[v]))))
    # sorted: a set's order follows PYTHONHASHSEED, and the incident draws follow this order
    directed = [f"{u}-{v}" for a, b in sorted(roads) for u, v in ((a, b), (b, a))]
    incidents = {road: str(rng.choice(INCIDENT_TYPES)) for road in directed}
    return town_from_dict({"junctions": junctions, "roads": [list(r) for r in sorted(roads)],
                           "incidents": incidents}, "<random town>")


def random_spec(rng: np.random.Generator, town, initial_belief: np.ndarray):
    """Waypoints a, b among roads reachable within 1-2 and 2-4 junctions of the start; the belief
    atom's threshold near its value at the initial belief, so that it can go either way."""
    start = str(rng.choice(town.states))
    rings = [{start}]
    for _ in range(4):
        rings.append({nxt for road in rings[-1] for nxt in town.successors(road)})
    near = sorted(rings[1] | rings[2])
    far = sorted(rings[2] | rings[3] | rings[4])
    a = sorted(rng.choice(near, size=min(len(near), int(rng.integers(1, 3))), replace=False).tolist())
    b = sorted(rng.choice(far, size=min(len(far), int(rng.integers(1, 3))), replace=False).tolist())
    coeffs = rng.integers(0, 2, size=7).astype(float)
    coeffs[int(rng.integers(7))] = 1.0
    offset = float(coeffs @ initial_belief + rng.uniform(-0.15, 0.15))
    text = (f'name = "random"\nstart = "{start}"\n'
            f'formula = "{FORMULAS[int(rng.integers(len(FORMULAS)))]}"\n'
            f"[states]\na = {a}\nb = {b}\n".replace("'", '"')
            + f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset}\n")
    return spec_from_text(text, "<random spec>", town)


@pytest.mark.slow
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), horizon=st.integers(3, 5),
       belief_rule=st.sampled_from(["bayes", "paper"]))
def test_bounds_bracket_brute_force_on_random_problems(driver, seed, horizon, belief_rule):
    rng = np.random.default_rng(seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    spec = random_spec(rng, town, pomdp.initial_belief)
    optimum = exact_optimum(pomdp, spec, horizon, belief_rule)
    for tau in (1e-12, 0.2):
        result = synthesize(pomdp, spec,
                            SynthesisSettings(tau=tau, horizon=horizon, belief_rule=belief_rule,
                                              time_limit=20, suffix_length=int(rng.integers(0, 3))))
        assert result.lower - TOLERANCE <= optimum <= result.upper + TOLERANCE, (result.lower, optimum)
        assert result.stats.runs[0].abstraction_root_upper >= optimum - TOLERANCE
    # a work limit (0.1-0.2 s on these towns) rather than a second of the wall clock: an unbounded
    # search that does not converge stops at the same point on any machine, its bounds as sound
    unbounded = synthesize(pomdp, spec, SynthesisSettings(belief_rule=belief_rule, time_limit=60.0,
                                                          work_limit=300_000, suffix_length=2))
    assert unbounded.upper >= optimum - TOLERANCE
    assert unbounded.lower <= unbounded.upper + TOLERANCE


def _early_stop_problem(driver, seed: int):
    """(pomdp, spec, horizon, the trust-free route's exact value) of one seeded random problem."""
    rng = np.random.default_rng(1000 + seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    spec = random_spec(rng, town, pomdp.initial_belief)
    horizon = int(rng.integers(4, 8))
    free = evaluate(pomdp, spec, trust_free_policy(town, spec),
                    EvaluationSettings(fallback_after=None, max_junctions=horizon))
    return pomdp, spec, horizon, free


@pytest.mark.parametrize("seed", range(6))
def test_returned_policy_is_worth_exactly_lower_on_random_problems(driver, seed):
    """Early stops (tau 0.2) leave open nodes; the policy drives the trust-free completion there,
    which the search valued exactly (exact trees, the default on small towns): `evaluate` of the
    policy equals L and is >= the trust-free route's value."""
    pomdp, spec, horizon, free = _early_stop_problem(driver, seed)
    for tau in (0.2, 1e-6):
        result = synthesize(pomdp, spec, SynthesisSettings(tau=tau, horizon=horizon, time_limit=20))
        value = evaluate(pomdp, spec, result.policy,
                         EvaluationSettings(fallback_after=None, max_junctions=horizon))
        run = result.stats.runs[0]
        assert not run.completion_bounds
        strict = run.lower_strict_labels
        assert value.lower == pytest.approx(strict, abs=TOLERANCE), (value.lower, strict, result.lower)
        # every label read as the vehicle reads it: L is the strict value, at least the free route's
        assert value.lower == pytest.approx(result.lower, abs=TOLERANCE)
        assert result.lower >= free.lower - TOLERANCE


@pytest.mark.parametrize("seed", range(6))
def test_returned_policy_is_worth_at_least_lower_with_completion_bounds(driver, seed):
    """The same problems with open nodes valued by the cluster bounds on the completion
    (completion="bounds"): `evaluate` of the policy is at least L and at least its strict-label
    value, and at most U; once converged L is within tau of the trust-free route's value or above."""
    pomdp, spec, horizon, free = _early_stop_problem(driver, seed)
    for tau in (0.2, 1e-6):
        result = synthesize(pomdp, spec,
                            SynthesisSettings(tau=tau, horizon=horizon, time_limit=20, completion="bounds"))
        value = evaluate(pomdp, spec, result.policy,
                         EvaluationSettings(fallback_after=None, max_junctions=horizon))
        strict = result.stats.runs[0].lower_strict_labels
        assert value.lower >= strict - TOLERANCE, (value.lower, strict, result.lower)
        assert result.lower - TOLERANCE <= value.lower <= result.upper + TOLERANCE
        if result.gap <= tau:
            # converged: L >= Pr_max - tau >= the trust-free route's value - tau
            assert result.lower >= free.lower - tau - TOLERANCE


def _return_problem(driver, seed: int):
    """A seeded random problem with a longer horizon (7-10 junctions): room to come back to a
    waypoint reached with too little trust, which only the free completion does."""
    rng = np.random.default_rng(2000 + seed)
    town = random_town(rng)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    spec = random_spec(rng, town, pomdp.initial_belief)
    return pomdp, spec, int(rng.integers(7, 11))


# Seeds 6 and 12 need the return (seed 12 in 3 s of CPU where seed 9 takes 7 s) and search
# thousands of nodes, seeds 0 and 2 a few hundred or fewer (seed 2 stops with open nodes), seeds
# 4, 7 and 8 have nothing to reach. Seeds 1, 3, 5 and 9 cost seconds each (seed 3 at H = 9, 19 s)
# and catch nothing these miss: a policy whose completion does not return, and an L raised above
# the returned policy's value, fail here.
RETURN_SEEDS = [0, 2, 4, 6, 7, 8, 12]


@pytest.mark.slow
def test_open_nodes_are_valued_by_the_completion_that_returns(driver):
    """Open nodes are valued by the free completion (state-only task, then back to what the DFA
    still needs) and the policy drives it where it has no row: early stops (tau 0.2) on seeded
    random problems give `evaluate` of the policy = L with exact trees (auto) and L <= value <= U
    with the cluster bounds; and with exact trees L >= the completion alone's value (a policy
    without rows). Some of these problems do need the return (the completion alone is worth more
    than the state-only one), so the check is not vacuous."""
    from tests.policies.routing.test_free_completion import StateOnlyCompletion, policy_without_rows

    returns = 0
    for seed in RETURN_SEEDS:
        pomdp, spec, horizon = _return_problem(driver, seed)
        alone = evaluate(pomdp, spec, policy_without_rows(pomdp, spec),
                         EvaluationSettings(fallback_after=None, max_junctions=horizon))
        old = evaluate(pomdp, spec, StateOnlyCompletion(pomdp.town, spec),
                       EvaluationSettings(fallback_after=None, max_junctions=horizon))
        returns += alone.lower > old.lower + 1e-6
        for completion in ("auto", "bounds"):
            result = synthesize(pomdp, spec,
                                SynthesisSettings(tau=0.2, horizon=horizon, time_limit=20,
                                                  completion=completion))
            value = evaluate(pomdp, spec, result.policy,
                             EvaluationSettings(fallback_after=None, max_junctions=horizon))
            run = result.stats.runs[0]
            if completion == "auto" and run.nodes:
                assert not run.completion_bounds and run.completion_closed
                assert value.lower == pytest.approx(run.lower_strict_labels, abs=TOLERANCE)
                assert value.lower == pytest.approx(result.lower, abs=TOLERANCE), (seed, value.lower)
            assert result.lower - TOLERANCE <= value.lower <= result.upper + TOLERANCE, (seed, completion)
            if completion == "auto" and run.completion_closed:
                assert result.lower >= alone.lower - TOLERANCE, (seed, alone.lower, result.lower)
    assert returns >= 2
