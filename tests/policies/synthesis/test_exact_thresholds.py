"""Thresholds at values the float filter reaches: synthesis reaches τ and stays sound.

Cases (threshold_cases.py, seeded numpy Generators): random towns of 4-8 junctions, H = 2-8, a
belief atom's offset at c·b̂ of a reached belief, a sum of prior entries or k/7 under the uniform
prior, exactly or one ulp either side. Labels that floats cannot decide are decided exactly
(policies/belief/exact_labels.py), so [L, U] closes to τ = 1e-3, contains the optimum of an
exact-rational brute force written for the test, and `evaluate` values the returned policy at
least L.
"""

from __future__ import annotations

import functools

import pytest

import trustroute
from tests.policies.synthesis.threshold_cases import Outcome, random_case, reset_case, run_case
from trustroute.policies.synthesis.exact_search import exact_optimum

TAU = 1e-3
TOLERANCE = 1e-9
FAST_SEEDS = range(1000, 1012)
# Sized to what the sweep finds: with float labels never decided exactly (`close` cleared in
# policies/belief/exact_labels.py's truth), 12 of these 60 cases, of every kind, come out unsound.
SWEEP_SEEDS = range(60)


@pytest.fixture(scope="module")
def fast_outcome(driver):
    """outcome(seed): run_case of FAST_SEEDS' case, once per module: its exact-rational brute force
    (Outcome.optimum) is also the reference of the exhaustive-search test below."""
    @functools.cache
    def outcome(seed: int) -> Outcome:
        return run_case(random_case(seed, driver), tau=TAU)

    return outcome


@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_a_threshold_case_reaches_tau_and_is_sound(fast_outcome, seed):
    outcome = fast_outcome(seed)
    assert outcome.sound(TOLERANCE), outcome
    assert outcome.policy_worth_lower(TOLERANCE), outcome
    assert outcome.reaches(TAU), outcome


@pytest.mark.parametrize("seed", FAST_SEEDS)
def test_the_exhaustive_search_equals_the_exact_rational_brute_force(fast_outcome, seed):
    """policies/synthesis/exact_search.py (float beliefs, labels decided by exact_labels) and the
    test's own integer brute force agree on every threshold case."""
    outcome = fast_outcome(seed)
    case = outcome.case
    assert exact_optimum(case.pomdp, case.spec, case.horizon) == pytest.approx(outcome.optimum, abs=TOLERANCE)


def test_histories_of_two_words_at_one_belief_on_a_threshold_close_the_gap():
    """The reset case (threshold_cases.py): a standstill and a takeover at the obstacle reach one
    float belief under two words, and its label at C-D floats cannot decide. Both words lead to
    one exact belief, on which the label holds: the search reads it there as the vehicle does and
    closes [L, U] on the optimum, 1 (L less its rounding margin), and says it converged; it does
    not end early with the label read both ways ([0, 1], said to be stopped by a time limit it
    never reached)."""
    case = reset_case()
    result = trustroute.synthesize(case.spec, case.pomdp.town, case.pomdp.driver, horizon=case.horizon,
                                   tau=TAU, time_limit=30.0)
    outcome = run_case(case, tau=TAU, time_limit=30.0)
    assert outcome.optimum == 1.0 and outcome.sound(TOLERANCE) and outcome.policy_worth_lower(TOLERANCE)
    # L is the computed 1 widened down by the rounding margin (policies/synthesis/rounding.py)
    assert result.upper == 1.0 and 1.0 - 1e-12 < result.lower <= 1.0
    assert result.stopped_by == "convergence"
    assert [run.stopped for run in result.stats.runs] == ["convergence"]


@pytest.mark.slow
def test_threshold_cases_reach_tau_in_99_per_cent_of_runs_and_are_all_sound(driver):
    outcomes = [run_case(random_case(seed, driver), tau=TAU) for seed in SWEEP_SEEDS]
    assert [o for o in outcomes if not o.sound(TOLERANCE)] == []
    assert [o for o in outcomes if not o.policy_worth_lower(TOLERANCE)] == []
    reached = sum(o.reaches(TAU) for o in outcomes)
    assert reached >= 0.99 * len(outcomes), [o for o in outcomes if not o.reaches(TAU)]
