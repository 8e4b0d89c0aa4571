"""The time-budget scheduler: deadlines, shares of the limit and of the time left, fit checks."""

from __future__ import annotations

import time

import pytest

from trustroute.policies.synthesis.budget import TimeBudget


def test_deadline_keeps_the_reserve_and_shares_never_pass_it():
    budget = TimeBudget.start(100.0, reserve=0.04)
    assert budget.deadline == pytest.approx(budget.started + 96.0)
    assert budget.share(0.5) == budget.started + 0.5 * 100.0
    assert budget.share(0.99) == budget.deadline          # capped at the deadline
    assert not budget.expired()
    assert budget.fits(10.0) and not budget.fits(97.0)


def test_share_of_rest_and_an_earlier_deadline():
    budget = TimeBudget.start(100.0)
    until = budget.started + 10.0
    part = budget.share_of_rest(0.25, until)
    assert time.perf_counter() <= part <= until
    assert part == pytest.approx(budget.started + 2.5, abs=0.5)
    shorter = budget.ending(until)
    assert shorter.started == budget.started and shorter.limit == budget.limit
    assert shorter.deadline == until
    assert shorter.share(0.5) == until        # half the limit would end after the earlier deadline


def test_a_passed_deadline_is_expired_and_nothing_fits():
    budget = TimeBudget.until(time.perf_counter() - 1.0)
    assert budget.expired() and not budget.fits(0.0)
    assert budget.share_of_rest(0.5) <= time.perf_counter()        # no time left: now
    assert budget.elapsed() >= 0.0
