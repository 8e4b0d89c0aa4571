"""Power of a study's planned tests, from simulated studies (harness/study/planning.py runs them):
each simulated study is analysed with the very test functions of the report (analysis/statistics.py,
called as analysis/study/paired.py calls them), and the share of studies in which a test rejects
at α is its power, with a Wilson 95 % interval.

The tests, named as the report names them, for every pair of conditions (A, B):
- `mcnemar`: satisfaction, per spec, the exact McNemar test (`mcnemar_exact`), rejects when p < α;
  effect: the paired risk difference (b − c) / n;
- `conditional_or`: satisfaction, per spec, the conditional odds ratio b / c with its exact
  (1 − α) interval (`conditional_odds_ratio`), rejects when the interval excludes 1; effect: the
  odds ratio;
- `wilcoxon`: mean reported trust, per spec and over both specs per participant (the report's
  "all specs" row), Wilcoxon's signed-rank test (`wilcoxon_paired`); effect: the median difference;
- `mixed_model`: mean reported trust over every spec, the mixed model with a random intercept per
  participant (`mixed_trust_model`, spec as strata); effect: the difference in means. A REML
  fit per study, planned when asked for.
Satisfaction is judged on the study's primary belief source, as its analysis will judge it
(harness/study/planning.py `source_satisfied`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from trustroute.analysis.repeated_measures import mixed_trust_model
from trustroute.analysis.statistics import (
    conditional_odds_ratio,
    mcnemar_exact,
    paired_table,
    rate_interval,
    wilcoxon_paired,
)
from trustroute.core import defaults

# Each planned test: its title as the report shows it, and the effect its power rows estimate
# (the plan's table and JSON name it per row).
_WORDS: dict[str, tuple[str, str]] = dict(zip(defaults.PLAN_TESTS, (
    ("McNemar exact p (satisfaction)", "(b − c) / n"),
    ("conditional OR [exact CI] (satisfaction)", "odds ratio b / c"),
    ("Wilcoxon p (reported trust)", "median difference"),
    ("mixed model, random intercept (reported trust)", "difference in means"),
), strict=True))
TESTS: dict[str, str] = {test: title for test, (title, _) in _WORDS.items()}
EFFECTS: dict[str, str] = {test: effect for test, (_, effect) in _WORDS.items()}
DEFAULT_TESTS: tuple[str, ...] = defaults.PLAN_DEFAULT_TESTS
ALL_SPECS = "all specs"


@dataclass(frozen=True)
class TestResult:
    """One planned test on one study: (test, pair, spec), rejected at α, its p-value (NaN for the
    odds ratio's interval) and the estimated effect."""

    test: str
    pair: tuple[str, str]
    spec: str
    rejected: bool
    p_value: float
    effect: float


@dataclass
class _Memo:
    """Results that depend on the discordant counts only (McNemar, the odds ratio's interval):
    the same function's answer for the same (b, c), computed once."""

    mcnemar: dict = field(default_factory=dict)
    odds: dict = field(default_factory=dict)


def study_tests(satisfied: np.ndarray, reported: np.ndarray, specs: Sequence[str],
                conditions: Sequence[str], tests: Sequence[str], alpha: float,
                memo: _Memo | None = None) -> list[TestResult]:
    """Every planned test of one study: satisfied and reported are [participants, specs,
    conditions] (the participants' episodes; reported is the mean reported trust)."""
    memo = memo if memo is not None else _Memo()
    out: list[TestResult] = []
    for a, b in itertools.combinations(range(len(conditions)), 2):
        pair = (conditions[a], conditions[b])
        for s, spec in enumerate(specs):
            first, second = satisfied[:, s, a], satisfied[:, s, b]
            only_a, only_b = int((first & ~second).sum()), int((~first & second).sum())
            if "mcnemar" in tests:
                p = memo.mcnemar.get((only_a, only_b))
                if p is None:
                    p = memo.mcnemar[(only_a, only_b)] = mcnemar_exact(first, second).p_value
                out.append(TestResult("mcnemar", pair, spec, p < alpha, p, (only_a - only_b) / len(first)))
            if "conditional_or" in tests:
                key = (only_a, only_b, alpha)
                odds = memo.odds.get(key)
                if odds is None:
                    odds = memo.odds[key] = conditional_odds_ratio(paired_table(first, second),
                                                                   level=1 - alpha, sides=pair)
                rejected = bool(odds.low > 1 or odds.high < 1)  # NaN (no discordant pair): False
                out.append(TestResult("conditional_or", pair, spec, rejected, math.nan, odds.value))
            if "wilcoxon" in tests:
                wx = wilcoxon_paired(reported[:, s, a], reported[:, s, b])
                out.append(TestResult("wilcoxon", pair, spec, wx.p_value < alpha, wx.p_value,
                                      wx.median_difference))
        if len(specs) > 1 and "wilcoxon" in tests:
            person = _all_specs_trust(satisfied, reported, a, b)
            wx = wilcoxon_paired(person, np.zeros(len(person)))
            out.append(TestResult("wilcoxon", pair, ALL_SPECS, wx.p_value < alpha, wx.p_value,
                                  wx.median_difference))
        if "mixed_model" in tests:
            value, treated, participant, strata = _long(reported, specs, a, b)
            out.append(_mixed(value, treated, participant, strata, pair, alpha))
    return out


def _all_specs_trust(satisfied: np.ndarray, reported: np.ndarray, a: int, b: int) -> np.ndarray:
    """Per participant the mean over specs of the trust difference A − B, over the specs where both
    episodes exist (paired.py's "all specs" row)."""
    del satisfied  # every simulated episode exists; kept for the symmetry of the call
    return np.nanmean(reported[:, :, a] - reported[:, :, b], axis=1)


def _long(reported: np.ndarray, specs: Sequence[str], a: int, b: int):
    """The mixed model's rows (participant, spec, condition order): value, treated, participant,
    strata."""
    n, n_specs = reported.shape[0], reported.shape[1]
    value = reported[:, :, [a, b]].reshape(-1)
    treated = np.tile([1.0, 0.0], n * n_specs)
    participant = np.repeat(np.arange(n), 2 * n_specs)
    strata = np.tile(np.repeat(np.asarray(specs, dtype=object), 2), n) if n_specs > 1 else None
    return value, treated, participant, strata


def _mixed(value, treated, participant, strata, pair: tuple[str, str], alpha: float) -> TestResult:
    effect = mixed_trust_model(value, treated, participant, strata)
    p = effect.p_value if effect.p_value is not None and math.isfinite(effect.p_value) else math.nan
    return TestResult("mixed_model", pair, ALL_SPECS, bool(p < alpha), p, effect.estimate)


def episodes_tests(episodes: pd.DataFrame, tests: Sequence[str], alpha: float,
                   conditions: Sequence[str] | None = None) -> list[TestResult]:
    """`study_tests` on a study's episodes table (episodes.parquet: participant, spec, condition,
    satisfied, mean_reported_trust), so a simulated study and a run one are analysed alike; the
    pairs of `conditions` (default: in the order the table names them; the report's: the config's).
    The mixed model reads the rows in the table's order (the report's are in the analysis' order of
    the participants, canonical.py): its optimiser's sums follow the rows and the coding of the
    pair, so another order or pair moves its p-value in about the ninth digit."""
    specs = list(dict.fromkeys(episodes["spec"]))
    conditions = list(dict.fromkeys(episodes["condition"]) if conditions is None else conditions)
    people = sorted(episodes["participant"].unique())
    shape = (len(people), len(specs), len(conditions))
    satisfied, reported = np.zeros(shape, dtype=bool), np.full(shape, np.nan)
    rows = (episodes["participant"].map({p: i for i, p in enumerate(people)}).to_numpy(),
            episodes["spec"].map({s: i for i, s in enumerate(specs)}).to_numpy(),
            episodes["condition"].map({c: i for i, c in enumerate(conditions)}).to_numpy())
    satisfied[rows] = episodes["satisfied"].astype(bool).to_numpy()
    reported[rows] = episodes["mean_reported_trust"].astype(float).to_numpy()
    out = study_tests(satisfied, reported, specs, conditions, [t for t in tests if t != "mixed_model"],
                      alpha)
    if "mixed_model" in tests:
        for a, b in itertools.combinations(conditions, 2):
            subset = episodes[episodes["condition"].isin((a, b))]
            spec = subset["spec"].to_numpy()
            out.append(_mixed(subset["mean_reported_trust"].to_numpy(dtype=float),
                              (subset["condition"] == a).to_numpy(dtype=float),
                              subset["participant"].to_numpy(), spec if len(set(spec)) > 1 else None,
                              (a, b), alpha))
    return out


@dataclass(frozen=True)
class Power:
    """A test's power at one sample size: the share of `studies` rejecting, its Wilson 95 %
    interval, and the estimated effect's median and central 95 % range (finite values). When each
    study drew its participants' model from `models` fitted models (a pilot's bootstrap refits),
    the power is averaged over them, and `fit_low`/`fit_high` are the 2.5/97.5 % percentiles of the
    refits' own powers (each the share of its own studies rejecting, so the range holds their
    Monte Carlo noise too); otherwise `models` is 0 and they are NaN."""

    test: str
    pair: tuple[str, str]
    spec: str
    participants: int
    studies: int
    rejected: int
    power: float
    low: float
    high: float
    effect_median: float
    effect_low: float
    effect_high: float
    models: int = 0
    fit_low: float = math.nan
    fit_high: float = math.nan


def _over_models(rejected: np.ndarray, models: np.ndarray) -> tuple[int, float, float]:
    """(models drawn, 2.5 %, 97.5 % percentile of their powers) of studies drawn from `models`."""
    drawn, index = np.unique(models, return_inverse=True)
    powers = np.bincount(index, weights=rejected) / np.bincount(index)
    low, high = np.percentile(powers, [2.5, 97.5])
    return int(drawn.size), float(low), float(high)


def power_table(results: Sequence[Sequence[TestResult]], participants: int,
                models: Sequence[int] | None = None) -> list[Power]:
    """The power of every test over the studies' results (one list of TestResult per study);
    models: the model each study drew its participants from (Power's docstring), or None."""
    grouped: dict[tuple, list[tuple[TestResult, int]]] = {}
    for i, study in enumerate(results):
        for r in study:
            grouped.setdefault((r.test, r.pair, r.spec), []).append((r, -1 if models is None else models[i]))
    out = []
    for (test, pair, spec), pairs in grouped.items():
        rows = [r for r, _ in pairs]
        k, n = sum(r.rejected for r in rows), len(rows)
        low, high = rate_interval(k, n, method="wilson")
        effects = np.array([r.effect for r in rows], dtype=float)
        effects = effects[np.isfinite(effects)]
        q = np.quantile(effects, [0.5, 0.025, 0.975]) if effects.size else [math.nan] * 3
        spread = () if models is None else _over_models(np.array([r.rejected for r in rows], dtype=float),
                                                        np.array([m for _, m in pairs]))
        out.append(Power(test, pair, spec, participants, n, int(k), k / n, low, high,
                         float(q[0]), float(q[1]), float(q[2]), *spread))
    return out


def minimal_sizes(table: Sequence[Power], target: float) -> dict[tuple, int | None]:
    """Per (test, pair, spec) the smallest sample size whose estimated power reaches `target` and
    stays there at every larger size tried (None when none does)."""
    out: dict[tuple, int | None] = {}
    keys = dict.fromkeys((p.test, p.pair, p.spec) for p in table)
    for key in keys:
        rows = sorted((p for p in table if (p.test, p.pair, p.spec) == key), key=lambda p: p.participants)
        found = None
        for row in reversed(rows):
            if row.power < target:
                break
            found = row.participants
        out[key] = found
    return out


def half_width(table: Sequence[Power]) -> float:
    """The widest half-interval of the table's powers (how precise the estimates are)."""
    return max(((p.high - p.low) / 2 for p in table), default=0.0)


@dataclass(frozen=True)
class PowerSettings:
    """How `estimate_power` runs: the tests and α, the target power, and the simulated studies per
    size: `simulations` exactly, or (None) rounds of `round_size` until every power's 95 %
    interval is within ±`precision`, at most `max_simulations`."""

    tests: tuple[str, ...] = DEFAULT_TESTS
    alpha: float = defaults.PLAN_ALPHA
    target: float = defaults.PLAN_TARGET
    simulations: int | None = None
    precision: float = 0.02
    round_size: int = 200
    max_simulations: int = 2400


# simulate(participants, studies) -> (satisfied, reported, specs, conditions) of the simulated studies,
# and optionally a fifth item: the index of the model each study drew its participants from
# (a pilot's refits), or None
Simulate = Callable[[int, int], tuple]


def estimate_power(simulate: Simulate, sizes: Sequence[int], settings: PowerSettings,
                   progress: Callable[[int, int], object] | None = None) -> list[Power]:
    """The power table over `sizes`: at each size, studies from `simulate` (a callable the harness
    passes in: analysis runs no simulation itself) analysed with `study_tests`, in rounds as
    `settings` says. progress(size, studies) is called after every round. When `simulate` also
    names the model each study drew (its fifth item), every power carries the spread over those
    models (`Power`)."""
    memo = _Memo()
    table: list[Power] = []
    for size in sizes:
        results: list[list[TestResult]] = []
        models: list[int] = []
        while True:
            wanted = settings.simulations if settings.simulations is not None else settings.max_simulations
            batch = min(settings.round_size, wanted - len(results))
            satisfied, reported, specs, conditions, *drawn = simulate(size, batch)
            results += [study_tests(satisfied[i], reported[i], specs, conditions, settings.tests,
                                    settings.alpha, memo) for i in range(batch)]
            if drawn and drawn[0] is not None:
                models += [int(m) for m in drawn[0]]
            rows = power_table(results, size, models or None)
            if progress is not None:
                progress(size, len(results))
            if len(results) >= wanted or (settings.simulations is None
                                          and half_width(rows) <= settings.precision):
                break
        table += rows
    return table
