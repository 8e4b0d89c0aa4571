"""Statistics against brute force: exact McNemar and Wilcoxon by enumeration, bootstrap coverage."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from trustroute.analysis.statistics import bootstrap_ci, mcnemar_exact, wilcoxon_paired


def _binomial_two_sided(k: int, n: int) -> float:
    probs = [math.comb(n, i) / 2**n for i in range(n + 1)]
    return min(1.0, sum(p for p in probs if p <= probs[k] * (1 + 1e-7)))


@pytest.mark.parametrize("seed", range(6))
def test_mcnemar_matches_enumeration(seed):
    rng = np.random.default_rng(seed)
    a = rng.random(30) < 0.7
    b = rng.random(30) < 0.5
    result = mcnemar_exact(a, b)
    only_a, only_b = int(np.sum(a & ~b)), int(np.sum(~a & b))
    assert (result.only_first, result.only_second) == (only_a, only_b)
    assert result.p_value == pytest.approx(_binomial_two_sided(only_a, only_a + only_b), rel=1e-9)


def test_mcnemar_no_discordant_pairs():
    same = np.array([True, False, True])
    assert mcnemar_exact(same, same).p_value == 1.0


def _wilcoxon_exact(x: np.ndarray, y: np.ndarray) -> float:
    d = x - y
    d = d[d != 0]
    ranks = np.argsort(np.argsort(np.abs(d))) + 1.0  # no ties in the test data
    observed = min(ranks[d > 0].sum(), ranks[d < 0].sum())
    total = 0
    count = 0
    for signs in itertools.product((0, 1), repeat=d.size):
        plus = sum(r for r, s in zip(ranks, signs, strict=True) if s)
        count += min(plus, ranks.sum() - plus) <= observed + 1e-9
        total += 1
    return count / total


@pytest.mark.parametrize("seed", range(4))
def test_wilcoxon_matches_enumeration(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(0.5, 1, 10)
    y = rng.normal(0, 1, 10)
    result = wilcoxon_paired(x, y)
    assert result.p_value == pytest.approx(_wilcoxon_exact(x, y), rel=1e-9)


def test_wilcoxon_all_equal_and_nan_pairs():
    assert wilcoxon_paired(np.ones(5), np.ones(5)).p_value == 1.0
    x = np.array([1.0, 2.0, np.nan, 4.0, 5.0, 7.0])
    y = np.array([0.0, 1.5, 3.0, 1.0, 2.0, 1.0])
    assert wilcoxon_paired(x, y).pairs == 5


def test_bootstrap_is_seeded_and_covers_the_mean():
    rng = np.random.default_rng(0)
    values = rng.random(50) < 0.8
    assert bootstrap_ci(values, np.random.default_rng(1), 2000) == bootstrap_ci(
        values, np.random.default_rng(1), 2000
    )
    hits = 0
    trials = 150
    for _ in range(trials):
        sample = (rng.random(80) < 0.8).astype(float)
        low, high = bootstrap_ci(sample, rng, 1000)
        hits += low <= 0.8 <= high
    # percentile bootstrap of a proportion at n=80: coverage close to 0.95 (binomial noise of 150 trials)
    assert 0.86 <= hits / trials <= 0.995


def test_bootstrap_edge_cases():
    assert all(math.isnan(v) for v in bootstrap_ci(np.array([]), np.random.default_rng(0)))
    assert bootstrap_ci(np.ones(10), np.random.default_rng(0), 100) == (1.0, 1.0)
    big = np.random.default_rng(0).random(100_000)
    low, high = bootstrap_ci(big, np.random.default_rng(0), 200)
    assert low < big.mean() < high and high - low < 0.01
