"""Order effects of the Latin square: satisfaction and reported trust per position (Cochran's Q and
Friedman across positions within participants), and carry-over by the condition driven just before.
Positions are 0-based in the data (docs/dataset.md) and shown from 1. A study whose participants all
drove one fixed order (an imported one) has no order effect to test: position is the cell there.

A live study may run a participant's trials in another order than planned (an incomplete trial
moves to the end): its positions are those of the order actually run (`run_order`, from the
study's attempts table), not the plan's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.analysis.formatting import finite_or_none
from trustroute.analysis.statistics import rate_interval
from trustroute.analysis.study.design import fixed_order
from trustroute.core.dataset import ATTEMPTS_FILE, read_attempts
from trustroute.harness.study.config import LIVE_ENGINE


def run_order(study_dir: Path, manifest: dict, episodes: pd.DataFrame) -> pd.DataFrame:
    """`episodes` with `position` the place each was run at, for a live study with an attempts
    table (a done trial's `run_position`); any other study's episodes as they are."""
    if manifest.get("engine") != LIVE_ENGINE or not (Path(study_dir) / ATTEMPTS_FILE).exists():
        return episodes
    attempts = read_attempts(study_dir, ["episode_id", "run_position", "outcome"])
    done = attempts[(attempts["outcome"] == "done") & attempts["run_position"].notna()]
    run = dict(zip(done["episode_id"], done["run_position"].astype(int), strict=True))
    return episodes.assign(position=[run.get(episode, position) for episode, position
                                     in zip(episodes["episode_id"], episodes["position"], strict=True)])


def position_tests(episodes: pd.DataFrame, column: str) -> dict:
    """Cochran's Q (satisfaction) and Friedman (reported trust) across positions within the
    participants who drove every position. When every participant drove the cells in one fixed order
    (design.py `fixed_order`), position is the cell: those tests would compare the cells, not the
    orders, so there are none, and `fixed_order` lists the cells by position instead."""
    from scipy import stats
    from statsmodels.stats.contingency_tables import cochrans_q

    tests: dict = {"cochran_q_p": None, "friedman_p": None, "participants": 0}
    positions = episodes["position"].nunique()
    complete = episodes.groupby("participant").filter(lambda g: g["position"].nunique() == positions)
    fixed = fixed_order(episodes)
    if fixed is not None:
        return {**tests, "participants": int(complete["participant"].nunique()),
                "fixed_order": [list(cell) for cell in fixed]}
    if positions >= 2 and complete["participant"].nunique() >= 2:
        sat = complete.pivot_table(index="participant", columns="position", values=column, aggfunc="first")
        trust = complete.pivot_table(
            index="participant", columns="position", values="mean_reported_trust", aggfunc="first"
        ).dropna()
        tests["participants"] = int(len(sat))
        # Friedman reads the participants with a report at every position, which can be fewer
        tests["friedman_participants"] = int(len(trust))
        if sat.to_numpy().std() > 0:
            tests["cochran_q_p"] = float(cochrans_q(sat.to_numpy(dtype=int)).pvalue)
        if positions >= 3 and len(trust) >= 2 and trust.to_numpy().std() > 0:
            tests["friedman_p"] = float(stats.friedmanchisquare(*trust.to_numpy().T).pvalue)
    return tests


def order_tables(episodes: pd.DataFrame, column: str) -> tuple[pd.DataFrame, dict, pd.DataFrame]:
    """Position effects (per position in the participants' orders: 1 is the first) and carry-over
    (by the previous condition)."""
    rows = []
    for position, group in episodes.groupby("position", sort=True):
        n, k = len(group), int(group[column].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "position": int(position) + 1,
                "n": n,
                "satisfied": k,
                "satisfaction_rate": k / n,
                "ci_low": low,
                "ci_high": high,
                "mean_trust": finite_or_none(np.nanmean(group["mean_reported_trust"].to_numpy(dtype=float)))
                if group["mean_reported_trust"].notna().any()
                else None,
            }
        )
    order = pd.DataFrame(rows)
    tests = position_tests(episodes, column)
    ordered = episodes.sort_values(["participant", "position"])
    previous = ordered.groupby("participant")["condition"].shift(1).fillna("none (first)")
    carry = ordered.assign(previous=previous)
    rows = []
    for (condition, before), group in carry.groupby(["condition", "previous"], sort=True):
        n, k = len(group), int(group[column].sum())
        low, high = rate_interval(k, n)
        rows.append(
            {
                "condition": condition,
                "previous_condition": before,
                "n": n,
                "satisfaction_rate": k / n,
                "ci_low": low,
                "ci_high": high,
                "mean_trust": finite_or_none(group["mean_reported_trust"].mean()),
            }
        )
    return order, tests, pd.DataFrame(rows)
