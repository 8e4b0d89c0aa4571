"""Per spec and condition of a study: the cells (satisfaction with exact and Wilson intervals on
the chosen belief source, reported trust with a bootstrap interval, true and final trust, junctions,
takeovers, fallback, the policy's exact and synthesized values), and the takeover rate per incident
type and condition.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from trustroute.analysis.belief_sources import beside_source
from trustroute.analysis.formatting import finite_or_none
from trustroute.analysis.statistics import bootstrap_ci, keyed_rng, rate_interval

TRUST_MEAN = "mean reported trust"   # the key of a cell's trust bootstrap


def cell_table(
    episodes: pd.DataFrame,
    spec_order,
    condition_order,
    belief_source: str,
    expected: dict,
    seed: int,
    resamples: int,
) -> pd.DataFrame:
    """One row per (spec, condition); the trust interval's resampling is keyed by the cell
    (statistics.py `keyed_rng`), so the same episodes give the same interval in any table."""
    other = beside_source(belief_source)
    rows = []
    for spec in spec_order:
        for condition in condition_order:
            group = episodes[(episodes["spec"] == spec) & (episodes["condition"] == condition)]
            n = len(group)
            k = int(group[f"satisfied_{belief_source}"].sum())
            low, high = rate_interval(k, n)
            wilson_low, wilson_high = rate_interval(k, n, method="wilson")
            trust = group["mean_reported_trust"].to_numpy(dtype=float)
            rng = keyed_rng(seed, TRUST_MEAN, spec, condition)
            trust_low, trust_high, trust_method = bootstrap_ci(trust, rng, resamples)
            exp = expected.get(spec, {}).get(condition, {})
            rows.append(
                {
                    "spec": spec,
                    "condition": condition,
                    "n": n,
                    "satisfied": k,
                    "satisfaction_rate": k / n if n else None,
                    "ci_low": finite_or_none(low),
                    "ci_high": finite_or_none(high),
                    "wilson_low": finite_or_none(wilson_low),
                    "wilson_high": finite_or_none(wilson_high),
                    f"satisfaction_rate_{other}": (
                        finite_or_none(group[f"satisfied_{other}"].mean()) if n else None
                    ),
                    "logged_satisfaction_rate": finite_or_none(group["satisfied"].mean()) if n else None,
                    "mean_trust": finite_or_none(np.nanmean(trust)) if np.isfinite(trust).any() else None,
                    "trust_ci_low": finite_or_none(trust_low),
                    "trust_ci_high": finite_or_none(trust_high),
                    "trust_ci_method": trust_method or None,
                    "mean_true_trust": finite_or_none(group["mean_trust"].mean()) if n else None,
                    "mean_final_trust": finite_or_none(group["final_trust"].mean()) if n else None,
                    "mean_junctions": finite_or_none(group["junctions"].mean()) if n else None,
                    "takeovers_per_episode": finite_or_none(group["takeovers"].mean()) if n else None,
                    "fallback_rate": finite_or_none(group["fallback_fired"].mean()) if n else None,
                    "exact_lower": exp.get("exact_lower"),
                    "exact_upper": exp.get("exact_upper"),
                    "exact_final_trust": exp.get("expected_final_trust"),
                    "synthesized_lower": exp.get("synthesized_lower"),
                    "synthesized_upper": exp.get("synthesized_upper"),
                    "synthesized_horizon": exp.get("synthesized_horizon"),
                    # the condition's policy has no synthesized decision: it drives its fallback
                    "fallback_only": bool(exp.get("fallback_only")),
                }
            )
    return pd.DataFrame(rows)


def takeover_table(roads: pd.DataFrame, episodes: pd.DataFrame, condition_order) -> pd.DataFrame:
    merged = roads[roads["index"] > 0][["episode_id", "incident", "takeover"]].merge(
        episodes[["episode_id", "condition"]], on="episode_id"
    )
    merged = merged[merged["incident"].fillna("").astype(str) != ""]
    rows = []
    for (incident, condition), group in merged.groupby(["incident", "condition"], sort=True):
        n, k = len(group), int(group["takeover"].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "incident": incident,
                "condition": condition,
                "roads": n,
                "takeovers": k,
                "rate": k / n,
                "ci_low": low,
                "ci_high": high,
            }
        )
    table = pd.DataFrame(
        rows, columns=["incident", "condition", "roads", "takeovers", "rate", "ci_low", "ci_high"]
    )
    if len(table):
        order = {c: i for i, c in enumerate(condition_order)}
        table = table.sort_values(
            ["incident", "condition"], key=lambda s: s.map(order) if s.name == "condition" else s
        ).reset_index(drop=True)
    return table
