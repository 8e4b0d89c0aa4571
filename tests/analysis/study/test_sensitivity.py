"""The sensitivity table: a comparison's interval depends on the outcomes compared, not on the belief
source's name, its place among the sources or which tables were computed before it."""

from __future__ import annotations

import pandas as pd

from tests.analysis.study.made_episodes import SOURCES, made_episodes
from trustroute.analysis.study.analysis import ANALYSIS_SEED
from trustroute.analysis.study.paired import all_pairs_table, condition_pairs, per_participant_table
from trustroute.analysis.study.sensitivity import sensitivity_table

SPECS, CONDITIONS = ["phi1", "phi2"], ["aware", "robust", "free"]
SHOWN = ["spec", "condition_a", "condition_b", "risk_difference", "rd_low", "rd_high"]


def _table(episodes: pd.DataFrame, sources, primary: str) -> pd.DataFrame:
    wide = per_participant_table(episodes, f"satisfied_{primary}", tuple(CONDITIONS))
    paired = all_pairs_table(wide, condition_pairs(CONDITIONS), SPECS, ANALYSIS_SEED, 400)
    return sensitivity_table(episodes, list(sources), primary, paired, CONDITIONS, SPECS, ANALYSIS_SEED, 400)


def _of(table: pd.DataFrame, source: str) -> list[dict]:
    return table.loc[table["source"] == source, SHOWN].reset_index(drop=True).to_dict("records")


def test_identical_outcomes_give_identical_intervals_on_every_source_in_any_order():
    episodes = made_episodes()   # the same outcomes on every source
    table = _table(episodes, SOURCES, "true")
    assert table.loc[table["spec"] == "all specs", "rd_low"].notna().all()
    lead = _of(table, "true")
    for source in SOURCES:
        assert _of(table, source) == lead, source
    for primary in ("filter", "reference"):   # another source leading, the sources in another order
        other = _table(episodes, reversed(SOURCES), primary)
        for source in SOURCES:
            assert _of(other, source) == lead, (primary, source)


def test_a_source_with_other_outcomes_keeps_the_others_intervals():
    episodes = made_episodes()
    flipped = episodes["participant"] % 3 == 0
    episodes.loc[flipped, "satisfied_reported"] = ~episodes.loc[flipped, "satisfied_reported"]
    table = _table(episodes, SOURCES, "true")
    assert _of(table, "reported") != _of(table, "true")
    assert _of(table, "filter") == _of(table, "true") == _of(table, "reference")
