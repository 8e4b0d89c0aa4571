"""How much a study's comparisons depend on the belief source the specs are evaluated on.

For every pair of conditions (paired.py `condition_pairs`) and every spec, and over the specs per
participant ("all specs"), the satisfaction difference A − B with its interval on every belief
source the study has (analysis/belief_sources.py): Newcombe's interval per spec, the BCa bootstrap
of the participants' mean differences over specs. The primary source's rows are those of the
paired table itself; another source's come from the same code on its column. Every bootstrap is
keyed by what it resamples (statistics.py `keyed_rng`: the statistic, the spec, the pair), so two
sources with the same outcomes show the same interval, and no source's figures depend on which
sources precede it.
"""

from __future__ import annotations

import pandas as pd

from trustroute.analysis.study.paired import all_pairs_table, condition_pairs, per_participant_table

SENSITIVITY_COLUMNS = ("spec", "condition_a", "condition_b", "pairs", "risk_difference", "rd_low", "rd_high",
                       "rd_method")


def sensitivity_table(episodes: pd.DataFrame, sources: list[str], primary: str, paired: pd.DataFrame,
                      condition_order: list[str], spec_order: list[str], seed: int,
                      resamples: int) -> pd.DataFrame:
    """One row per (pair, spec, source): the satisfaction difference and its interval; `primary`
    marks the source the other tables lead with (its rows are `paired`'s)."""
    pairs = condition_pairs(condition_order)
    if not pairs or not len(episodes) or not len(paired):
        return pd.DataFrame()
    frames = []
    for source in sources:
        if source == primary:
            rows = paired
        else:
            column = f"satisfied_{source}"
            wide = per_participant_table(episodes, column, tuple(condition_order))
            rows = all_pairs_table(wide, pairs, spec_order, seed, resamples)
        frames.append(rows[list(SENSITIVITY_COLUMNS)].assign(source=source, primary=source == primary))
    return pd.concat(frames, ignore_index=True)
