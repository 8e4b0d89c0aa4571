"""The synthetic driver's statistics against its driver model (fixed seeds, tests that can fail).

Each frequency is checked with a binomial or chi-square test at level 1e-4; each check also
asserts that the same data reject a nearby wrong model, so the tests have power.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tests.policies.model.test_trust_pomdp import random_model
from trustroute.participants.synthetic_driver import SyntheticDriver

ALPHA = 1e-4


def chi_square_p(counts: np.ndarray, probabilities: np.ndarray) -> float:
    """Chi-square goodness of fit, pooling cells with expected count < 5 into one."""
    expected = probabilities * counts.sum()
    small = expected < 5
    if small.any():
        counts = np.append(counts[~small], counts[small].sum())
        expected = np.append(expected[~small], expected[small].sum())
    keep = expected > 0
    if (counts[~keep] > 0).any():
        return 0.0                                   # an impossible outcome happened
    if keep.sum() < 2:
        return 1.0
    return float(stats.chisquare(counts[keep], expected[keep] * counts[keep].sum()
                                 / expected[keep].sum()).pvalue)


@pytest.fixture(scope="module")
def failing_model(town):
    """A random model whose dynamics depend on the AV's performance."""
    return random_model(np.random.default_rng(11), 7, performance_dependent=True, sparse=False)


@pytest.mark.parametrize("incident", ["obstacle", "pedestrian", "truck"])
@pytest.mark.parametrize("trust", [1, 4, 7])
def test_takeover_frequency(driver, incident, trust):
    rng = np.random.default_rng(100 + trust)
    n = 4000
    person = SyntheticDriver(driver, rng, initial_trust=trust)
    takeovers = sum(person.decides_takeover(incident) for _ in range(n))
    assert person.trust == trust                   # deciding does not move trust
    p = driver.takeover_probability[driver.incident_index(incident), trust - 1]
    assert stats.binomtest(takeovers, n, p).pvalue > ALPHA
    wrong = min(max(p + 0.05 if p < 0.5 else p - 0.05, 0.0), 1.0)
    assert stats.binomtest(takeovers, n, wrong).pvalue < ALPHA


def test_no_incident_never_takes_over(driver):
    person = SyntheticDriver(driver, np.random.default_rng(0), initial_trust=1)
    assert not any(person.decides_takeover("none") for _ in range(500))


@pytest.mark.parametrize("incident, took_over, trust", [("obstacle", True, 2), ("obstacle", False, 5),
                                                        ("pedestrian", True, 4), ("truck", False, 7)])
def test_trust_transition_frequencies(driver, incident, took_over, trust):
    rng = np.random.default_rng(7 + trust)
    n = 5000
    counts = np.zeros(7)
    for _ in range(n):
        person = SyntheticDriver(driver, rng, initial_trust=trust)
        counts[person.move_trust(incident, took_over) - 1] += 1
    row = driver.trust_transition[driver.incident_index(incident), int(took_over), 0, trust - 1]
    assert chi_square_p(counts, row) > ALPHA
    other = driver.trust_transition[driver.incident_index(incident), int(not took_over), 0, trust - 1]
    assert chi_square_p(counts, other) < ALPHA


def test_trust_transition_depends_on_performance(failing_model):
    rng = np.random.default_rng(5)
    n = 5000
    for performance, e in (("succ", 0), ("fail", 1)):
        counts = np.zeros(7)
        for _ in range(n):
            person = SyntheticDriver(failing_model, rng, initial_trust=3)
            counts[person.move_trust("truck", True, performance) - 1] += 1
        i = failing_model.incident_index("truck")
        assert chi_square_p(counts, failing_model.trust_transition[i, 1, e, 2]) > ALPHA
        assert chi_square_p(counts, failing_model.trust_transition[i, 1, 1 - e, 2]) < ALPHA


def test_performance_frequency(failing_model, driver):
    rng = np.random.default_rng(9)
    n = 4000
    person = SyntheticDriver(failing_model, rng, initial_trust=2)
    fails = sum(person.performance("obstacle") == "fail" for _ in range(n))
    p = failing_model.failure_probability[failing_model.incident_index("obstacle"), 1]
    assert stats.binomtest(fails, n, p).pvalue > ALPHA
    assert stats.binomtest(fails, n, min(p + 0.05, 1.0)).pvalue < ALPHA
    nominal = SyntheticDriver(driver, rng)
    assert {nominal.performance("obstacle") for _ in range(200)} == {"succ"}


@pytest.mark.parametrize("accuracy", [0.8, 0.5])
def test_report_accuracy_in_the_middle(driver, accuracy):
    rng = np.random.default_rng(21)
    n = 6000
    person = SyntheticDriver(driver, rng, report_accuracy=accuracy, initial_trust=4)
    counts = np.zeros(7)
    for _ in range(n):
        counts[person.report_trust() - 1] += 1
    expected = np.zeros(7)
    expected[3] = accuracy
    expected[2] = expected[4] = (1 - accuracy) / 2
    assert chi_square_p(counts, expected) > ALPHA
    wrong = expected.copy()
    wrong[3] += 0.03
    wrong[2] -= 0.03
    assert chi_square_p(counts, wrong) < ALPHA
    assert person.trust == 4                       # reporting does not move trust


@pytest.mark.parametrize("trust, neighbour", [(1, 2), (7, 6)])
def test_report_is_clipped_at_the_ends(driver, trust, neighbour):
    rng = np.random.default_rng(trust)
    n = 6000
    person = SyntheticDriver(driver, rng, report_accuracy=0.8, initial_trust=trust)
    reports = [person.report_trust() for _ in range(n)]
    assert set(reports) <= {trust, neighbour}
    # the wrong report goes off the scale half of the time and is clipped back to the truth
    assert stats.binomtest(reports.count(trust), n, 0.9).pvalue > ALPHA


def test_initial_trust_is_drawn_from_the_model(failing_model):
    rng = np.random.default_rng(2)
    n = 6000
    counts = np.zeros(7)
    for _ in range(n):
        counts[SyntheticDriver(failing_model, rng).trust - 1] += 1
    assert chi_square_p(counts, failing_model.initial_belief) > ALPHA
    assert chi_square_p(counts, np.full(7, 1 / 7)) < ALPHA


def test_same_seed_same_episode(driver):
    def episode(seed: int) -> list:
        rng = np.random.default_rng(seed)
        person = SyntheticDriver(driver, rng)
        out = [person.trust]
        for incident in ["obstacle", "pedestrian", "truck", "none"] * 5:
            h = person.decides_takeover(incident)
            e = person.performance(incident)
            out += [h, e, person.move_trust(incident, h, e), person.report_trust()]
        return out

    assert episode(4) == episode(4)
    assert episode(4) != episode(5)


def test_bad_arguments(driver):
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="report_accuracy"):
        SyntheticDriver(driver, rng, report_accuracy=1.5)
    with pytest.raises(ValueError, match="initial trust"):
        SyntheticDriver(driver, rng, initial_trust=8)
    person = SyntheticDriver(driver, rng)
    with pytest.raises(ValueError, match="not covered"):
        person.decides_takeover("cow")
    with pytest.raises(ValueError, match="performance"):
        person.move_trust("truck", False, "great")


def test_trust_moves_draw_as_the_inverse_cdf_of_the_row():
    """move_trust (cumulative rows cached per model, bisect) draws the very index the direct
    inverse CDF of the transition row gives with the same generator state."""
    model = random_model(np.random.default_rng(11), 7, performance_dependent=True, sparse=False)
    driver = SyntheticDriver(model, np.random.default_rng(5), initial_trust=model.trust_levels[2])
    mirror = np.random.default_rng(5)
    theta = 2
    for step in range(400):
        incident = model.incident_types[step % len(model.incident_types)]
        took_over, performance = bool(step % 3 == 0), ("succ", "fail")[step % 2]
        e = ("succ", "fail").index(performance)
        row = model.trust_transition[model.incident_index(incident), int(took_over), e, theta]
        cdf = np.cumsum(row)
        theta = min(int(np.searchsorted(cdf, mirror.random() * cdf[-1], side="right")), cdf.size - 1)
        assert driver.move_trust(incident, took_over, performance) == model.trust_levels[theta]
