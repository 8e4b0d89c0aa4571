"""Statistics of a study: intervals for rates, paired effect sizes, tests and repeated-measures models.

Intervals for a rate k/n (`rate_interval`): exact Clopper–Pearson and Wilson score, both from
`scipy.stats.binomtest(...).proportion_ci`.

Paired binary outcomes (satisfied under condition A and under B for the same participant and spec)
give a 2x2 table with discordant counts b (only A) and c (only B):
- `mcnemar_exact`: McNemar's test, the two-sided binomial test of b against b + c at 1/2;
- `paired_risk_difference`: (b - c) / n with Newcombe's hybrid score interval for paired
  proportions (Newcombe 1998, method 10: Wilson intervals of both margins and the phi correlation);
- `conditional_odds_ratio`: b / c with the exact interval from the Clopper–Pearson interval of
  b / (b + c) (the conditional binomial likelihood of the matched pairs).

Paired values (a participant's trust under A and under B):
- `wilcoxon_paired`: Wilcoxon signed-rank test via scipy; p = 1 when every difference is zero;
- `mean_difference`: the mean paired difference with a BCa bootstrap interval over participants
  from `scipy.stats.bootstrap` (the Generator passed in drives the resampling);
- `bootstrap_ci`: percentile bootstrap of a mean (scipy.stats.bootstrap), for single cells.

Repeated measures across specs (statsmodels): `conditional_logit` fits satisfaction on the
condition with spec fixed effects and one stratum per participant (the participant effect is
conditioned away, so four episodes of one person never count as four people); `mixed_trust_model`
fits mean trust with a random intercept per participant.
"""

from __future__ import annotations

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


def mcnemar_exact(first: np.ndarray, second: np.ndarray) -> McNemar:
    """Exact McNemar test of paired booleans: two-sided binomial test of b vs c at 1/2."""
    table = paired_table(first, second)
    discordant = table.only_first + table.only_second
    p = 1.0 if discordant == 0 else float(stats.binomtest(table.only_first, discordant, 0.5).pvalue)
    return McNemar(pairs=table.pairs, only_first=table.only_first, only_second=table.only_second, p_value=p)


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its interval (nan where undefined)."""

    value: float
    low: float
    high: float


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
    )


def conditional_odds_ratio(table: PairedTable, level: float = DEFAULT_LEVEL) -> Estimate:
    """b / c with the exact interval from the Clopper–Pearson interval of b / (b + c).

    No discordant pair: (nan, nan, nan). c = 0 gives an infinite estimate and upper bound."""
    b, c = table.only_first, table.only_second
    if b + c == 0:
        return Estimate(math.nan, math.nan, math.nan)
    low, high = rate_interval(b, b + c, level, "exact")

    def odds(p: float) -> float:
        return math.inf if p >= 1.0 else p / (1.0 - p)

    return Estimate(math.inf if c == 0 else b / c, odds(low), odds(high))


# -- paired values --------------------------------------------------------------------------------


@dataclass(frozen=True)
class Wilcoxon:
    pairs: int
    nonzero: int
    statistic: float
    p_value: float
    median_difference: float


def _drop_nan_pairs(first: np.ndarray, second: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(first, dtype=float)
    b = np.asarray(second, dtype=float)
    if a.shape != b.shape:
        raise ValueError(f"paired samples differ in shape: {a.shape} vs {b.shape}")
    keep = ~(np.isnan(a) | np.isnan(b))
    return a[keep], b[keep]


def wilcoxon_paired(first: np.ndarray, second: np.ndarray) -> Wilcoxon:
    """Wilcoxon signed-rank test (two-sided) of paired values; pairs with a NaN are dropped."""
    a, b = _drop_nan_pairs(first, second)
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


def _bootstrap_mean(
    data: np.ndarray, rng: np.random.Generator, resamples: int, level: float, method: str
) -> tuple[float, float]:
    if data.size == 0:
        return math.nan, math.nan
    if data.size == 1 or np.all(data == data[0]):
        return float(data[0]), float(data[0])  # no spread: every resample has the same mean
    with warnings.catch_warnings():
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
    if math.isnan(low) or math.isnan(high):  # BCa undefined (e.g. all but one value equal)
        return _bootstrap_mean(data, rng, resamples, level, "percentile")
    return low, high


def bootstrap_ci(
    values: np.ndarray,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = DEFAULT_LEVEL,
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean (scipy.stats.bootstrap); NaNs dropped, empty: nan."""
    if not 0 < level < 1:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    data = np.asarray(values, dtype=float)
    return _bootstrap_mean(data[~np.isnan(data)], rng, resamples, level, "percentile")


def mean_difference(
    first: np.ndarray,
    second: np.ndarray,
    rng: np.random.Generator,
    resamples: int = DEFAULT_RESAMPLES,
    level: float = DEFAULT_LEVEL,
) -> Estimate:
    """Mean of first - second over pairs (NaN pairs dropped), BCa bootstrap interval over pairs."""
    a, b = _drop_nan_pairs(first, second)
    difference = a - b
    if difference.size == 0:
        return Estimate(math.nan, math.nan, math.nan)
    low, high = _bootstrap_mean(difference, rng, resamples, level, "BCa")
    return Estimate(float(difference.mean()), low, high)


# -- repeated measures ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelEffect:
    """One coefficient of a repeated-measures model; `note` says why it is missing if it is."""

    model: str
    term: str
    estimate: float = math.nan  # odds ratio (conditional logit) or difference (mixed model)
    low: float = math.nan
    high: float = math.nan
    p_value: float = math.nan
    groups: int = 0
    observations: int = 0
    note: str = ""


def _design(treated: np.ndarray, strata: np.ndarray | None) -> np.ndarray:
    """Columns: the treatment indicator, then one dummy per stratum level but the first."""
    columns = [np.asarray(treated, dtype=float)]
    if strata is not None:
        levels = list(dict.fromkeys(np.asarray(strata).tolist()))
        columns += [(np.asarray(strata) == level).astype(float) for level in levels[1:]]
    return np.column_stack(columns)


def conditional_logit(
    outcome: np.ndarray,
    treated: np.ndarray,
    participant: np.ndarray,
    strata: np.ndarray | None = None,
    level: float = DEFAULT_LEVEL,
) -> ModelEffect:
    """Conditional logistic regression of a binary outcome on `treated` (+ stratum dummies, e.g. the
    spec), one group per participant (statsmodels ConditionalLogit). Returns the treatment's odds ratio.

    Participants whose outcomes are all equal carry no information and drop out of the likelihood;
    with no informative participant, or a separated fit, the effect is missing with a note."""
    from statsmodels.discrete.conditional_models import ConditionalLogit

    y = np.asarray(outcome, dtype=float)
    groups = np.asarray(participant)
    informative = {g for g in np.unique(groups) if 0 < y[groups == g].sum() < (groups == g).sum()}
    base = ModelEffect("conditional logit", "condition", groups=len(informative), observations=int(y.size))
    if not informative:
        return replace(base, note="no participant had different outcomes between episodes")
    exog = _design(treated, strata)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = ConditionalLogit(y, exog, groups=groups).fit(disp=False)
        beta, se = float(result.params[0]), float(result.bse[0])
        p = float(result.pvalues[0])
    except (np.linalg.LinAlgError, ValueError) as exc:
        return replace(base, note=f"fit failed ({type(exc).__name__})")
    if not (math.isfinite(beta) and math.isfinite(se)) or se > 50:
        return replace(base, note="separated: the odds ratio is unbounded on these data")
    z = stats.norm.ppf(0.5 + level / 2)
    return replace(
        base, estimate=math.exp(beta), low=math.exp(beta - z * se), high=math.exp(beta + z * se), p_value=p
    )


def mixed_trust_model(
    value: np.ndarray,
    treated: np.ndarray,
    participant: np.ndarray,
    strata: np.ndarray | None = None,
    level: float = DEFAULT_LEVEL,
) -> ModelEffect:
    """Linear mixed model value ~ treated (+ stratum dummies) with a random intercept per
    participant (statsmodels MixedLM, REML). Returns the treatment's difference in means."""
    from statsmodels.regression.mixed_linear_model import MixedLM

    y = np.asarray(value, dtype=float)
    keep = ~np.isnan(y)
    groups = np.asarray(participant)[keep]
    base = ModelEffect(
        "mixed model (random intercept)",
        "condition",
        groups=len(np.unique(groups)),
        observations=int(keep.sum()),
    )
    if keep.sum() < 4 or len(np.unique(groups)) < 2:
        return replace(base, note="too few observations")
    kept_strata = None if strata is None else np.asarray(strata)[keep]
    exog = np.column_stack([np.ones(keep.sum()), _design(np.asarray(treated)[keep], kept_strata)])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = MixedLM(y[keep], exog, groups=groups).fit(reml=True)
        beta, se, p = float(result.params[1]), float(result.bse[1]), float(result.pvalues[1])
    except (np.linalg.LinAlgError, ValueError) as exc:
        return replace(base, note=f"fit failed ({type(exc).__name__})")
    if not (math.isfinite(beta) and math.isfinite(se)):
        return replace(base, note="the fit did not converge")
    z = stats.norm.ppf(0.5 + level / 2)
    return replace(base, estimate=beta, low=beta - z * se, high=beta + z * se, p_value=p)
