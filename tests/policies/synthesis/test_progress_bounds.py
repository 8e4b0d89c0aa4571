"""What a synthesis tells its progress after each round are the bounds its result will show so far:
never an L below one already reached (a new search starting from 0), never a U of another
probability (a search within fewer junctions than the unbounded problem asked), and no L at all
before there is one to show (the trust-state synthesis' L is a valued policy's)."""

from __future__ import annotations

import itertools

from trustroute.policies.logic.spec import load_spec
from trustroute.policies.synthesis.belief_synthesis import synthesize
from trustroute.policies.synthesis.settings import SynthesisSettings
from trustroute.policies.trust_state_synthesis.synthesis import synthesize_joint

# a fixed amount of work (policies/work_clock.py): the same rounds on any machine
UNBOUNDED = SynthesisSettings(horizon=None, work_limit=1_000_000, time_limit=900.0)
ROUNDING = 1e-9   # the result's bounds are the computed ones widened outward (rounding.py)


def _told(synthesis, pomdp, spec) -> tuple[list[tuple[float | None, float]], object]:
    told: list[tuple[float | None, float]] = []
    result = synthesis(pomdp, spec, UNBOUNDED, on_iteration=lambda lower, upper: told.append((lower, upper)))
    return told, result


def test_unbounded_belief_synthesis_tells_the_best_bounds_so_far(pomdp):
    told, result = _told(synthesize, pomdp, load_spec("specs/phi1.toml", pomdp.town))
    assert len({run.horizon for run in result.stats.runs}) > 1, "several searches, bounded and not"
    lowers = [lower for lower, _ in told]
    uppers = [upper for _, upper in told]
    assert all(lower is not None for lower in lowers)
    assert lowers == sorted(lowers) and uppers == sorted(uppers, reverse=True), told
    assert max(lowers) > 0.9 and abs(lowers[-1] - result.lower) <= ROUNDING, (told[-1], result.lower)
    assert min(uppers) >= result.upper - ROUNDING, (told, result.upper)


def test_trust_state_synthesis_tells_no_lower_bound_before_a_policy_is_valued(pomdp):
    told, result = _told(synthesize_joint, pomdp, load_spec("specs/phi1_trust.toml", pomdp.town))
    assert result.lower > 0.5
    assert told[0][0] is None, told   # the unbounded U comes first: no policy valued yet
    valued = [lower for lower, _ in told if lower is not None]
    assert valued and valued == sorted(valued) and abs(valued[-1] - result.lower) <= ROUNDING, told
    assert 0.0 not in valued


def _robust_told(problem) -> tuple[list[tuple[float | None, float]], object]:
    """What a robust population synthesis of (town, population, spec) tells its progress, and its
    result; its runs (the Bayes objective's, each candidate prior's) bound other probabilities."""
    from trustroute.policies.synthesize_spec import synthesize_for_population

    town, population, spec = problem
    told: list[tuple[float | None, float]] = []
    made = synthesize_for_population(town, population, spec, "robust",
                                     SynthesisSettings(horizon=3, time_limit=10, grid_points=3),
                                     on_iteration=lambda lower, upper: told.append((lower, upper)))
    return told, made


def _assert_robust_bounds(told, made) -> None:
    """Every report is a bound of the robust value the result will show: no L above it (the Bayes
    objective's L is the prior-weighted value, above the worst type's), no U below it."""
    assert told and made.lower < made.bayes_lower, "the robust value differs from the Bayes one"
    valued = [lower for lower, _ in told if lower is not None]
    uppers = [upper for _, upper in told]
    assert all(lower <= made.lower + ROUNDING for lower in valued), (told, made.lower)
    assert valued == sorted(valued), told
    # the Bayes run's U as computed; the bound the candidates are told is rounded outward
    assert all(later <= earlier + ROUNDING for earlier, later in itertools.pairwise(uppers)), told
    assert min(uppers) >= made.upper - ROUNDING, (told, made.upper)


def test_a_robust_belief_population_synthesis_tells_the_robust_bounds():
    import numpy as np

    from tests.policies.synthesis.test_population_synthesis import population_of, small_spec
    from tests.policies.synthesis.test_synthesis_random import random_town

    rng = np.random.default_rng(11)
    town = random_town(rng)
    population = population_of(rng, 2)
    _assert_robust_bounds(*_robust_told((town, population, small_spec(rng, town, population, False))))


def test_a_robust_trust_state_population_synthesis_tells_the_robust_bounds(driver):
    import numpy as np

    from tests.policies.trust_state_synthesis.test_population import random_population_problem

    rng = np.random.default_rng(3)
    _assert_robust_bounds(*_robust_told(random_population_problem(rng, driver, 3)))
