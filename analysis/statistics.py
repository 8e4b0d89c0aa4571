"""Statistics of a study: intervals for rates, paired effect sizes and tests.

Intervals for a rate k/n (`rate_interval`): exact Clopper–Pearson and Wilson score, both from
`scipy.stats.binomtest(...).proportion_ci`.

Paired binary outcomes (satisfied under condition A and under B for the same participant and spec)
give a 2x2 table with discordant counts b (only A) and c (only B):
- `mcnemar_exact`: McNemar's test, the two-sided binomial test of b against b + c at 1/2;
- `paired_risk_difference`: (b - c) / n with Newcombe's hybrid score interval for paired
  proportions (Newcombe 1998, method 10: Wilson intervals of both margins and the phi correlation);
- `conditional_odds_ratio`: b / c with the exact interval from the Clopper–Pearson interval of
  b / (b + c) (the conditional binomial likelihood of the matched pairs); when every discordant pair
  favours one side (b or c is 0, the conditional MLE is 0 or infinite) the estimate is the
  median-unbiased one (`exact_odds_ratio`) and the reason is written in `Estimate.note`.

Paired values (a participant's trust under A and under B):
- `sign_test`: the exact two-sided sign test, the binomial test of the positive differences among
  the nonzero ones at 1/2 (zero differences are ties, dropped); the "all specs" satisfaction test;
- `wilcoxon_paired`: Wilcoxon signed-rank test, two-sided; p = 1 when every difference is zero.
  Up to `WILCOXON_EXACT_PAIRS` nonzero differences the p-value is exact, with ties and zeros: the
  null distribution of the rank sum over every sign flip (`sign_flip_p`, dynamic programming over
  the doubled midranks; scipy's permutation test and its exact test give the same p). scipy
  itself is exact only without ties or zeros (or for at most 13 pairs) and otherwise uses the
  normal approximation, which on 21 participants' trust reports is off by about 0.01. Beyond the
  limit the p-value is scipy's normal approximation (tie-corrected), and `Wilcoxon.method` says
  so (`WILCOXON_APPROXIMATE`), for the tables to mark it;
- `mean_difference`: the mean paired difference with a BCa bootstrap interval over participants
  from `scipy.stats.bootstrap` (the Generator passed in drives the resampling); `Estimate.method`
  names the interval given: BCa, or the percentile interval where BCa is undefined (differences
  equal up to rounding, whose leave-one-out means are one float: scipy's acceleration is 0/0, nan),
  or "degenerate" where every difference is the same (no resampling: the interval is the point);
- `bootstrap_ci`: percentile bootstrap of a mean (scipy.stats.bootstrap), for single cells;
- `keyed_rng`: the Generator of one resampling, from the analysis seed and a key naming what is
  resampled, so the same data and comparison get the same interval wherever and whenever computed.

Repeated-measures models (conditional logit, mixed model) are in analysis/repeated_measures.py.

Multiplicity: a study with k conditions compares every pair of them; `holm` adjusts the p-values of
one family (one test, one spec, every pair) by Holm's step-down method, which controls the
family-wise error rate under any dependence between the tests.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

DEFAULT_RESAMPLES = 10_000
DEFAULT_LEVEL = 0.95
RATE_METHODS = ("exact", "wilson")


# -- rates ---------------------------------------------------------------------------------------


def rate_interval(k: int, n: int, level: float = DEFAULT_LEVEL, method: str = "exact") -> tuple[float, float]:
    """Two-sided interval of the rate k/n: "exact" (Clopper–Pearson) or "wilson"; (nan, nan) if n = 0."""
    if method not in RATE_METHODS:
        raise ValueError(f"unknown interval method {method!r}; use one of {', '.join(RATE_METHODS)}")
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    if n == 0:
        return math.nan, math.nan
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    interval = stats.binomtest(int(k), int(n)).proportion_ci(confidence_level=level, method=method)
    return float(interval.low), float(interval.high)


# -- paired binary outcomes -----------------------------------------------------------------------


@dataclass(frozen=True)
class PairedTable:
    """The 2x2 table of paired booleans: both, only the first, only the second, neither."""

    both: int
    only_first: int
    only_second: int
    neither: int

    @property
    def pairs(self) -> int:
        return self.both + self.only_first + self.only_second + self.neither


def paired_table(first: np.ndarray, second: np.ndarray) -> PairedTable:
    a = np.asarray(first, dtype=bool)
    b = np.asarray(second, dtype=bool)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    return PairedTable(int(np.sum(a & b)), int(np.sum(a & ~b)), int(np.sum(~a & b)), int(np.sum(~a & ~b)))


@dataclass(frozen=True)
class McNemar:
    pairs: int
    only_first: int  # pairs where A succeeded and B failed
    only_second: int  # pairs where B succeeded and A failed
    p_value: float


def holm(p_values: list[float | None]) -> list[float | None]:
    """Holm-adjusted p-values of one family, in the given order (None and nan stay None and are not
    counted): the i-th smallest of m becomes max over j <= i of min(1, (m - j + 1) p_(j))."""
    present = [(p, i) for i, p in enumerate(p_values) if p is not None and not math.isnan(p)]
    out: list[float | None] = [None] * len(p_values)
    running, m = 0.0, len(present)
    for rank, (p, i) in enumerate(sorted(present)):
        running = max(running, min(1.0, (m - rank) * p))
        out[i] = running
    return out


def binomial_half_p(first: int, second: int) -> float:
    """Two-sided exact p-value of `first` against `second` under equal chances: the binomial test
    of `first` among `first + second` at 1/2 (1 when both are 0). McNemar's test, the sign test and
    the matched pairs' exact test are all this one."""
    total = int(first) + int(second)
    return 1.0 if total == 0 else float(stats.binomtest(int(first), total, 0.5).pvalue)


def mcnemar_exact(first: np.ndarray, second: np.ndarray) -> McNemar:
    """Exact McNemar test of paired booleans: two-sided binomial test of b vs c at 1/2."""
    table = paired_table(first, second)
    p = binomial_half_p(table.only_first, table.only_second)
    return McNemar(pairs=table.pairs, only_first=table.only_first, only_second=table.only_second, p_value=p)


@dataclass(frozen=True)
class SignTest:
    """The exact sign test of paired differences: how many are above zero, below it and zero."""

    positive: int
    negative: int
    zero: int
    p_value: float


def sign_test(differences: np.ndarray) -> SignTest:
    """Exact two-sided sign test of paired differences (NaN dropped): the binomial test of the
    positive ones among the nonzero ones at 1/2; zero differences are ties and are dropped, and
    with no nonzero difference p = 1."""
    values = np.asarray(differences, dtype=float)
    values = values[~np.isnan(values)]
    positive, negative = int(np.sum(values > 0)), int(np.sum(values < 0))
    return SignTest(positive, negative, int(values.size) - positive - negative,
                    binomial_half_p(positive, negative))


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its interval (nan where undefined); `note` says why it is what it is
    when it is not the plain estimate (e.g. median-unbiased on separated data)."""

    value: float
    low: float
    high: float
    note: str = ""
    # the interval's method where one column holds intervals of several: `mean_difference`'s
    # BOOTSTRAP_*, `paired_risk_difference`'s NEWCOMBE ("" where there is no interval)
    method: str = ""


NEWCOMBE = "Newcombe"   # the method of `paired_risk_difference`'s interval (Estimate.method)


def paired_risk_difference(table: PairedTable, level: float = DEFAULT_LEVEL) -> Estimate:
    """P(A) - P(B) = (b - c) / n with Newcombe's method-10 interval for paired proportions."""
    n = table.pairs
    if n == 0:
        return Estimate(math.nan, math.nan, math.nan)
    a, b, c, d = table.both, table.only_first, table.only_second, table.neither
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = rate_interval(a + b, n, level, "wilson")
    l2, u2 = rate_interval(a + c, n, level, "wilson")
    denominator = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(denominator) if denominator > 0 else 0.0
    difference = p1 - p2
    lower = (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2
    upper = (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2
    return Estimate(
        difference,
        max(-1.0, difference - math.sqrt(max(lower, 0.0))),
        min(1.0, difference + math.sqrt(max(upper, 0.0))),
        method=NEWCOMBE,
    )


def _odds(p: float) -> float:
    return math.inf if p >= 1.0 else p / (1.0 - p)


def median_unbiased_proportion(k: int, n: int) -> float:
    """The median-unbiased estimate of a binomial proportion from k of n (n > 0): the midpoint on the
    log-odds scale of the two one-sided 50 % limits (Hirji's definition), the one finite limit when k
    is 0 or n (then P(X >= n | p) = p^n = 1/2 gives p = 2^(-1/n))."""
    if not 0 <= k <= n or n == 0:
        raise ValueError(f"need 0 <= k <= n and n > 0, got k={k}, n={n}")
    low = 0.0 if k == 0 else float(stats.beta.ppf(0.5, k, n - k + 1))  # P(X >= k | low) = 1/2
    high = 1.0 if k == n else float(stats.beta.ppf(0.5, k + 1, n - k))  # P(X <= k | high) = 1/2
    if k == 0:
        return high
    if k == n:
        return low
    midpoint = (math.log(_odds(low)) + math.log(_odds(high))) / 2
    return 1.0 / (1.0 + math.exp(-midpoint))


TOO_FEW = "too few observations"   # why an estimate or a test is missing: not enough data to compute it
NO_DISCORDANCE = "no discordant pair (equal outcomes under both): no odds ratio is estimable"


def exact_odds_ratio(b: int, c: int, level: float = DEFAULT_LEVEL) -> Estimate:
    """The odds ratio of matched pairs from the binomial of b among the b + c discordant pairs:
    the median-unbiased estimate with the exact interval of the Clopper–Pearson interval of
    b / (b + c); finite estimate even when b or c is 0 (where b / c is 0 or infinite)."""
    if b + c == 0:
        return Estimate(math.nan, math.nan, math.nan, NO_DISCORDANCE)
    low, high = rate_interval(b, b + c, level, "exact")
    return Estimate(_odds(median_unbiased_proportion(b, b + c)), _odds(low), _odds(high))


def all_discordant_favour(pairs: int, side: str) -> str:
    """"all 3 discordant pairs favour A", or "the one discordant pair favours A"."""
    if pairs == 1:
        return f"the one discordant pair favours {side}"
    return f"all {pairs} discordant pairs favour {side}"


def one_sided_reason(b: int, c: int, first: str = "A", second: str = "B") -> str:
    """Why a paired odds ratio is median-unbiased: every discordant pair favours one side."""
    side = first if c == 0 else second
    return (f"{all_discordant_favour(b + c, side)} (b / c = {'inf' if c == 0 else '0'}): "
            f"median-unbiased OR, exact CI open {'above' if c == 0 else 'below'}")


def conditional_odds_ratio(
    table: PairedTable, level: float = DEFAULT_LEVEL, sides: tuple[str, str] = ("A", "B")
) -> Estimate:
    """b / c with the exact interval from the Clopper–Pearson interval of b / (b + c).

    No discordant pair: (nan, nan, nan) with the reason. When b or c is 0 (separation) b / c says
    nothing, so the estimate is the median-unbiased one of `exact_odds_ratio`, with the reason in
    the note; the interval is then unbounded on one side (upper bound inf, or lower bound 0).
    `sides` name the first and the second sample in the note."""
    b, c = table.only_first, table.only_second
    if b + c == 0:
        return Estimate(math.nan, math.nan, math.nan, NO_DISCORDANCE)
    low, high = rate_interval(b, b + c, level, "exact")
    if b == 0 or c == 0:
        exact = exact_odds_ratio(b, c, level)
        return replace(exact, note=one_sided_reason(b, c, *sides))
    return Estimate(b / c, _odds(low), _odds(high))


# -- paired values --------------------------------------------------------------------------------


WILCOXON_EXACT = "exact"
WILCOXON_APPROXIMATE = "normal approximation"


@dataclass(frozen=True)
class Wilcoxon:
    pairs: int
    nonzero: int
    statistic: float
    p_value: float
    median_difference: float
    method: str = WILCOXON_EXACT   # how p_value was computed: WILCOXON_EXACT or WILCOXON_APPROXIMATE


def _drop_nan_pairs(first: np.ndarray, second: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    keep = ~(np.isnan(a) | np.isnan(b))
    return a[keep], b[keep]


# the exact null distribution costs about m^3 / 2 additions for m nonzero differences: 40 ms at
# 300, 0.3 s at 500; beyond, the normal approximation (then within about 1e-3 of the exact p)
WILCOXON_EXACT_PAIRS = 300


def sign_flip_p(difference: np.ndarray) -> float:
    """Two-sided p-value of Wilcoxon's signed-rank sum W+ over every sign flip of the nonzero
    differences (midranks for ties), exactly: W+ doubled is an integer sum of doubled midranks,
    whose distribution over the 2^m equally likely flips is built one rank at a time (as
    probabilities, so no count overflows). p = 2 min(P(W+ >= w), P(W+ <= w)), at most 1 (scipy's
    permutation test's two-sided rule; flipping a zero changes nothing, so zeros drop out)."""
    nonzero = difference[difference != 0]
    doubled = np.rint(2.0 * stats.rankdata(np.abs(nonzero))).astype(np.int64)
    probability = np.zeros(int(doubled.sum()) + 1)
    probability[0] = 1.0
    top = 0   # the largest doubled sum reachable so far
    for rank in doubled:
        top += int(rank)
        probability[rank:top + 1] = 0.5 * (probability[rank:top + 1] + probability[:top + 1 - rank])
        probability[:rank] *= 0.5   # below rank only the unflipped term contributes
    observed = int(doubled[nonzero > 0].sum())
    greater = float(probability[observed:].sum())
    less = float(probability[:observed + 1].sum())
    return min(1.0, 2.0 * min(greater, less))


def wilcoxon_paired(first: np.ndarray, second: np.ndarray) -> Wilcoxon:
    """Wilcoxon signed-rank test (two-sided) of paired values; pairs with a NaN are dropped, zero
    differences are dropped from the ranks (Wilcoxon's rule). The statistic is min(W+, W-)."""
    a, b = _drop_nan_pairs(first, second)
    difference = a - b
    nonzero = int(np.count_nonzero(difference))
    median = float(np.median(difference)) if difference.size else math.nan
    if nonzero == 0:
        return Wilcoxon(
            pairs=int(a.size), nonzero=0, statistic=math.nan, p_value=1.0, median_difference=median
        )
    if nonzero <= WILCOXON_EXACT_PAIRS:
        ranks = stats.rankdata(np.abs(difference[difference != 0]))
        positive = float(ranks[difference[difference != 0] > 0].sum())
        statistic, p_value, method = (min(positive, float(ranks.sum()) - positive), sign_flip_p(difference),
                                      WILCOXON_EXACT)
    else:
        result = stats.wilcoxon(a, b, zero_method="wilcox", alternative="two-sided", method="asymptotic")
        statistic, p_value, method = float(result.statistic), float(result.pvalue), WILCOXON_APPROXIMATE
    return Wilcoxon(
        pairs=int(a.size),
        nonzero=nonzero,
        statistic=statistic,
        p_value=p_value,
        median_difference=median,
        method=method,
    )


# The interval a bootstrap of a mean gives (`Estimate.method` of `mean_difference`): BCa; the
# percentile interval where BCa is undefined; none where every value is the same (the point).
BOOTSTRAP_BCA = "BCa"
BOOTSTRAP_PERCENTILE = "percentile"
BOOTSTRAP_DEGENERATE = "degenerate"


def _bootstrap_mean(
    data: np.ndarray, rng: np.random.Generator, resamples: int, level: float, method: str
) -> tuple[float, float, str]:
    """The `method` interval of the mean of `data` and the method that gave it (BOOTSTRAP_*)."""
    if data.size == 0:
        return math.nan, math.nan, ""
    if data.size == 1 or np.all(data == data[0]):
        # no spread: every resample has the same mean
        return float(data[0]), float(data[0]), BOOTSTRAP_DEGENERATE
    # BCa's nan where it is undefined is handled below: neither scipy's warning nor numpy's 0/0 is shown
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        result = stats.bootstrap(
            (data,),
            np.mean,
            n_resamples=resamples,
            confidence_level=level,
            method=method,
            rng=rng,
            batch=max(1, 2_000_000 // data.size),
        )
    low, high = float(result.confidence_interval.low), float(result.confidence_interval.high)
    if method == BOOTSTRAP_BCA and (math.isnan(low) or math.isnan(high)):
        # BCa undefined: values equal up to rounding (a participant's trust one level higher under
        # A on episodes of different lengths), whose leave-one-out means are one float, so the
        # jackknife's spread is 0 and scipy's acceleration 0/0
        return _bootstrap_mean(data, rng, resamples, level, BOOTSTRAP_PERCENTILE)
    return low, high, method


def bootstrap_ci(
    values: np.ndarray,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = DEFAULT_LEVEL,
) -> tuple[float, float, str]:
    """Percentile bootstrap interval of the mean (scipy.stats.bootstrap) and its method:
    BOOTSTRAP_PERCENTILE, or BOOTSTRAP_DEGENERATE where every value is the same (the interval is
    the point). NaNs dropped; empty: nan, nan and ""."""
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    data = np.asarray(values, dtype=float)
    return _bootstrap_mean(data[~np.isnan(data)], rng, resamples, level, BOOTSTRAP_PERCENTILE)


def keyed_rng(seed: int, *key: object) -> np.random.Generator:
    """The Generator of one resampling: `seed`'s SeedSequence spawned at a stable hash of `key`, which
    names what is resampled (the statistic and the comparison, e.g. "trust difference", "phi1",
    "aware", "free"), never where the result is shown. Two bootstraps of the same data under the same
    key draw alike, and no bootstrap's draws depend on which ran before it. SHA-256 of the key's
    text, as Python's hash() of a str differs between runs."""
    digest = hashlib.sha256("\x1f".join(str(part) for part in key).encode()).digest()
    words = tuple(int.from_bytes(digest[i:i + 4], "little") for i in range(0, len(digest), 4))
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=words))


def mean_difference(
    first: np.ndarray,
    second: np.ndarray,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = DEFAULT_LEVEL,
) -> Estimate:
    """Mean of first - second over pairs (NaN pairs dropped), BCa bootstrap interval over pairs;
    `method` names the interval given (BOOTSTRAP_*: BCa, percentile where BCa is undefined,
    degenerate where every difference is the same)."""
    a, b = _drop_nan_pairs(first, second)
    difference = a - b
    if difference.size == 0:
        return Estimate(math.nan, math.nan, math.nan)
    low, high, method = _bootstrap_mean(difference, rng, resamples, level, BOOTSTRAP_BCA)
    return Estimate(float(difference.mean()), low, high, method=method)
