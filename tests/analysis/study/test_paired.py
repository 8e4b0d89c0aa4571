"""The paired tables on separated data: every unbounded odds ratio is shown with its reason."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

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
    rows = paired_table_rows(wide, ("aware", "free"), ["phi1", "phi2"], 20240513, 200)
    shown = paired_display(rows)
    assert "odds ratio note" in shown
    for text, note in zip(shown["conditional OR [exact CI]"], shown["odds ratio note"], strict=True):
        if "inf" in text:
            assert re.search(r"discordant pairs? favours? aware", note), note
        assert "inf [" not in text  # the estimate itself is finite


@pytest.mark.slow
def test_the_report_shows_no_unbounded_odds_ratio_without_its_reason(model_study, model_report):
    payload = model_report
    for row in payload["paired"]:
        for key in ("odds_ratio", "or_low", "or_high"):
            value = row.get(key)
            if value is not None and (value == math.inf or value == 0.0):
                assert re.search(r"discordant pairs? favours? ", row["or_note"]), row
        if row.get("odds_ratio") is not None:
            assert math.isfinite(row["odds_ratio"])
    for row in payload["repeated_measures"]:
        if row["estimate"] is not None:
            assert math.isfinite(row["estimate"]) and row["estimate"] < 1e6, row
            if row["high"] == math.inf or row["low"] == 0.0:
                assert "separation" in row["note"], row
    for cell in payload["cells"]:   # probabilities and their intervals lie in [0, 1]
        assert 0.0 <= cell["ci_low"] <= cell["satisfaction_rate"] <= cell["ci_high"] <= 1.0
    html = (model_study / "report.html").read_text()
    intervals = re.findall(r"\[(-?[\d.]+|inf), (-?[\d.]+|inf)\]", html)
    assert intervals and all(float(v) < 1e6 for pair in intervals for v in pair if v != "inf")


def _three_spec_episodes() -> pd.DataFrame:
    """16 participants x 3 specs x (aware, robust, free), outcomes drawn so that the participants'
    mean differences over specs tie often and take both signs."""
    rng = np.random.default_rng(21)
    rows = []
    for person in range(16):
        for spec in ("s1", "s2", "s3"):
            for condition, chance in (("aware", 0.8), ("robust", 0.6), ("free", 0.4)):
                rows.append({"participant": person, "spec": spec, "condition": condition,
                             "satisfied": bool(rng.random() < chance),
                             "mean_reported_trust": float(rng.integers(1, 8))})
    return pd.DataFrame(rows)


def test_the_all_specs_satisfaction_test_is_the_exact_sign_test_with_holm():
    """The "all specs" row's sign test p is the two-sided binomial test of the participants ahead
    under A among those not tied (their mean satisfaction over specs), and its Holm value adjusts
    it over the pairs of conditions."""
    from scipy import stats
    from statsmodels.stats.multitest import multipletests

    from trustroute.analysis.study.paired import ALL_SPECS, all_pairs_table, condition_pairs

    episodes = _three_spec_episodes()
    conditions = ("aware", "robust", "free")
    wide = per_participant_table(episodes, "satisfied", conditions)
    table = all_pairs_table(wide, condition_pairs(conditions), ["s1", "s2", "s3"], 20240513, 200)
    rows = table[table["spec"] == ALL_SPECS].set_index(["condition_a", "condition_b"])
    expected = {}
    for a, b in condition_pairs(conditions):
        rate = episodes.pivot_table(index="participant", columns="condition", values="satisfied",
                                    aggfunc="mean")
        difference = rate[a] - rate[b]
        ahead, behind = int((difference > 0).sum()), int((difference < 0).sum())
        expected[(a, b)] = stats.binomtest(ahead, ahead + behind, 0.5).pvalue
        assert rows.loc[(a, b), "sign_test_p"] == pytest.approx(expected[(a, b)], rel=1e-12)
        assert (rows.loc[(a, b), "a_ahead"], rows.loc[(a, b), "b_ahead"]) == (ahead, behind)
    assert len({round(p, 12) for p in expected.values()}) == 3   # three different tests
    adjusted = multipletests(list(expected.values()), method="holm")[1]
    for (pair, _), holm_p in zip(expected.items(), adjusted, strict=True):
        assert rows.loc[pair, "sign_test_p_holm"] == pytest.approx(holm_p, rel=1e-12)
    shown = paired_display(table)
    assert "participants ahead A / B" in shown and "sign test p (satisfaction)" in shown
