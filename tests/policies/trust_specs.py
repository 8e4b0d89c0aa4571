"""Random small problems whose specs mix road, belief and trust-state atoms (shared by tests)."""

from __future__ import annotations

import numpy as np

from tests.policies.evaluation.test_random_models import random_driver
from tests.policies.synthesis.test_synthesis_random import random_town
from trustroute.policies.logic.spec import spec_from_text
from trustroute.policies.model.trust_pomdp import build_pomdp

TRUST_FORMULAS = ("F (a & trusting)", "(!wary) U (a & F (b & trusting))", "F (a & X trusting)",
                  "(!wary) U (F b)")
BELIEF_FORMULAS = ("F (a & F (b & high))", "(!high) U a")
MIXED_FORMULAS = ("F (a & high & trusting)", "(!wary) U (a & F (b & high))",
                  "F (a & trusting) | F (b & high)")
FORMULAS = {"trust": TRUST_FORMULAS, "belief": BELIEF_FORMULAS, "mixed": MIXED_FORMULAS}


def random_problem(rng: np.random.Generator, driver, kind: str):
    """(pomdp, spec) on a random 4-5 junction town and driver model; `kind` picks the atoms."""
    town = random_town(rng)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    start = str(rng.choice(town.states))
    rings = [{start}]
    for _ in range(3):
        rings.append({nxt for road in rings[-1] for nxt in town.successors(road)})
    near, far = sorted(rings[1] | rings[2]), sorted(rings[2] | rings[3])
    a = sorted(rng.choice(near, size=min(len(near), 2), replace=False).tolist())
    b = sorted(rng.choice(far, size=min(len(far), 2), replace=False).tolist())
    coeffs = rng.integers(0, 2, size=7).astype(float)
    coeffs[int(rng.integers(7))] = 1.0
    offset = float(coeffs @ pomdp.initial_belief + rng.uniform(-0.15, 0.15))
    high_levels = sorted({int(v) for v in rng.integers(3, 8, size=3)})
    low_levels = sorted({int(v) for v in rng.integers(1, 4, size=2)})
    formula = FORMULAS[kind][int(rng.integers(len(FORMULAS[kind])))]
    wary_roads = sorted(rng.choice(town.states, size=2, replace=False).tolist())
    text = (f'name = "random"\nstart = "{start}"\nformula = "{formula}"\n'
            f"[states]\na = {a}\nb = {b}\n"
            f"[beliefs.high]\ncoeffs = {coeffs.tolist()}\noffset = {offset}\n"
            f"[trust_states]\ntrusting = {{ trust = {high_levels} }}\n"
            f"wary = {{ roads = {wary_roads}, trust = {low_levels} }}\n").replace("'", '"')
    return pomdp, spec_from_text(text, "<random spec>", town)
