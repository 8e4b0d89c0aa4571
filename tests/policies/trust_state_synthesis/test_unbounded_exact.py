"""The unbounded bounds of specs that test the hidden trust, against their exact values.

On exact_loops.py's problems (a choice after one informative road, then loops with no exit whose
roads move the hidden trust unseen; the spec reads the trust there), Pr_max and the returned
policy's value over unbounded time are absorption probabilities of a finite Markov chain, solved in
Fractions. The synthesis' certified bounds must hold with no tolerance, the floats read exactly:

    L <= value(returned policy) <= Pr_max <= U.

Even seeds are `recurrent` loops (the live mass decays geometrically: the unbounded evaluation stops
with at most 1e-9 of it open, L lies that far below the policy's value); odd seeds `rising` ones
(every branch is decided within a few junctions: the computed L and U are the exact values up to
floating-point rounding, so only the margins keep them on the right side, and each stays within
1e-10 of its exact value here). Every run ends with every search complete ("depth cap") and the
policy's evaluation converged, on a work limit: the same bounds at any load.
"""

from __future__ import annotations

from fractions import Fraction

import pytest

from tests.policies.synthesis.threshold_cases import sweep
from tests.policies.trust_state_synthesis.exact_loops import exact_loop_values, loop_case
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.synthesize_spec import synthesize_spec

# The fast seeds: 1 and 3 (rising) have L above the policy's exact value when neither the unfolding's
# ROUNDING_MARGIN_PER_LEVEL nor the outward rounding is applied; 0 and 30 (recurrent) have U below
# Pr_max when the relaxation's margin is dropped too, and 30 when the relaxation is iterated from
# below (its limit is the value, but no iterate is an upper bound).
SEEDS = sweep(40, fast=(0, 1, 3, 30))
SETTINGS = SynthesisSettings(tau=1e-15, time_limit=600.0, work_limit=5_000_000)
CLOSE = 1e-10     # a rising case's L and U lie this close to the exact values


@pytest.mark.parametrize("seed", SEEDS)
def test_unbounded_bounds_contain_the_exact_values(driver, seed):
    case = loop_case(seed, driver.incident_types)
    result = synthesize_spec(case.pomdp, case.spec, SETTINGS)
    exact = exact_loop_values(case, result.policy)
    lower, upper = Fraction(result.lower), Fraction(result.upper)
    assert lower <= exact.policy <= exact.optimum <= upper, (
        seed, case.kind, result.lower, float(exact.policy), float(exact.optimum), result.upper,
        float(exact.policy - lower), float(upper - exact.optimum))
    stats = result.stats.to_dict()
    assert stats["stopped"] == "depth cap" and stats["policy_value"]["stopped_by"] == "convergence", stats
    assert exact.branches == 4
    if case.kind == "rising":   # the margins alone keep these bounds on the right side
        assert exact.optimum - lower <= CLOSE and upper - exact.optimum <= CLOSE, (
            seed, float(exact.optimum - lower), float(upper - exact.optimum))
