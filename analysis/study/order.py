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
from trustroute.analysis.statistics import TOO_FEW, rate_interval
from trustroute.analysis.study.design import fixed_order
from trustroute.core.dataset import ATTEMPTS_FILE, read_attempts
from trustroute.core.package import table_path
from trustroute.harness.study.config import LIVE_ENGINE


def run_order(study_dir: Path, manifest: dict, episodes: pd.DataFrame) -> pd.DataFrame:
    """`episodes` with `position` the place each was run at, for a live study with an attempts
    table (a done trial's `run_position`); any other study's episodes as they are."""
    if manifest.get("engine") != LIVE_ENGINE or not table_path(study_dir, ATTEMPTS_FILE).exists():
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
    orders, so there are none, and `fixed_order` lists the cells by position instead. A test that
    cannot be computed has p None and its reason in `cochran_q_note` / `friedman_note`."""
    tests: dict = {"cochran_q_p": None, "friedman_p": None, "participants": 0}
    positions = episodes["position"].nunique()
    complete = episodes.groupby("participant").filter(lambda g: g["position"].nunique() == positions)
    tests["participants"] = int(complete["participant"].nunique())
    fixed = fixed_order(episodes)
    if fixed is not None:
        return {**tests, "fixed_order": [list(cell) for cell in fixed]}
    if positions < 2:
        reason = "one position: no order to compare"
        return {**tests, "cochran_q_note": reason, "friedman_note": reason}
    if tests["participants"] < 2:
        reason = f"{TOO_FEW}: fewer than 2 participants drove every position"
        return {**tests, "cochran_q_note": reason, "friedman_note": reason}
    sat = complete.pivot_table(index="participant", columns="position", values=column, aggfunc="first")
    trust = complete.pivot_table(
        index="participant", columns="position", values="mean_reported_trust", aggfunc="first"
    ).dropna()
    # Friedman reads the participants with a report at every position, which can be fewer
    tests["friedman_participants"] = int(len(trust))
    tests["cochran_q_p"], tests["cochran_q_note"] = _cochran_q(sat.to_numpy())
    tests["friedman_p"], tests["friedman_note"] = _friedman(trust.to_numpy())
    return tests


def _cochran_q(satisfied: np.ndarray) -> tuple[float | None, str]:
    """Cochran's Q p-value of participants x positions, or None and why not."""
    from statsmodels.stats.contingency_tables import cochrans_q

    if satisfied.std() == 0:
        return None, "no variation: every episode's outcome the same"
    return float(cochrans_q(satisfied.astype(int)).pvalue), ""


def _friedman(trust: np.ndarray) -> tuple[float | None, str]:
    """Friedman's p-value of participants x positions (mean reported trust), or None and why not."""
    from scipy import stats

    if trust.shape[1] < 3:
        return None, f"{trust.shape[1]} positions: Friedman's test needs 3 or more"
    if len(trust) < 2:
        return None, f"{TOO_FEW}: fewer than 2 participants with a report at every position"
    if trust.std() == 0:
        return None, "no variation: every mean reported trust the same"
    return float(stats.friedmanchisquare(*trust.T).pvalue), ""


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
