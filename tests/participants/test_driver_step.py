"""The driver step on arrays of drivers against the single synthetic driver and the model.

A batch of one draws exactly what the synthetic driver draws (same seed, same values, bit for
bit); a batch of many drivers at one (kind, incident, θ) draws (h, e, θ') with the model's joint
probability P(h, e, θ' | θ, inc) (chi-square at level 1e-4, rejecting the neighbouring trust row);
the tables follow incidents by name and drivers by kind.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.participants.test_synthetic_driver import chi_square_p
from tests.policies.model.test_trust_pomdp import random_model
from trustroute.participants.driver_model import PERFORMANCES, driver_model_from_dict, driver_tables
from trustroute.participants.driver_step import (
    draw_initial_trust,
    draw_performances,
    draw_reports,
    draw_rows,
    draw_step,
    draw_takeovers,
    draw_trust,
)
from trustroute.participants.synthetic_driver import SyntheticDriver
from trustroute.policies.model.trust_pomdp import build_pomdp

ALPHA = 1e-4


@pytest.fixture(scope="module")
def failing_model():
    return random_model(np.random.default_rng(12), 7, performance_dependent=True, sparse=False)


def test_a_batch_of_one_is_the_synthetic_driver(failing_model):
    """Batch-shaped calls ([1] arrays) and the synthetic driver, on one seed each: equal draws."""
    tables = failing_model.tables
    incidents = ["obstacle", "pedestrian", "truck", "none"] * 5
    for seed in range(20):
        person = SyntheticDriver(failing_model, np.random.default_rng(seed), report_accuracy=0.6)
        rng = np.random.default_rng(seed)
        kind = np.zeros(1, dtype=np.int64)
        theta = draw_initial_trust(tables, kind, rng)
        assert theta.shape == (1,) and theta[0] == person.trust_index
        for name in incidents:
            inc = np.array([failing_model.incident_index(name)])
            h, e, theta = draw_step(tables, kind, inc, theta, rng)
            took_over = person.decides_takeover(name)
            performance = person.performance(name)
            assert (bool(h[0]), PERFORMANCES[e[0]]) == (took_over, performance)
            assert failing_model.trust_levels[theta[0]] == person.move_trust(name, took_over, performance)
            report = draw_reports(theta, 0.6, 7, rng)
            assert report.shape == (1,) and failing_model.trust_levels[report[0]] == person.report_trust()


def test_one_step_of_many_drivers_follows_the_joint_probability(town, failing_model):
    pomdp = build_pomdp(town, failing_model)
    tables = failing_model.tables
    rng = np.random.default_rng(3)
    n = 20000
    for trust in (0, 3, 6):
        inc = failing_model.incident_index("pedestrian")
        h, e, after = draw_step(tables, np.zeros(n, dtype=np.int64), np.full(n, inc), np.full(n, trust), rng)
        counts = np.bincount((h * 2 + e) * 7 + after, minlength=28).astype(float)
        expected = pomdp.weighted_transition[inc, :, :, trust, :]        # P(h, e, θ' | θ, inc)
        assert chi_square_p(counts, expected.ravel()) > ALPHA
        wrong = trust + 1 if trust < 6 else trust - 1
        assert chi_square_p(counts, pomdp.weighted_transition[inc, :, :, wrong, :].ravel()) < ALPHA


def test_each_draw_takes_one_uniform_per_driver(failing_model):
    """n drivers take n uniforms per draw, in driver order: the same stream as n single calls."""
    tables = failing_model.tables
    n = 50
    kind, inc = np.zeros(n, dtype=np.int64), np.arange(n) % 4
    theta = np.arange(n) % 7
    h, e = np.arange(n) % 2, (np.arange(n) // 2) % 2
    for draw, args in ((draw_takeovers, (kind, inc, theta)), (draw_performances, (kind, inc, theta)),
                       (draw_trust, (kind, inc, h, e, theta))):
        batch = draw(tables, *args, np.random.default_rng(5))
        rng = np.random.default_rng(5)
        single = [draw(tables, *(int(a[i]) for a in args), rng) for i in range(n)]
        assert batch.tolist() == single
    cdf = tables.initial_cdf[np.zeros(n, dtype=np.int64)]
    rng = np.random.default_rng(6)
    assert draw_rows(cdf, np.random.default_rng(6)).tolist() == [draw_rows(cdf[0], rng) for _ in range(n)]


def test_tables_follow_incidents_by_name_and_drivers_by_kind(driver, failing_model):
    reordered = driver_model_from_dict({**failing_model.to_dict(),
                                        "incident_types": list(reversed(failing_model.incident_types))})
    tables = driver_tables([driver, reordered], driver.incident_types)
    for i, name in enumerate(driver.incident_types):
        assert np.array_equal(tables.takeover[0, i], driver.takeover_probability[driver.incident_index(name)])
        j = reordered.incident_index(name)
        assert np.array_equal(tables.takeover[1, i], reordered.takeover_probability[j])
        assert np.array_equal(tables.failure[1, i], reordered.failure_probability[j])
        assert np.array_equal(tables.transition_cdf[1, i], np.cumsum(reordered.trust_transition[j], axis=-1))
    assert np.array_equal(tables.initial_cdf[1], np.cumsum(reordered.initial_belief))
    # kind 0 (the packaged model) never fails; kind 1 does
    rng = np.random.default_rng(0)
    kind = np.repeat([0, 1], 3000)
    e = draw_performances(tables, kind, np.full(6000, driver.incident_index("obstacle")),
                          np.full(6000, 3), rng)
    assert e[:3000].sum() == 0 and e[3000:].sum() > 0
    with pytest.raises(ValueError, match="does not cover"):
        driver_tables([driver], ["obstacle", "flood"])
    with pytest.raises(ValueError, match="at least one"):
        driver_tables([])
    assert driver.tables is driver.tables
