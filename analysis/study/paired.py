"""Paired effects over participants, for every pair of conditions: the per-participant table, the
paired statistics per spec (2x2 counts, exact McNemar, Newcombe risk difference, conditional odds
ratio, BCa trust difference, Wilcoxon) with an "all specs" row that is per participant (its
satisfaction: the exact sign test of the participants' mean differences over specs), and the
repeated-measures models (conditional logit, mixed trust model) with one group per participant.

With k conditions there are k(k-1)/2 pairs (`condition_pairs`); every p-value gets its Holm-adjusted
value beside it (`<test>_holm`), the family being that test on that spec (or model outcome) over
every pair (analysis/statistics.py `holm`). With two conditions the adjusted p equals the raw one.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

from trustroute.analysis.formatting import finite_or_none
from trustroute.analysis.repeated_measures import conditional_logit, mixed_trust_model
from trustroute.analysis.statistics import (
    conditional_odds_ratio,
    holm,
    keyed_rng,
    mcnemar_exact,
    mean_difference,
    paired_risk_difference,
    paired_table,
    sign_test,
    wilcoxon_paired,
)

ALL_SPECS = "all specs"
# the keys of the bootstraps (with the spec and the pair): what is resampled, not where it is shown
TRUST_DIFFERENCE = "trust difference"
SATISFACTION_DIFFERENCE = "satisfaction difference"


PAIRED_TESTS = ("mcnemar_p", "sign_test_p", "wilcoxon_p")   # the p-values adjusted over the pairs


def condition_pairs(conditions) -> list[tuple[str, str]]:
    """Every pair (a, b) of `conditions`, a the trust-aware side: "aware" first, "free" last, the
    others in their order between (so a two-condition study keeps "aware vs free")."""
    ranked = sorted(conditions, key=lambda c: 0 if c == "aware" else 2 if c == "free" else 1)
    return list(itertools.combinations(ranked, 2))


def with_holm(frame: pd.DataFrame, family: list[str], tests: tuple[str, ...]) -> pd.DataFrame:
    """`frame` with `<test>_holm` beside every test column present: Holm over the rows sharing the
    `family` columns (one spec, one driver type: every pair of conditions)."""
    if not len(frame):
        return frame
    frame = frame.copy()
    for test in tests:
        if test not in frame:
            continue
        adjusted = pd.Series([None] * len(frame), index=frame.index, dtype=object)
        for _, rows in frame.groupby(family, sort=False, dropna=False):
            values = [finite_or_none(v) for v in rows[test]]
            adjusted.loc[rows.index] = holm(values)
        frame.insert(frame.columns.get_loc(test) + 1, f"{test}_holm", adjusted.to_numpy())
    return frame


def all_pairs_table(wide: pd.DataFrame, pairs: list[tuple[str, str]], spec_order, seed: int,
                    resamples: int) -> pd.DataFrame:
    """The paired statistics of every pair, with Holm-adjusted p-values per spec."""
    frames = [paired_table_rows(wide, pair, spec_order, seed, resamples) for pair in pairs]
    frames = [f for f in frames if len(f)]
    if not frames:
        return pd.DataFrame()
    return with_holm(pd.concat(frames, ignore_index=True), ["spec"], PAIRED_TESTS)


def all_pairs_repeated(episodes: pd.DataFrame, column: str, pairs: list[tuple[str, str]]) -> pd.DataFrame:
    """The repeated-measures models of every pair, with Holm-adjusted p-values per outcome."""
    frames = [repeated_measures_table(episodes, column, pair) for pair in pairs]
    if not frames:
        return pd.DataFrame()
    return with_holm(pd.concat(frames, ignore_index=True), ["outcome"], ("p_value",))


def per_participant_table(episodes: pd.DataFrame, column: str, pair: tuple[str, ...]) -> pd.DataFrame:
    """One row per (participant, spec): satisfied and mean reported trust under each condition of
    `pair` (two conditions, or every condition of the study)."""
    subset = episodes[episodes["condition"].isin(pair)]
    wide = subset.pivot_table(
        index=["participant", "spec"],
        columns="condition",
        values=[column, "mean_reported_trust"],
        aggfunc="first",
    )
    out = pd.DataFrame(index=wide.index)
    for condition in pair:
        out[f"satisfied_{condition}"] = wide.get((column, condition))
        out[f"trust_{condition}"] = wide.get(("mean_reported_trust", condition))
    return out.reset_index()


def trust_difference_columns(trust, wx) -> dict:
    """A paired row's trust columns: the mean difference with its interval and the interval's method
    (statistics.py `mean_difference`), and Wilcoxon's test with the median difference."""
    return {
        "trust_difference": finite_or_none(trust.value),
        "trust_diff_low": finite_or_none(trust.low),
        "trust_diff_high": finite_or_none(trust.high),
        "trust_diff_method": trust.method,
        "wilcoxon_pairs": wx.pairs,
        "wilcoxon_p": wx.p_value,
        "wilcoxon_method": wx.method,
        "median_trust_difference": finite_or_none(wx.median_difference),
    }


def paired_table_rows(
    wide: pd.DataFrame, pair: tuple[str, str], spec_order, seed: int, resamples: int
) -> pd.DataFrame:
    """The paired statistics of one pair, per spec and over specs; each bootstrap draws from its own
    Generator keyed by the statistic, the spec and the pair (statistics.py `keyed_rng`), so the same
    data give the same interval in every table (per type "all", sensitivity) and in any order."""
    a, b = pair
    rows = []
    for spec in spec_order:
        group = wide[wide["spec"] == spec].dropna(subset=[f"satisfied_{a}", f"satisfied_{b}"])
        if group.empty:
            continue
        first, second = group[f"satisfied_{a}"].astype(bool), group[f"satisfied_{b}"].astype(bool)
        table = paired_table(first, second)
        mc = mcnemar_exact(first, second)
        rd = paired_risk_difference(table)
        odds = conditional_odds_ratio(table, sides=pair)
        trust = mean_difference(group[f"trust_{a}"], group[f"trust_{b}"],
                                keyed_rng(seed, TRUST_DIFFERENCE, spec, a, b), resamples)
        wx = wilcoxon_paired(group[f"trust_{a}"], group[f"trust_{b}"])
        rows.append(
            {
                "spec": spec,
                "condition_a": a,
                "condition_b": b,
                "unit": "participant",
                "pairs": table.pairs,
                "both_satisfied": table.both,
                "only_a_satisfied": table.only_first,
                "only_b_satisfied": table.only_second,
                "neither_satisfied": table.neither,
                "mcnemar_p": mc.p_value,
                "risk_difference": finite_or_none(rd.value),
                "rd_low": finite_or_none(rd.low),
                "rd_high": finite_or_none(rd.high),
                "rd_method": rd.method,
                "odds_ratio": finite_or_none(odds.value),
                "or_low": finite_or_none(odds.low),
                "or_high": finite_or_none(odds.high),
                "or_note": odds.note,
                **trust_difference_columns(trust, wx),
            }
        )
    # Across specs, one value per participant (their repeated measures are not independent pairs).
    both = wide.dropna(subset=[f"satisfied_{a}", f"satisfied_{b}"])
    if both["spec"].nunique() > 1:
        person = (
            both.assign(
                sat_diff=both[f"satisfied_{a}"].astype(float) - both[f"satisfied_{b}"].astype(float),
                trust_diff=both[f"trust_{a}"] - both[f"trust_{b}"],
            )
            .groupby("participant")[["sat_diff", "trust_diff"]]
            .mean()
        )
        sat = sign_test(person["sat_diff"].to_numpy())
        trust = mean_difference(person["trust_diff"].to_numpy(), np.zeros(len(person)),
                                keyed_rng(seed, TRUST_DIFFERENCE, ALL_SPECS, a, b), resamples)
        sat_mean = mean_difference(person["sat_diff"].to_numpy(), np.zeros(len(person)),
                                   keyed_rng(seed, SATISFACTION_DIFFERENCE, ALL_SPECS, a, b), resamples)
        wx = wilcoxon_paired(person["trust_diff"].to_numpy(), np.zeros(len(person)))
        rows.append(
            {
                "spec": ALL_SPECS,
                "condition_a": a,
                "condition_b": b,
                "unit": "participant (mean over specs)",
                "pairs": int(len(person)),
                "mcnemar_p": None,
                "a_ahead": sat.positive,
                "b_ahead": sat.negative,
                "sign_test_p": sat.p_value,
                "risk_difference": finite_or_none(sat_mean.value),
                "rd_low": finite_or_none(sat_mean.low),
                "rd_high": finite_or_none(sat_mean.high),
                "rd_method": sat_mean.method,
                **trust_difference_columns(trust, wx),
            }
        )
    return pd.DataFrame(rows)


def repeated_measures_table(episodes: pd.DataFrame, column: str, pair: tuple[str, str]) -> pd.DataFrame:
    a, b = pair
    subset = episodes[episodes["condition"].isin(pair)]
    treated = (subset["condition"] == a).to_numpy(dtype=float)
    participant = subset["participant"].to_numpy()
    spec = subset["spec"].to_numpy()
    strata = spec if len(set(spec)) > 1 else None
    rows = []
    for outcome, effect in (
        (
            "satisfied (odds ratio)",
            conditional_logit(subset[column].to_numpy(dtype=float), treated, participant, strata,
                              sides=pair),
        ),
        (
            "mean reported trust (difference)",
            mixed_trust_model(
                subset["mean_reported_trust"].to_numpy(dtype=float), treated, participant, strata
            ),
        ),
    ):
        rows.append(
            {
                "outcome": outcome,
                "model": effect.model,
                "effect_of": f"{a} vs {b}",
                "estimate": finite_or_none(effect.estimate),
                "low": finite_or_none(effect.low),
                "high": finite_or_none(effect.high),
                "p_value": finite_or_none(effect.p_value),
                "participants": effect.groups,
                "episodes": effect.observations,
                "note": effect.note,
            }
        )
    return pd.DataFrame(rows)
