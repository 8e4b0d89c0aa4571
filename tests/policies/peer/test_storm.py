"""Storm's belief exploration against our search, on the same product POMDP (needs `[peer]`)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.policies.trust_specs import random_problem
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.peer.product_pomdp import explicit_product
from trustroute.policies.trust_state_synthesis.search import joint_bounds

pytest.importorskip("stormpy", reason="Storm tests need the optional extra: pip install -e '.[peer]'")

from trustroute.policies.peer.storm import run_storm  # noqa: E402

# Storm's iterative solvers stop at a relative precision of 1e-6.
STORM_PRECISION = 1e-6


def assert_overlap(storm, ours):
    assert storm.lower <= storm.upper + STORM_PRECISION
    assert max(storm.lower, ours.lower) <= min(storm.upper, ours.upper) + STORM_PRECISION, (storm, ours)


@pytest.mark.slow
@pytest.mark.parametrize("horizon", [10, None])
def test_storm_and_ours_overlap_on_phi1_with_the_trust_atom(pomdp, horizon):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    storm = run_storm(explicit_product(pomdp, spec, horizon), time_limit=2)
    ours = joint_bounds(pomdp, spec, depth=6, horizon=horizon)
    assert_overlap(storm, ours)
    if horizon is not None:   # our value is exact there: inside Storm's interval
        assert ours.gap <= 1e-11
        assert storm.lower - STORM_PRECISION <= ours.lower <= storm.upper + STORM_PRECISION


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_storm_brackets_our_exact_bounded_value_on_random_small_towns(driver, seed):
    pomdp, spec = random_problem(np.random.default_rng(seed), driver, "trust")
    ours = joint_bounds(pomdp, spec, depth=0, horizon=3)
    storm = run_storm(explicit_product(pomdp, spec, 3), time_limit=1)
    assert storm.lower_complete
    assert storm.lower - STORM_PRECISION <= ours.lower <= storm.upper + STORM_PRECISION
    assert_overlap(run_storm(explicit_product(pomdp, spec, None), time_limit=1),
                   joint_bounds(pomdp, spec, depth=3))


def test_no_reachable_goal_is_the_value_0_with_its_reason(pomdp, monkeypatch):
    import trustroute.policies.peer.storm as storm

    def storm_must_not_run(*_args, **_kwargs):
        raise AssertionError("Storm rejects a property whose label no state carries")

    monkeypatch.setattr(storm, "build_storm_model", storm_must_not_run)
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    product = explicit_product(pomdp, spec, 5)   # no satisfying route within 5 junctions
    assert not product.goal.any()
    result = run_storm(product, time_limit=1)
    assert (result.lower, result.upper) == (0.0, 0.0) and "no reachable state" in result.note
    assert joint_bounds(pomdp, spec, depth=5, horizon=5).upper <= 1e-11   # ours agrees


def test_a_storm_error_is_an_input_error(pomdp, monkeypatch):
    import stormpy.pomdp

    from trustroute.core.errors import InputError

    def refuse(*_args, **_kwargs):
        raise RuntimeError("InvalidPropertyException: something Storm cannot take\nmore lines")

    monkeypatch.setattr(stormpy.pomdp, "verify_with_belief_unfolding", refuse)
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    with pytest.raises(InputError, match="something Storm cannot take") as error:
        run_storm(explicit_product(pomdp, spec, 6), time_limit=1)
    assert "\n" not in error.value.one_line()
