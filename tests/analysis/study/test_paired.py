"""The paired tables on separated data: every unbounded odds ratio is shown with its reason."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from trustroute.analysis.study.display import paired_display
from trustroute.analysis.study.paired import paired_table_rows, per_participant_table, repeated_measures_table


def _episodes() -> pd.DataFrame:
    """21 participants x 2 specs x (aware, free); the 6 who differ all favour aware."""
    pattern = [[(1, 0), (1, 1)]] * 3 + [[(1, 1), (1, 0)]] * 3
    pattern += [[(1, 1), (1, 1)]] * 10 + [[(0, 0), (0, 0)]] * 5
    rows = []
    for person, cells in enumerate(pattern):
        for spec, (aware, free) in zip(("phi1", "phi2"), cells, strict=True):
            for condition, satisfied in (("aware", aware), ("free", free)):
                rows.append({"participant": f"p{person:02d}", "spec": spec, "condition": condition,
                             "satisfied": bool(satisfied), "mean_reported_trust": 4.0 + 0.1 * person})
    return pd.DataFrame(rows)


def test_repeated_measures_row_on_separated_data_is_exact_and_says_why():
    row = repeated_measures_table(_episodes(), "satisfied", ("aware", "free")).iloc[0]
    assert math.isfinite(row["estimate"]) and row["low"] > 1 and row["high"] == math.inf
    assert row["estimate"] < 100 and 0 < row["p_value"] < 0.05
    assert "separation" in row["note"] and "aware" in row["note"]


def test_paired_display_names_the_reason_beside_an_unbounded_odds_ratio():
    episodes = _episodes()
    wide = per_participant_table(episodes, "satisfied", ("aware", "free"))
    rows = paired_table_rows(wide, ("aware", "free"), ["phi1", "phi2"], np.random.default_rng(0), 200)
    shown = paired_display(rows)
    assert "odds ratio note" in shown
    for text, note in zip(shown["conditional OR [exact CI]"], shown["odds ratio note"], strict=True):
        if "inf" in text:
            assert "discordant pairs favour aware" in note
        assert "inf [" not in text  # the estimate itself is finite
