"""The report's certified bounds (a policy's exact value [L, U], the synthesized [L, U]) are shown
rounded outward, L down and U up, as every command prints them (trustroute/core/wording.py): a lower
bound a hair below 1 never reads as 1."""

from __future__ import annotations

import dataclasses

import pandas as pd

from trustroute.analysis.study.analysis import study_analysis
from trustroute.analysis.study.display import display_tables
from trustroute.analysis.study.paper_comparison import paper_comparison

BELOW, ABOVE = 1.0 - 4e-6, 0.5 + 4e-6   # a certified L a hair below 1, a U a hair above 0.5


def test_the_cells_table_rounds_every_certified_interval_outward(model_study):
    analysis = study_analysis(model_study, resamples=20)
    cells = analysis.cells.copy()
    cells["exact_lower"], cells["exact_upper"] = 0.5 - 4e-6, ABOVE
    cells["synthesized_lower"], cells["synthesized_upper"] = BELOW, 1.0
    shown = display_tables(dataclasses.replace(analysis, cells=cells))["cells"]
    assert set(shown["exact value [L, U]"]) == {"[0.499, 0.501]"}
    assert set(shown["synthesized [L, U]"]) == {"[0.999, 1.000]"}


def test_the_paper_comparison_rounds_the_synthesized_bounds_outward():
    episodes = pd.DataFrame({"spec": ["phi1", "phi2"] * 2, "condition": ["aware"] * 2 + ["free"] * 2,
                             "satisfied_true": [True, False, True, True],
                             "mean_reported_trust": [5.0, 4.0, 3.0, 6.0]})
    cells = pd.DataFrame({"spec": ["phi1", "phi2"], "condition": ["aware", "aware"],
                          "synthesized_lower": [BELOW, 0.25], "synthesized_upper": [1.0, ABOVE],
                          "synthesized_horizon": [20, 20]})
    ours = {row["figure"]: row["ours"] for row in paper_comparison(episodes, cells, "true")}
    assert ours["Pr_max(phi1), synthesized, ours within H=20 junctions"] == "[0.9999, 1.0000]"
    assert ours["Pr_max(phi2), synthesized, ours within H=20 junctions"] == "[0.2500, 0.5001]"
