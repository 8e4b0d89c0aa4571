"""Statistics of a study: intervals for rates, paired effect sizes, tests and repeated-measures models.

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
- `wilcoxon_paired`: Wilcoxon signed-rank test via scipy; p = 1 when every difference is zero.
  Where scipy enumerates every sign flip by a permutation test (at most 13 pairs, with ties or
  zero differences: 2^n statistics each recomputed, seconds at n = 13), the same exact null
  distribution is counted instead (`sign_flip_p`: the rank sums of every flip by dynamic
  programming over the doubled midranks), which gives scipy's very p-value in microseconds;
- `mean_difference`: the mean paired difference with a BCa bootstrap interval over participants
  from `scipy.stats.bootstrap` (the Generator passed in drives the resampling);
- `bootstrap_ci`: percentile bootstrap of a mean (scipy.stats.bootstrap), for single cells.

Repeated measures across specs (statsmodels): `conditional_logit` fits satisfaction on the
condition with spec fixed effects and one stratum per participant (the participant effect is
conditioned away, so four episodes of one person never count as four people); `mixed_trust_model`
fits mean trust with a random intercept per participant.

Separation is detected from the data before the conditional logit is fitted (`separation`): the
conditional likelihood grows without bound along a coefficient direction d exactly when, within every
participant, no episode that failed scores above one that succeeded (d . (x_success - x_failure) >= 0
for every such pair), and a linear programme finds whether such a d moves the treatment coefficient.
Complete separation: some d orders every such pair strictly; quasi-separation: only with ties. On
separated data the Wald interval of the fit means nothing, so the effect reported is the exact
conditional one of the matched (participant, stratum) pairs: b ~ Binomial(b + c, OR / (1 + OR)),
with its median-unbiased estimate, Clopper–Pearson-based interval and exact p-value, and the reason
written in `ModelEffect.note`.

Multiplicity: a study with k conditions compares every pair of them; `holm` adjusts the p-values of
one family (one test, one spec, every pair) by Holm's step-down method, which controls the
family-wise error rate under any dependence between the tests.
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


def mcnemar_exact(first: np.ndarray, second: np.ndarray) -> McNemar:
    """Exact McNemar test of paired booleans: two-sided binomial test of b vs c at 1/2."""
    table = paired_table(first, second)
    discordant = table.only_first + table.only_second
    p = 1.0 if discordant == 0 else float(stats.binomtest(table.only_first, discordant, 0.5).pvalue)
    return McNemar(pairs=table.pairs, only_first=table.only_first, only_second=table.only_second, p_value=p)


@dataclass(frozen=True)
class Estimate:
    """A point estimate with its interval (nan where undefined); `note` says why it is what it is
    when it is not the plain estimate (e.g. median-unbiased on separated data)."""

    value: float
    low: float
    high: float
    note: str = ""


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


NO_DISCORDANCE = "no discordant pair (equal outcomes under both): no odds ratio is estimable"


def exact_odds_ratio(b: int, c: int, level: float = DEFAULT_LEVEL) -> Estimate:
    """The odds ratio of matched pairs from the binomial of b among the b + c discordant pairs:
    the median-unbiased estimate with the exact interval of the Clopper–Pearson interval of
    b / (b + c); finite estimate even when b or c is 0 (where b / c is 0 or infinite)."""
    if b + c == 0:
        return Estimate(math.nan, math.nan, math.nan, NO_DISCORDANCE)
    low, high = rate_interval(b, b + c, level, "exact")
    return Estimate(_odds(median_unbiased_proportion(b, b + c)), _odds(low), _odds(high))


def one_sided_reason(b: int, c: int, first: str = "A", second: str = "B") -> str:
    """Why a paired odds ratio is median-unbiased: every discordant pair favours one side."""
    side = first if c == 0 else second
    return (f"all {b + c} discordant pairs favour {side} (b / c = {'inf' if c == 0 else '0'}): "
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


# scipy.stats.wilcoxon enumerates all 2^n sign flips (a permutation test) when the n pairs, zero
# differences included, are at most this many and the differences have ties or zeros
SIGN_FLIPS_ENUMERATED = 13


def sign_flip_p(difference: np.ndarray) -> float:
    """Two-sided p-value of Wilcoxon's signed-rank sum W+ over every sign flip of the nonzero
    differences (midranks for ties), counted exactly: W+ doubled is an integer sum of doubled
    midranks, whose distribution over the 2^m flips is built one rank at a time. p = 2 min(P(W+ >=
    w), P(W+ <= w)), at most 1 (scipy's permutation test's two-sided rule; flipping a zero changes
    nothing, so zeros only scale the count)."""
    nonzero = difference[difference != 0]
    doubled = np.rint(2.0 * stats.rankdata(np.abs(nonzero))).astype(np.int64)
    counts = np.zeros(int(doubled.sum()) + 1, dtype=np.int64)
    counts[0] = 1
    for rank in doubled:
        counts[rank:] = counts[rank:] + counts[:-rank].copy()
    observed = int(doubled[nonzero > 0].sum())
    total = float(2 ** nonzero.size)
    greater = float(counts[observed:].sum()) / total
    less = float(counts[:observed + 1].sum()) / total
    return min(1.0, 2.0 * min(greater, less))


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
    magnitudes = np.abs(difference[difference != 0])
    if difference.size <= SIGN_FLIPS_ENUMERATED and (nonzero < difference.size
                                                   or np.unique(magnitudes).size < magnitudes.size):
        ranks = stats.rankdata(magnitudes)
        positive = float(ranks[difference[difference != 0] > 0].sum())
        statistic, p_value = min(positive, float(ranks.sum()) - positive), sign_flip_p(difference)
    else:
        result = stats.wilcoxon(a, b, zero_method="wilcox", alternative="two-sided")
        statistic, p_value = float(result.statistic), float(result.pvalue)
    return Wilcoxon(
        pairs=int(a.size),
        nonzero=nonzero,
        statistic=statistic,
        p_value=p_value,
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


@dataclass(frozen=True)
class Separation:
    """Whether the conditional likelihood is unbounded along the treatment coefficient.

    `kind`: "none", "complete" (some direction orders every success/failure pair of a participant
    strictly) or "quasi" (only with ties); `favours`: "treated" or "control" when separated."""

    kind: str
    favours: str = ""


def _contrasts(y: np.ndarray, exog: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """x_success - x_failure for every pair of a success and a failure of the same participant."""
    rows = []
    for group in np.unique(groups):
        member = groups == group
        success, failure = exog[member & (y == 1)], exog[member & (y == 0)]
        if len(success) and len(failure):
            rows.append((success[:, None, :] - failure[None, :, :]).reshape(-1, exog.shape[1]))
    return np.vstack(rows) if rows else np.zeros((0, exog.shape[1]))


def _furthest(contrasts: np.ndarray, sign: float, margin: bool) -> float:
    """max sign * d[0] (margin False) or the largest t with contrasts . d >= t, sign * d[0] >= t
    (margin True) over |d| <= 1, contrasts . d >= 0: a linear programme (scipy HiGHS)."""
    from scipy.optimize import linprog

    width = contrasts.shape[1]
    if margin:  # variables (d, t): maximise t subject to contrasts . d >= t and sign * d0 >= t
        first = np.zeros(width)
        first[0] = sign
        a_ub = np.hstack([-np.vstack([contrasts, first]), np.ones((len(contrasts) + 1, 1))])
        cost = np.zeros(width + 1)
        cost[-1] = -1.0
        bounds = [(-1.0, 1.0)] * width + [(0.0, 1.0)]
    else:
        a_ub, cost, bounds = -contrasts, np.zeros(width), [(-1.0, 1.0)] * width
        cost[0] = -sign
    result = linprog(cost, A_ub=a_ub, b_ub=np.zeros(len(a_ub)), bounds=bounds, method="highs")
    return float(-result.fun) if result.status == 0 else 0.0


SEPARATION_TOLERANCE = 1e-9


def separation(outcome: np.ndarray, exog: np.ndarray, participant: np.ndarray) -> Separation:
    """Separation of the conditional logit's first coefficient (the treatment) from the data alone."""
    y = np.asarray(outcome, dtype=float)
    contrasts = _contrasts(y, np.asarray(exog, dtype=float), np.asarray(participant))
    if not len(contrasts):
        return Separation("none")
    for sign, favours in ((1.0, "treated"), (-1.0, "control")):
        if _furthest(contrasts, sign, margin=False) > SEPARATION_TOLERANCE:
            complete = _furthest(contrasts, sign, margin=True) > SEPARATION_TOLERANCE
            return Separation("complete" if complete else "quasi", favours)
    return Separation("none")


def matched_discordance(
    outcome: np.ndarray, treated: np.ndarray, participant: np.ndarray, strata: np.ndarray | None
) -> tuple[int, int, int]:
    """(b, c, unmatched) over the (participant, stratum) pairs of one treated and one control episode:
    b pairs where only the treated one succeeded, c where only the control one did; `unmatched`
    counts the (participant, stratum) cells that are not such a pair."""
    frame = {"y": np.asarray(outcome, dtype=float), "t": np.asarray(treated, dtype=float)}
    keys = list(zip(np.asarray(participant).tolist(),
                    [None] * len(frame["y"]) if strata is None else np.asarray(strata).tolist(), strict=True))
    cells: dict = {}
    for key, y, t in zip(keys, frame["y"], frame["t"], strict=True):
        cells.setdefault(key, []).append((t, y))
    b = c = unmatched = 0
    for episodes in cells.values():
        treated_y = [y for t, y in episodes if t == 1]
        control_y = [y for t, y in episodes if t != 1]
        if len(treated_y) != 1 or len(control_y) != 1:
            unmatched += 1
            continue
        b += int(treated_y[0] == 1 and control_y[0] == 0)
        c += int(treated_y[0] == 0 and control_y[0] == 1)
    return b, c, unmatched


EXACT_MODEL = "exact conditional (matched pairs)"


def _separated_effect(base: ModelEffect, found: Separation, discordance: tuple[int, int, int],
                      level: float, sides: tuple[str, str]) -> ModelEffect:
    """The estimable effect on separated data: the exact conditional odds ratio of the matched pairs."""
    b, c, unmatched = discordance
    side = sides[0] if found.favours == "treated" else sides[1]
    kind = "complete separation" if found.kind == "complete" else "quasi-separation"
    reason = f"{kind}, all {b + c} discordant pairs ({b} / {c}) favour {side}: the logit's OR is infinite"
    if unmatched or b + c == 0:
        return replace(base, note=f"{reason}; no exact estimate (episodes not in matched pairs)")
    exact = exact_odds_ratio(b, c, level)
    p = float(stats.binomtest(b, b + c, 0.5).pvalue)
    return replace(
        base, model=EXACT_MODEL, estimate=exact.value, low=exact.low, high=exact.high, p_value=p,
        note=f"{reason}; shown: the matched pairs' exact median-unbiased OR, CI open "
        f"{'above' if c == 0 else 'below'}",
    )


def conditional_logit(
    outcome: np.ndarray,
    treated: np.ndarray,
    participant: np.ndarray,
    strata: np.ndarray | None = None,
    level: float = DEFAULT_LEVEL,
    sides: tuple[str, str] = ("the treated condition", "the control condition"),
) -> ModelEffect:
    """Conditional logistic regression of a binary outcome on `treated` (+ stratum dummies, e.g. the
    spec), one group per participant (statsmodels ConditionalLogit). Returns the treatment's odds ratio.

    Participants whose outcomes are all equal carry no information and drop out of the likelihood;
    with no informative participant the effect is missing with a note. Separated data (`separation`)
    are not fitted: the effect is the exact conditional one of the matched pairs, with the reason
    (naming the treated and the control condition by `sides`)."""
    from statsmodels.discrete.conditional_models import ConditionalLogit

    y = np.asarray(outcome, dtype=float)
    groups = np.asarray(participant)
    treated = np.asarray(treated, dtype=float)
    observations = int(y.size)
    keep, dropped = _constant_strata(y, strata)
    if dropped:
        y, groups, treated = y[keep], groups[keep], treated[keep]
        strata = np.asarray(strata)[keep]
    informative = {g for g in np.unique(groups) if 0 < y[groups == g].sum() < (groups == g).sum()}
    base = ModelEffect("conditional logit", "condition", groups=len(informative), observations=observations,
                       note=dropped)
    if not informative:
        return replace(base, note=_joined("no participant had different outcomes between episodes", dropped))
    exog = _design(treated, strata)
    found = separation(y, exog, groups)
    if found.kind != "none":
        effect = _separated_effect(base, found, matched_discordance(y, treated, groups, strata), level, sides)
        return replace(effect, note=_joined(effect.note, dropped))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = ConditionalLogit(y, exog, groups=groups).fit(disp=False)
        beta, se = float(result.params[0]), float(result.bse[0])
        p = float(result.pvalues[0])
    except (np.linalg.LinAlgError, ValueError) as exc:
        return replace(base, note=_joined(f"fit failed ({type(exc).__name__})", dropped))
    if not (math.isfinite(beta) and math.isfinite(se)):
        return replace(base, note=_joined("the fit did not converge", dropped))
    z = stats.norm.ppf(0.5 + level / 2)
    return replace(
        base, estimate=math.exp(beta), low=math.exp(beta - z * se), high=math.exp(beta + z * se), p_value=p
    )


def _joined(*notes: str) -> str:
    return "; ".join(n for n in notes if n)


def _constant_strata(y: np.ndarray, strata: np.ndarray | None) -> tuple[np.ndarray, str]:
    """Rows to keep, and a note naming the strata left out: a stratum (spec) whose outcomes are all
    equal has an infinite effect (quasi-separation of its dummy) and, at that limit, tells nothing
    about the condition, so the fit without it is the limit of the fit with it."""
    keep = np.ones(y.size, dtype=bool)
    if strata is None:
        return keep, ""
    levels = np.asarray(strata)
    constant = [level for level in dict.fromkeys(levels.tolist())
                if len(np.unique(y[levels == level])) == 1]
    if not constant or len(constant) == len(set(levels.tolist())):
        return keep, ""   # all constant: no participant differs, said by the caller
    keep = ~np.isin(levels, constant)
    return keep, "; ".join(
        f"{level} left out (every episode {'satisfied' if y[levels == level][0] == 1 else 'unsatisfied'}:"
        " no discordance, an infinite effect of its own)" for level in constant)


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
