"""Exact evaluation on random driver models, including AV failures that move trust (succ/fail branches)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.policies.evaluation.test_plain import RandomStationaryPolicy, recursive_value
from trustroute.participants.driver_model import DriverModel
from trustroute.policies.evaluation.plain import evaluate
from trustroute.policies.evaluation.settings import EvaluationSettings
from trustroute.policies.logic.spec import load_spec
from trustroute.policies.model.trust_pomdp import build_pomdp
from trustroute.policies.routing.fallback import with_fallback
from trustroute.policies.routing.free import trust_free_policy


def random_driver(rng: np.random.Generator, incident_types: tuple[str, ...]) -> DriverModel:
    n = 7
    k = len(incident_types)
    takeover = rng.uniform(0, 1, size=(k, n))
    failure = rng.uniform(0, 0.5, size=(k, n))
    transition = rng.dirichlet(np.full(n, 0.7), size=(k, 2, 2, n))
    return DriverModel(trust_levels=tuple(range(1, n + 1)), incident_types=incident_types,
                       takeover_probability=takeover, failure_probability=failure,
                       trust_transition=transition, initial_belief=rng.dirichlet(np.ones(n)),
                       trust_free_takeover_probability={}, source_path="<random>")


@pytest.mark.slow
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), belief_rule=st.sampled_from(["bayes", "paper"]))
def test_evaluate_equals_plain_recursion_on_random_models(town, driver, seed, belief_rule):
    """φ1 (the baseline route takes 6 junctions); 4 branches per incident road keep trees small."""
    rng = np.random.default_rng(seed)
    pomdp = build_pomdp(town, random_driver(rng, driver.incident_types))
    assert pomdp.driver.depends_on_performance
    spec = load_spec("specs/phi1.toml", town)
    for policy, after, cap in ((trust_free_policy(town, spec), None, 6),
                               (RandomStationaryPolicy(town, rng), 2, 7)):
        wrapped = policy if after is None else with_fallback(policy, town, spec, after=after)
        evaluation = evaluate(pomdp, spec, wrapped,
                              EvaluationSettings(max_junctions=cap, belief_rule=belief_rule))
        satisfied, final_trust = recursive_value(pomdp, spec, wrapped, cap, belief_rule)
        assert evaluation.gap == 0.0
        assert abs(evaluation.lower - satisfied) <= 1e-10
        assert abs(evaluation.expected_final_trust - final_trust) <= 1e-8
        assert abs(sum(evaluation.end_mass.values()) - 1.0) <= 1e-10
