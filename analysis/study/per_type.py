"""Per true driver type (studies with a `[drivers] population`, whose episodes carry the
participant's `driver_type`): the cells and the paired statistics of every pair of conditions, per
type and over all participants ("all").
"""

from __future__ import annotations

import pandas as pd

from trustroute.analysis.study.cells import cell_table
from trustroute.analysis.study.paired import (
    PAIRED_TESTS,
    condition_pairs,
    paired_table_rows,
    per_participant_table,
    with_holm,
)

ALL_TYPES = "all"
PER_TYPE_CELL_COLUMNS = (
    "spec", "condition", "n", "satisfied", "satisfaction_rate", "ci_low", "ci_high", "mean_trust",
    "trust_ci_low", "trust_ci_high", "trust_ci_method", "mean_true_trust", "takeovers_per_episode",
)


def per_type_tables(
    episodes: pd.DataFrame, spec_order, condition_order, belief_source: str, seed: int, resamples: int,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per true driver type and over all participants: the cells (satisfaction with exact CI, mean
    reported trust with bootstrap CI, mean true trust) and the paired statistics of every pair of
    conditions (paired.py `condition_pairs`), Holm-adjusted per type and spec. Empty without a
    `driver_type` in the episodes. The bootstraps are keyed by what they resample (cells.py,
    paired.py), so the "all" rows are the main tables' rows."""
    if "driver_type" not in episodes or not episodes["driver_type"].notna().any():
        return pd.DataFrame(), pd.DataFrame()
    names = sorted(episodes["driver_type"].dropna().unique())
    groups = [(name, episodes[episodes["driver_type"] == name]) for name in names]
    groups.append((ALL_TYPES, episodes))
    column = f"satisfied_{belief_source}"
    cells, paired = [], []
    for name, group in groups:
        table = cell_table(group, spec_order, condition_order, belief_source, {}, seed, resamples)
        cells.append(table[list(PER_TYPE_CELL_COLUMNS)].assign(
            driver_type=name, participants=group["participant"].nunique()))
        for pair in condition_pairs(condition_order):
            rows = paired_table_rows(per_participant_table(group, column, pair), pair, spec_order, seed,
                                     resamples)
            if len(rows):
                paired.append(rows.assign(driver_type=name))
    cell_frame = pd.concat(cells, ignore_index=True)
    cell_frame = cell_frame[["driver_type", "participants", *PER_TYPE_CELL_COLUMNS]]
    if not paired:
        return cell_frame, pd.DataFrame()
    paired_frame = with_holm(pd.concat(paired, ignore_index=True), ["driver_type", "spec"], PAIRED_TESTS)
    return cell_frame, paired_frame[["driver_type", *[c for c in paired_frame.columns if c != "driver_type"]]]
