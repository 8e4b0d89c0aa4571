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
from trustroute.policies.synthesis.settings import SynthesisSettings

# Storm's iterative solvers stop at a relative precision of 1e-6.
STORM_PRECISION = 1e-6
# Where Storm's unfolding cannot complete (the unbounded objective), it stops after this many
# beliefs, at the same point on any machine, rather than at its time limit, which it overruns
# (2.8 s at a limit of 1 s). On these problems its lower bound is already 1.0 there, as after
# its time limit (about 80 000 beliefs on the random towns, 300 000 on the paper's).
UNFOLDED_BELIEFS = 20_000


def assert_overlap(storm, ours):
    assert storm.lower <= storm.upper + STORM_PRECISION
    assert max(storm.lower, ours.lower) <= min(storm.upper, ours.upper) + STORM_PRECISION, (storm, ours)


@pytest.mark.slow
@pytest.mark.parametrize("horizon", [10, None])
def test_storm_and_ours_overlap_on_phi1_with_the_trust_atom(pomdp, horizon):
    spec = load_spec("specs/phi1_trust.toml", pomdp.town)
    storm = run_storm(explicit_product(pomdp, spec, horizon), time_limit=2,
                      max_beliefs=UNFOLDED_BELIEFS if horizon is None else None)
    ours = joint_bounds(pomdp, spec, depth=6, horizon=horizon)
    assert_overlap(storm, ours)
    if horizon is None:
        assert storm.lower_beliefs <= UNFOLDED_BELIEFS and not storm.lower_complete
    else:   # our value is exact there: inside Storm's interval
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
    assert_overlap(run_storm(explicit_product(pomdp, spec, None), time_limit=1, max_beliefs=UNFOLDED_BELIEFS),
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


@pytest.mark.slow
@pytest.mark.parametrize("seed", [21, 22, 23])
def test_storm_overlaps_our_population_synthesis_on_the_lifted_product(driver, seed):
    """A driver population's type-aware model is a POMDP with hidden (type, trust): Storm unfolds
    its product with the trust-state atoms read on the trust level of that index."""
    from tests.policies.trust_state_synthesis.test_population import random_population_problem
    from trustroute.participants.driver_population import DriverPopulation, DriverType
    from trustroute.policies.belief.problem import problem
    from trustroute.policies.model.trust_pomdp import build_pomdp
    from trustroute.policies.synthesize_spec import synthesize_for_population

    rng = np.random.default_rng(seed)
    town, population, spec = random_population_problem(rng, driver, 2 + seed % 2)
    found = problem(town, population, spec)
    product = explicit_product(found.pomdp, found.spec, 3)
    storm = run_storm(product, time_limit=2)
    ours = synthesize_for_population(town, population, spec, "bayes",
                                     SynthesisSettings(horizon=3, time_limit=10))
    assert_overlap(storm, ours)
    if storm.lower_complete:   # Storm's unfolding is exact: our certified value lies in it
        assert storm.lower - STORM_PRECISION <= ours.lower <= storm.upper + STORM_PRECISION
    # Two copies of one type: the lifted product's value is the single model's (trust-state atoms
    # read the trust level of (type, trust), not the raw index).
    same = DriverPopulation(types=(DriverType("one", 0.5, population.types[0].model),
                                   DriverType("two", 0.5, population.types[0].model)))
    lifted = run_storm(explicit_product(problem(town, same, spec).pomdp, spec, 3), time_limit=2)
    single = run_storm(explicit_product(build_pomdp(town, population.types[0].model), spec, 3), time_limit=2)
    assert lifted.lower_complete and single.lower_complete
    assert lifted.lower == pytest.approx(single.lower, abs=STORM_PRECISION)


@pytest.mark.slow
def test_storm_agrees_with_our_population_value_on_phi1_trust_with_three_types(town):
    from trustroute.participants.driver_population import EXAMPLE_POPULATION_PATH, load_driver_population
    from trustroute.policies.belief.problem import problem
    from trustroute.policies.synthesize_spec import synthesize_for_population

    population = load_driver_population(EXAMPLE_POPULATION_PATH)
    spec = load_spec("specs/phi1_trust.toml", town)
    found = problem(town, population, spec)
    storm = run_storm(explicit_product(found.pomdp, found.spec, 10), time_limit=60)
    ours = synthesize_for_population(town, population, spec, "bayes",
                                     SynthesisSettings(horizon=10, time_limit=30))
    assert_overlap(storm, ours)
    assert storm.lower_complete          # Storm's unfolding is exact: our certified value is its value
    assert ours.lower == pytest.approx(storm.lower, rel=STORM_PRECISION)
