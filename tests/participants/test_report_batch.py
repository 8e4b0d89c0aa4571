"""draw_report_batch draws the trust-report noise model of draw_report (report_matrix) for many
drivers at once."""

from __future__ import annotations

import numpy as np
import pytest

from trustroute.participants.driver_model import report_matrix
from trustroute.participants.driver_step import draw_report_batch


@pytest.mark.parametrize("theta", [0, 3, 6])
def test_batch_reports_follow_the_report_matrix(theta):
    draws = draw_report_batch(np.full(100_000, theta), 0.8, 7, np.random.default_rng(theta))
    frequencies = np.bincount(draws, minlength=7) / draws.size
    assert np.abs(frequencies - report_matrix(0.8, 7)[theta]).max() < 0.006


def test_perfect_reports_are_the_trust_and_take_one_uniform_each():
    rng, twin = np.random.default_rng(1), np.random.default_rng(1)
    theta = np.arange(7)
    assert (draw_report_batch(theta, 1.0, 7, rng) == theta).all()
    twin.random(7)
    assert rng.random() == twin.random()
