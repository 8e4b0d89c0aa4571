"""Certified bounds hold exactly, rounding included (policies/synthesis/rounding.py).

On small random towns (3-5 junctions, H <= 5, the default and random driver models, a belief atom
at a random offset) the synthesized [L, U] contains the exact-rational optimum with no tolerance,
L is at most the returned policy's exact value, and both lie in [0, 1]. Without the outward
rounding the optimum lies outside [L, U], or a bound above 1, on some of these seeds
(`python -m benchmarks bench_rounding_power` counts them).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from fractions import Fraction

import numpy as np
import pytest

from tests.policies.synthesis.threshold_cases import _ExactFilter, exact_value, small_case
from trustroute.policies.belief.exact_labels import exact_prior
from trustroute.policies.logic.labelling import UNIT_ROUNDOFF
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.rounding import model_rounding, relative_margin, widen
from trustroute.policies.synthesis.settings import SynthesisSettings

SEEDS = range(40)


@pytest.fixture(scope="module")
def outcome(driver):
    @functools.cache
    def run(seed: int):
        pomdp, spec, horizon = small_case(seed, driver)
        result = synthesize(pomdp, spec, SynthesisSettings(tau=1e-9, horizon=horizon, time_limit=20.0))
        optimum = exact_value(pomdp, spec, horizon)
        policy_value = exact_value(pomdp, spec, horizon, policy=result.policy)
        return result, optimum, policy_value

    return run


@pytest.mark.parametrize("seed", SEEDS)
def test_bounds_contain_the_exact_optimum_with_no_tolerance(outcome, seed):
    result, optimum, policy_value = outcome(seed)
    assert 0.0 <= result.lower <= result.upper <= 1.0
    assert Fraction(result.lower) <= optimum <= Fraction(result.upper), (seed, result.lower, result.upper)
    assert Fraction(result.lower) <= policy_value, (seed, result.lower, policy_value)
    assert result.stats.converged      # decided on the computed bounds (their gap, not the margin)


@pytest.mark.parametrize("seed", range(6))
def test_unbounded_bounds_lie_in_the_unit_interval(driver, seed):
    pomdp, spec, _ = small_case(seed, driver)
    result = synthesize(pomdp, spec, SynthesisSettings(horizon=None, time_limit=5.0))
    assert 0.0 <= result.lower <= result.upper <= 1.0, (seed, result.lower, result.upper)


def test_widening_keeps_zero_and_one_and_moves_the_rest_outward(driver):
    margin = relative_margin(model_rounding(build_pomdp(small_case(0, driver)[0].town, driver)), 20, "bayes")
    assert 0 < margin < 1e-12
    assert widen(0.0, 1.0, margin) == (0.0, 1.0)
    assert widen(0.0, 0.0, margin) == (0.0, 0.0)
    above_one = widen(1.0000000000000002, 1.0000000000000002, margin)
    assert above_one[0] < 1.0 and above_one[1] == 1.0
    low, high = widen(0.5, 0.5, margin)
    assert low < 0.5 < high and 0.5 - low < 1e-12 and high - 0.5 < 1e-12


def test_a_models_rounding_constants_are_held_on_it_and_count_its_rows_exactly(driver):
    """model_rounding is computed once per model and rule (every synthesis of the model reads it),
    and its row units are those of the exact gap |Σ row - 1| (the rows' decimals) of the row
    furthest from 1: here one row of the packaged model moved off 1 by about 3e-10."""
    transition = driver.trust_transition.copy()
    transition[1, 1, 0, 2, 3] += 3e-10
    town = small_case(0, driver)[0].town
    moved = build_pomdp(town, dataclasses.replace(driver, trust_transition=transition))
    rounding = model_rounding(moved)
    assert model_rounding(moved) is rounding
    assert model_rounding(moved, "paper") is model_rounding(moved, "paper")
    gap = max(abs(sum((Fraction(repr(v)) for v in row), Fraction(0)) - 1)
              for row in transition.reshape(-1, transition.shape[-1]).tolist())
    assert 1e-10 < gap < 1e-9
    assert rounding.rows == math.ceil(float(gap) * (1 + 4 * UNIT_ROUNDOFF) / UNIT_ROUNDOFF)


def test_the_brute_force_builds_one_exact_filter_per_model_and_rule(driver):
    """exact_value's filter is built once per model and rule: a model rebuilt from the same numbers
    gets the filter already built, which is the one a fresh build gives; another rule, or the same
    numbers under another prior, get their own."""
    pomdp = build_pomdp(small_case(0, driver)[0].town, driver)
    shared = _ExactFilter.of(pomdp, "bayes")
    assert _ExactFilter.of(build_pomdp(pomdp.town, driver), "bayes") is shared
    assert shared == _ExactFilter._build(pomdp, "bayes", exact_prior(driver))
    assert _ExactFilter.of(pomdp, "paper") not in (shared, None)
    skewed = dataclasses.replace(driver, initial_belief=np.array([0.1] * 4 + [0.2] * 3))
    other = _ExactFilter.of(build_pomdp(pomdp.town, skewed), "bayes")
    assert other.prior == (1, 1, 1, 1, 2, 2, 2) and other.update == shared.update
