"""Repeated-measures models of a study, over every episode with one group per participant.

Across specs: `conditional_logit` fits satisfaction on the condition with spec fixed effects and
one stratum per participant (statsmodels ConditionalLogit; the participant effect is conditioned
away, so four episodes of one person never count as four people); `mixed_trust_model` fits mean
trust with a random intercept per participant by REML (`random_intercept_reml`).

The mixed model's REML fit is the profile likelihood over one number, the ratio of the
participants' variance to the residual variance, maximised over [0, inf) with the boundary 0
included: the fixed effects are then the GLS estimate and their covariance the residual variance
times (X' V^-1 X)^-1. A study whose participants differ little has its REML optimum at that
boundary (a variance of 0, the fit being ordinary least squares: the demo study's trust model
is one); statsmodels' MixedLM does not reach it (its optimisers stop short of the boundary, saying
they converged or not depending on the processor, or fail on a singular matrix), so the fit is
computed here and statsmodels checks it in the tests where its fit converges.

Separation is detected from the data before the conditional logit is fitted (`separation`): the
conditional likelihood grows without bound along a coefficient direction d exactly when, within every
participant, no episode that failed scores above one that succeeded (d . (x_success - x_failure) >= 0
for every such pair), and a linear programme finds whether such a d moves the treatment coefficient.
Complete separation: some d orders every such pair strictly; quasi-separation: only with ties. On
separated data the Wald interval of the fit means nothing, so the effect reported is the exact
conditional one of the matched (participant, stratum) pairs: b ~ Binomial(b + c, OR / (1 + OR)),
with its median-unbiased estimate, Clopper–Pearson-based interval and exact p-value, and the reason
written in `ModelEffect.note`.

The exact pieces (median-unbiased odds ratio, binomial test at 1/2) are analysis/statistics.py's.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from trustroute.analysis.statistics import (
    DEFAULT_LEVEL,
    TOO_FEW,
    all_discordant_favour,
    binomial_half_p,
    exact_odds_ratio,
)


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
    b, c, _ = discordance
    side = sides[0] if found.favours == "treated" else sides[1]
    kind = "complete separation" if found.kind == "complete" else "quasi-separation"
    reason = f"{kind}, {all_discordant_favour(b + c, side)} ({b} / {c}): the logit's OR is infinite"
    return _matched_pairs_effect(base, discordance, level, reason)


def _matched_pairs_effect(base: ModelEffect, discordance: tuple[int, int, int], level: float,
                          reason: str) -> ModelEffect:
    """The exact conditional odds ratio of the matched pairs (binomial of b among b + c: median-
    unbiased estimate, exact interval, exact p), shown where the logit's fit cannot be, with why."""
    b, c, unmatched = discordance
    if unmatched or b + c == 0:
        return replace(base, note=f"{reason}; no exact estimate (episodes not in matched pairs)")
    exact = exact_odds_ratio(b, c, level)
    opening = ", CI open above" if c == 0 else ", CI open below" if b == 0 else ""
    return replace(
        base, model=EXACT_MODEL, estimate=exact.value, low=exact.low, high=exact.high,
        p_value=binomial_half_p(b, c), note=f"{reason}; shown: the matched pairs' exact median-unbiased "
        f"OR{opening}",
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
            # Newton's method: statsmodels' default BFGS stops with a gradient near 1e-3, an odds
            # ratio some 1e-4 off the maximum; the conditional likelihood is concave and, once
            # separation is ruled out, has its maximum inside
            result = ConditionalLogit(y, exog, groups=groups).fit(disp=False, method="newton")
        beta, se = float(result.params[0]), float(result.bse[0])
        p = float(result.pvalues[0])
    except np.linalg.LinAlgError:
        # a singular information matrix: another coefficient (a spec's, among the few informative
        # participants) runs off to infinity while the treatment's need not; the matched pairs'
        # exact conditional effect is the estimate that stays defined
        pairs = matched_discordance(y, treated, groups, strata)
        effect = _matched_pairs_effect(base, pairs, level, "the logit's information matrix is singular, "
                                       "another effect being infinite or not identified "
                                       f"among the discordant pairs ({pairs[0]} / {pairs[1]})")
        return replace(effect, note=_joined(effect.note, dropped))
    except ValueError as exc:
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


# the profile is scanned on this grid of log variance ratios, then refined around its best point
LOG_RATIO_GRID = np.arange(-12.0, 8.01, 0.5)
BOUNDARY_NOTE = ("the participants' variance is estimated at 0 (REML on its boundary): the fit is "
                 "ordinary least squares")


@dataclass(frozen=True)
class RandomInterceptFit:
    """A random-intercept REML fit: the fixed effects, their covariance, the variance ratio."""

    beta: np.ndarray
    covariance: np.ndarray
    ratio: float      # the participants' variance over the residual variance (0: on the boundary)
    residual_variance: float


def random_intercept_reml(y: np.ndarray, exog: np.ndarray, groups: np.ndarray) -> RandomInterceptFit:
    """REML fit of y = exog beta + u_group + e, u ~ N(0, ratio s2), e ~ N(0, s2).

    Within a group of k rows V = I + ratio 11', whose inverse is I - c 11' with c = ratio / (1 + k
    ratio) and log det log(1 + k ratio); the profile REML criterion (n - p) log s2(ratio) + log det
    V + log det X'V^-1 X is minimised over ratio on a grid of log ratios, refined, and compared with
    ratio = 0 exactly."""
    from scipy.optimize import minimize_scalar

    codes = np.unique(groups, return_inverse=True)[1].ravel()
    m = int(codes.max()) + 1
    sizes = np.bincount(codes, minlength=m).astype(float)
    sums = np.zeros((m, exog.shape[1]))
    np.add.at(sums, codes, exog)
    y_sums = np.bincount(codes, weights=y, minlength=m)
    n, p = exog.shape

    def fit(ratio: float) -> tuple[float, np.ndarray, np.ndarray, float]:
        """The REML criterion at `ratio`, with the GLS fixed effects, X'V^-1 X and s2 there."""
        c = ratio / (1.0 + sizes * ratio)
        gram = exog.T @ exog - sums.T @ (c[:, None] * sums)
        beta = np.linalg.solve(gram, exog.T @ y - sums.T @ (c * y_sums))
        residual = y - exog @ beta
        residual_sums = np.bincount(codes, weights=residual, minlength=m)
        s2 = float(residual @ residual - np.sum(c * residual_sums ** 2)) / (n - p)
        log_s2 = math.log(s2) if s2 > 0 else -math.inf   # an exact fit: no residual variance
        criterion = (n - p) * log_s2 + float(np.sum(np.log1p(sizes * ratio))) + np.linalg.slogdet(gram)[1]
        return criterion, beta, gram, s2

    scanned = [fit(math.exp(g))[0] for g in LOG_RATIO_GRID]
    best = int(np.argmin(scanned))
    low, high = LOG_RATIO_GRID[max(best - 1, 0)], LOG_RATIO_GRID[min(best + 1, len(LOG_RATIO_GRID) - 1)]
    refined = minimize_scalar(lambda g: fit(math.exp(g))[0], bounds=(low, high), method="bounded",
                              options={"xatol": 1e-10})
    interior = math.exp(float(refined.x))
    ratio = 0.0 if fit(0.0)[0] <= fit(interior)[0] else interior
    _, beta, gram, s2 = fit(ratio)
    # the covariance only of the fit chosen: the scan needs the criterion alone
    return RandomInterceptFit(beta, s2 * np.linalg.inv(gram), ratio, s2)


def mixed_trust_model(
    value: np.ndarray,
    treated: np.ndarray,
    participant: np.ndarray,
    strata: np.ndarray | None = None,
    level: float = DEFAULT_LEVEL,
) -> ModelEffect:
    """Linear mixed model value ~ treated (+ stratum dummies) with a random intercept per
    participant, by REML (`random_intercept_reml`). Returns the treatment's difference in means with
    its Wald interval and p-value; the note says when the participants' variance is estimated at
    0."""
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
        return replace(base, note=TOO_FEW)
    kept_strata = None if strata is None else np.asarray(strata)[keep]
    exog = np.column_stack([np.ones(keep.sum()), _design(np.asarray(treated)[keep], kept_strata)])
    if keep.sum() <= exog.shape[1] or np.linalg.matrix_rank(exog) < exog.shape[1]:
        return replace(base, note=f"the condition is not estimable ({TOO_FEW} or collinear)")
    fitted = random_intercept_reml(y[keep], exog, groups)
    beta, se = float(fitted.beta[1]), math.sqrt(float(fitted.covariance[1, 1]))
    if not (math.isfinite(beta) and se > 0):
        return replace(base, note="no residual variation: no interval")
    z = stats.norm.ppf(0.5 + level / 2)
    return replace(base, estimate=beta, low=beta - z * se, high=beta + z * se,
                   p_value=float(2 * stats.norm.sf(abs(beta / se))),
                   note=BOUNDARY_NOTE if fitted.ratio == 0 else "")
