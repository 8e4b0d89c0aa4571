"""A bootstrap interval is labelled with the method that gave it, wherever it is shown.

`mean_difference` (analysis/statistics.py) gives the BCa interval; where BCa is undefined it gives
the percentile interval, and where every difference is the same no interval but the point. The
input that makes BCa undefined is an ordinary one: every participant's mean reported trust one level
higher under A, on episodes of different lengths. The differences are then 1 up to rounding, every
leave-one-out mean is the same float, and scipy's acceleration is 0/0 (nan). A single differing
pair, or a few participants, do not: scipy computes BCa there. Each label is checked against scipy
itself on the same Generator; the paired table's rows (`--json`), its display (the terminal and the
report) and the sensitivity table name the method beside every interval that is not BCa.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pandas as pd
from scipy import stats

from trustroute.analysis.statistics import (
    BOOTSTRAP_BCA,
    BOOTSTRAP_DEGENERATE,
    BOOTSTRAP_PERCENTILE,
    NEWCOMBE,
    keyed_rng,
    mean_difference,
)
from trustroute.analysis.study.display import paired_display, sensitivity_display
from trustroute.analysis.study.paired import (
    ALL_SPECS,
    TRUST_DIFFERENCE,
    paired_table_rows,
    per_participant_table,
)
from trustroute.analysis.study.sensitivity import SENSITIVITY_COLUMNS

RESAMPLES = 2000
SEED = 20240513


def one_level_higher(participants: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Each participant's mean reported trust under A and under B over 2-8 reports, A's every report
    one level above B's: differences of 1 up to rounding."""
    rng = np.random.default_rng(seed)
    first, second = [], []
    for _ in range(participants):
        reports = rng.integers(1, 7, size=int(rng.integers(2, 9)))
        first.append(float(np.mean(reports + 1)))
        second.append(float(np.mean(reports)))
    return np.array(first), np.array(second)


def scipy_interval(data: np.ndarray, generator: np.random.Generator, method: str) -> tuple[float, float]:
    with warnings.catch_warnings(), np.errstate(invalid="ignore"):
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        found = stats.bootstrap((data,), np.mean, n_resamples=RESAMPLES, method=method, rng=generator)
    return float(found.confidence_interval.low), float(found.confidence_interval.high)


def assert_labelled_truly(first: np.ndarray, second: np.ndarray, seed: int) -> str:
    """mean_difference's interval is what scipy gives by the method it names, on the same draws
    (the percentile interval from the draws after the BCa attempt); returns the method."""
    found = mean_difference(first, second, np.random.default_rng(seed), RESAMPLES)
    difference = first - second
    if found.method == BOOTSTRAP_DEGENERATE:
        assert np.all(difference == difference[0]) and found.low == found.high == found.value
        return found.method
    generator = np.random.default_rng(seed)
    bca = scipy_interval(difference, generator, "BCa")
    if found.method == BOOTSTRAP_BCA:
        assert (found.low, found.high) == bca
    else:
        assert found.method == BOOTSTRAP_PERCENTILE and all(math.isnan(v) for v in bca)
        assert (found.low, found.high) == scipy_interval(difference, generator, "percentile")
    return found.method


def test_each_interval_is_labelled_with_the_method_that_gave_it():
    rng = np.random.default_rng(3)
    spread = rng.normal(4.6, 1, 21), rng.normal(4.4, 1, 21)
    assert assert_labelled_truly(*spread, 5) == BOOTSTRAP_BCA
    first, second = one_level_higher(21, 0)
    assert len(set((first - second).tolist())) > 1        # not all equal: resampled
    assert assert_labelled_truly(first, second, 5) == BOOTSTRAP_PERCENTILE
    methods = [assert_labelled_truly(*one_level_higher(n, seed), seed) for n in (5, 21) for seed in range(20)]
    assert methods.count(BOOTSTRAP_PERCENTILE) >= 20
    # a single differing pair, two or three pairs: BCa is defined
    for first, second in ((np.r_[np.zeros(20), 1.0], np.zeros(21)), (np.array([0.0, 1.0]), np.zeros(2)),
                          (np.array([0.0, 0.0, 2.0]), np.zeros(3))):
        assert assert_labelled_truly(first, second, 7) == BOOTSTRAP_BCA
    # every difference the same (or one pair): the point, said so
    assert assert_labelled_truly(np.arange(5.0) + 1, np.arange(5.0), 7) == BOOTSTRAP_DEGENERATE
    assert assert_labelled_truly(np.array([3.0]), np.array([1.0]), 7) == BOOTSTRAP_DEGENERATE


def test_a_fallback_warns_nothing():
    """The BCa attempt's nan is handled: no warning reaches the terminal."""
    first, second = one_level_higher(21, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = mean_difference(first, second, np.random.default_rng(5), RESAMPLES)
    assert found.method == BOOTSTRAP_PERCENTILE


def _episodes() -> pd.DataFrame:
    """21 participants x 2 specs x (aware, free): trust one level higher under aware (episodes of
    different lengths), the same outcome under both conditions."""
    first, second = one_level_higher(42, 0)
    rows = []
    for person in range(21):
        for k, spec in enumerate(("phi1", "phi2")):
            for condition, trust in (("aware", first[2 * person + k]), ("free", second[2 * person + k])):
                rows.append({"participant": f"p{person:02d}", "spec": spec, "condition": condition,
                             "satisfied": person % 3 == 0, "mean_reported_trust": trust})
    return pd.DataFrame(rows)


def test_the_tables_name_the_method_of_every_interval_that_is_not_bca():
    wide = per_participant_table(_episodes(), "satisfied", ("aware", "free"))
    rows = paired_table_rows(wide, ("aware", "free"), ["phi1", "phi2"], SEED, RESAMPLES)
    per_spec, everything = rows[rows["spec"] != ALL_SPECS], rows[rows["spec"] == ALL_SPECS].iloc[0]
    # the rows (--json): the method beside every interval, as computed
    assert set(per_spec["rd_method"]) == {NEWCOMBE}
    assert everything["rd_method"] == BOOTSTRAP_DEGENERATE          # no participant differs
    assert (everything["rd_low"], everything["rd_high"]) == (0.0, 0.0)
    for _, row in per_spec.iterrows():
        group = wide[wide["spec"] == row["spec"]]
        again = mean_difference(group["trust_aware"], group["trust_free"],
                                keyed_rng(SEED, TRUST_DIFFERENCE, row["spec"], "aware", "free"), RESAMPLES)
        assert (row["trust_diff_low"], row["trust_diff_high"], row["trust_diff_method"]) == (
            again.low, again.high, again.method)
    assert BOOTSTRAP_PERCENTILE in set(rows["trust_diff_method"])
    # the display (terminal and report): the method after each interval that is not BCa
    shown = paired_display(rows)
    for text, method in zip(shown["trust difference [BCa CI]"], rows["trust_diff_method"], strict=True):
        assert text.endswith(f"] ({method})") if method != BOOTSTRAP_BCA else text.endswith("]")
    risk = dict(zip(rows["spec"], shown["risk difference [95% CI]"], strict=True))
    assert risk[ALL_SPECS].endswith(f"({BOOTSTRAP_DEGENERATE})") and risk["phi1"].endswith("]")
    sensitivity = rows[list(SENSITIVITY_COLUMNS)].assign(source="true", primary=True)
    cells = sensitivity_display(sensitivity).set_index("spec")["true (primary)"]
    assert cells[ALL_SPECS].endswith(f"({BOOTSTRAP_DEGENERATE})") and cells["phi1"].endswith("]")
