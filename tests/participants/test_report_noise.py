"""The trust-report noise model is defined once (driver_model): the synthetic driver's draws
follow `report_matrix`, which the fitting uses."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.participants.driver_model import draw_report, report_matrix
from trustroute.participants.synthetic_driver import SyntheticDriver


@pytest.mark.parametrize("accuracy", [0.0, 0.6, 0.8, 1.0])
def test_draws_follow_the_matrix(accuracy):
    k, n = 7, 20_000
    rng = np.random.default_rng(5)
    matrix = report_matrix(accuracy, k)
    np.testing.assert_allclose(matrix.sum(axis=1), 1.0)
    for theta in (0, 3, k - 1):
        counts = np.bincount([draw_report(theta, accuracy, k, rng) for _ in range(n)], minlength=k)
        # 5 standard errors of a binomial frequency (a false alarm has probability < 1e-6 per cell)
        tolerance = 5 * np.sqrt(matrix[theta] * (1 - matrix[theta]) / n) + 1e-12
        assert np.all(np.abs(counts / n - matrix[theta]) <= tolerance)


def test_the_synthetic_driver_reports_through_the_model(driver):
    a = SyntheticDriver(driver, np.random.default_rng(9), report_accuracy=0.7, initial_trust=4)
    rng = np.random.default_rng(9)
    theta = driver.trust_levels.index(4)  # reporting does not move trust
    assert [a.report_trust() for _ in range(200)] == [
        driver.trust_levels[draw_report(theta, 0.7, driver.n_trust, rng)] for _ in range(200)
    ]
