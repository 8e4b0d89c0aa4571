"""Statistics of a study: bootstrap confidence intervals and paired tests.

- `bootstrap_ci`: percentile bootstrap of a statistic (the mean by default) with a Generator
  passed in, resampling in chunks so memory stays bounded for large studies;
- `mcnemar_exact`: McNemar's test on paired binary outcomes (satisfied with condition A vs B
  for the same participant and spec), exact: two-sided binomial test of the discordant pairs;
- `wilcoxon_paired`: Wilcoxon signed-rank test on paired values (a participant's trust under A
  vs B), via scipy; p = 1 when every difference is zero.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

DEFAULT_RESAMPLES = 10_000
DEFAULT_LEVEL = 0.95
_CHUNK_CELLS = 4_000_000  # resample indices held in memory at once


def bootstrap_ci(
    values: np.ndarray,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = DEFAULT_LEVEL,
    statistic: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[float, float]:
    """Percentile bootstrap interval of `statistic` (row-wise over resamples [B, n]; default mean).

    NaN values are dropped first; an empty sample gives (nan, nan).
    """
    data = np.asarray(values, dtype=float)
    data = data[~np.isnan(data)]
    n = data.size
    if n == 0:
        return math.nan, math.nan
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    statistic = statistic or (lambda sample: sample.mean(axis=1))
    chunk = max(1, _CHUNK_CELLS // n)
    estimates = []
    for start in range(0, resamples, chunk):
        size = min(chunk, resamples - start)
        estimates.append(statistic(data[rng.integers(0, n, size=(size, n))]))
    estimates = np.concatenate(estimates)
    alpha = (1 - level) / 2
    low, high = np.quantile(estimates, [alpha, 1 - alpha])
    return float(low), float(high)


@dataclass(frozen=True)
class McNemar:
    pairs: int
    only_first: int  # pairs where A succeeded and B failed
    only_second: int  # pairs where B succeeded and A failed
    p_value: float


def mcnemar_exact(first: np.ndarray, second: np.ndarray) -> McNemar:
    """Exact McNemar test of paired booleans: two-sided binomial test of b vs c at 1/2."""
    a = np.asarray(first, dtype=bool)
    b = np.asarray(second, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    only_first = int(np.sum(a & ~b))
    only_second = int(np.sum(~a & b))
    discordant = only_first + only_second
    p = 1.0 if discordant == 0 else float(stats.binomtest(only_first, discordant, 0.5).pvalue)
    return McNemar(pairs=int(a.size), only_first=only_first, only_second=only_second, p_value=p)


@dataclass(frozen=True)
class Wilcoxon:
    pairs: int
    nonzero: int
    statistic: float
    p_value: float
    median_difference: float


def wilcoxon_paired(first: np.ndarray, second: np.ndarray) -> Wilcoxon:
    """Wilcoxon signed-rank test (two-sided) of paired values; pairs with a NaN are dropped."""
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    keep = ~(np.isnan(a) | np.isnan(b))
    a, b = a[keep], b[keep]
    difference = a - b
    nonzero = int(np.count_nonzero(difference))
    median = float(np.median(difference)) if difference.size else math.nan
    if nonzero == 0:
        return Wilcoxon(
            pairs=int(a.size), nonzero=0, statistic=math.nan, p_value=1.0, median_difference=median
        )
    result = stats.wilcoxon(a, b, zero_method="wilcox", alternative="two-sided")
    return Wilcoxon(
        pairs=int(a.size),
        nonzero=nonzero,
        statistic=float(result.statistic),
        p_value=float(result.pvalue),
        median_difference=median,
    )
