"""Unbounded bounds that say something: end components collapsed, U closes where the optimum is below 1.

On random small towns, where the long-horizon bounded value is below 1 and the spec is of the
kinds in CLOSING, the unbounded run must close its gap to 1e-3; on every spec it must stay above
the long-horizon lower bound (the unbounded value is at least V_H). That an unbounded run's policy
is worth its L is checked by exact evaluation in test_synthesis.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_junctions
from trustroute.networks.town import INCIDENT_TYPES, town_from_dict
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings

FORMULAS = ("(!high) U a", "(!high) U (a & F b)", "F (a & high)", "(!high) U (a & X (F (b & high)))")
# Where the closure is asserted: after the until only state atoms remain. With a belief atom after
# it (F (b & high)) or F (a & high), U can stay at 1 on some towns (docs/synthesis.md).
CLOSING = ("(!high) U a", "(!high) U (a & F b)")
LONG_HORIZON = 24
TOLERANCE = 1e-9
# Units of work (about 100,000 a second of one idle core), with a time limit far above as the
# safety net only: a run stops on its work, whatever the machine's load.
LONG_WORK = {"work_limit": 6_000_000, "time_limit": 900.0}
SHORT_WORK = {"work_limit": 1_000_000, "time_limit": 900.0}


def deterministic_town(rng: np.random.Generator):
    """A random connected town of 4-5 junctions; every draw in a fixed order (no set iteration)."""
    n = int(rng.integers(4, 6))
    names = [chr(ord("A") + i) for i in range(n)]
    junctions = random_junctions(rng, names)
    roads = {tuple(sorted((names[i], names[int(rng.integers(i))]))) for i in range(1, n)}
    for _ in range(int(rng.integers(1, n))):
        u, v = rng.choice(n, size=2, replace=False)
        roads.add(tuple(sorted((names[u], names[v]))))
    roads = sorted(roads)
    directed = [f"{u}-{v}" for a, b in roads for u, v in ((a, b), (b, a))]
    incidents = {road: str(rng.choice(INCIDENT_TYPES)) for road in directed}
    return town_from_dict({"junctions": junctions, "roads": [list(r) for r in roads],
                           "incidents": incidents}, "<random town>")


def risky_spec(rng: np.random.Generator, town, initial_belief: np.ndarray):
    start = town.states[int(rng.integers(len(town.states)))]
    others = [road for road in town.states if road != start]
    a = sorted(rng.choice(others, size=min(2, len(others)), replace=False).tolist())
    b = sorted(rng.choice(others, size=1, replace=False).tolist())
    coeffs = rng.integers(0, 2, size=7).astype(float)
    coeffs[int(rng.integers(7))] = 1.0
    offset = float(coeffs @ initial_belief + rng.uniform(-0.15, 0.15))
    text = (f'name = "risky"\nstart = "{start}"\nformula = "{FORMULAS[int(rng.integers(len(FORMULAS)))]}"\n'
            f"[states]\na = {a}\nb = {b}\n".replace("'", '"')
            + f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset!r}\n")
    return spec_from_text(text, "<risky spec>", town)


@pytest.mark.slow
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), default_driver=st.booleans())
# (!high) U (a & F b) on 8 roads, optimum 0.6214: the search at H = 20 overran the search's share
# of the work, and the unbounded problem's search, given a share of what was left of it, never ran
# (U stayed at 1)
@example(seed=288965858, default_driver=False)
def test_unbounded_gap_closes_where_the_optimum_is_below_one(driver, seed, default_driver):
    rng = np.random.default_rng(seed)
    town = deterministic_town(rng)
    model = driver if default_driver else random_driver(rng, driver.incident_types)
    pomdp = build_pomdp(town, model)
    spec = risky_spec(rng, town, pomdp.initial_belief)
    # Work limits, not time limits (policies/work_clock.py): where the gap is asserted, work well
    # above what the examples need (some need 12 s unbounded on an idle machine, 1,200,000 units), so
    # the gap is the algorithm's and no example depends on the machine's load. Elsewhere only
    # soundness is asserted, which holds at any limit.
    long = synthesize(pomdp, spec, SynthesisSettings(tau=1e-4, horizon=LONG_HORIZON, **LONG_WORK))
    closes = long.upper < 1 - 1e-3 and spec.formula_text in CLOSING   # optimum below 1 (within 1e-3)
    unbounded = synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, **(LONG_WORK if closes else SHORT_WORK)))
    assert unbounded.upper >= long.lower - TOLERANCE          # the unbounded value is at least V_H
    assert unbounded.lower <= unbounded.upper + TOLERANCE
    if closes:
        assert unbounded.gap <= 1e-3, (unbounded.lower, unbounded.upper, long.lower, long.upper)


def test_end_components_close_a_case_the_greatest_fixed_point_left_at_one(driver):
    """Seed 5 of the generator: (!high) U (a & X (F (b & high))), default driver. Every route
    is decided (optimum 0 within 24 junctions and unbounded); iteration from 1 without collapsing
    end components kept U = 1 here."""
    rng = np.random.default_rng(5)
    town = deterministic_town(rng)
    pomdp = build_pomdp(town, driver)
    spec = risky_spec(rng, town, pomdp.initial_belief)
    assert spec.formula_text == "(!high) U (a & X (F (b & high)))"
    # Work limits well above what it needs: the gap asserted below is the algorithm's.
    long = synthesize(pomdp, spec, SynthesisSettings(tau=1e-4, horizon=LONG_HORIZON, **LONG_WORK))
    unbounded = synthesize(pomdp, spec, SynthesisSettings(tau=1e-3, **LONG_WORK))
    assert long.upper < 1e-3
    assert unbounded.gap <= 1e-3 and unbounded.upper >= long.lower - TOLERANCE
