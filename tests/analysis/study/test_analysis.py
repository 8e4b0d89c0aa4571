"""The analysis as JSON: every p-value and estimate at full precision."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from trustroute.analysis.study.analysis import StudyAnalysis


def test_json_keeps_tiny_p_values_and_every_digit():
    """A McNemar p of 2e-12 (40 discordant pairs, all one way) is written as itself, not rounded to 10
    decimal places (0); missing and infinite values are null."""
    tiny = float(stats.binomtest(40, 40, 0.5).pvalue)       # 2 / 2**40
    assert tiny < 5e-10
    paired = pd.DataFrame({
        "spec": ["phi1", "phi2", "all specs"], "pairs": np.array([40, 40, 40], dtype=np.int64),
        "mcnemar_p": [tiny, 1.5e-09, None], "or_high": [math.inf, 2.0, math.nan],
        "trust_difference": [0.1234567890123456789, 1.0 / 3.0, -2.5e-13],
        "or_note": ["", "why", None], "fallback_only": np.array([True, False, True]),
    })
    empty = pd.DataFrame()
    analysis = StudyAnalysis(
        study_dir=Path("study"), belief_source="true", manifest={}, cells=empty, paired=paired,
        repeated=empty, takeovers=empty, order=empty, order_tests={}, carryover=empty,
        per_participant=empty, paper=empty, paper_note="", satisfaction=empty, episodes=empty)
    rows = json.loads(json.dumps(analysis.to_dict()))["paired"]
    assert [r["mcnemar_p"] for r in rows] == [tiny, 1.5e-09, None]
    assert [r["trust_difference"] for r in rows] == [0.1234567890123456789, 1.0 / 3.0, -2.5e-13]
    assert [r["or_high"] for r in rows] == [None, 2.0, None]
    assert [r["pairs"] for r in rows] == [40, 40, 40]
    assert [r["or_note"] for r in rows] == ["", "why", None]
    assert [r["fallback_only"] for r in rows] == [True, False, True]
