"""The paper's figures are written once (analysis/paper_figures.py); the documentation's table
of them (docs/study.md, "Headline figures of the paper") and every reader agree with it."""

from __future__ import annotations

from pathlib import Path

from trustroute.analysis import paper_figures
from trustroute.analysis.carla_study.analysis import paper_matches

ROOT = Path(__file__).resolve().parents[2]


def documented_figures() -> dict[str, str]:
    text = (ROOT / "docs" / "study.md").read_text()
    section = text.split("## Headline figures of the paper", 1)[1].split("\n## ", 1)[0]
    rows = [line.strip("|").split("|") for line in section.splitlines() if line.startswith("| ")]
    return {figure.strip(): value.strip() for figure, value in rows[1:]}


def test_the_documented_table_is_the_module():
    documented = documented_figures()
    assert documented["Pr_max(φ1)"] == str(paper_figures.PR_MAX["phi1"])
    assert documented["Pr_max(φ2)"] == str(paper_figures.PR_MAX["phi2"])
    assert documented["participants satisfying φ1 / φ2 (aware)"] == (
        f"{paper_figures.count_text('phi1')}, {paper_figures.count_text('phi2')}")
    assert documented["satisfaction aware vs free"] == paper_figures.aware_vs_free_text(
        paper_figures.SATISFACTION_RATE)
    assert documented["average trust aware vs free"] == paper_figures.aware_vs_free_text(
        paper_figures.MEAN_TRUST)


def test_printed_forms():
    assert paper_figures.count_text("phi1") == "18/21" and paper_figures.count_text("phi2") == "17/21"
    assert paper_figures.aware_vs_free_text(paper_figures.SATISFACTION_RATE) == "0.85 vs 0.775"
    assert paper_figures.aware_vs_free_text(paper_figures.MEAN_TRUST) == "4.6018 vs 4.3933"
    assert all(n == paper_figures.PARTICIPANTS for _, n in paper_figures.SATISFIED_AWARE.values())


def test_the_real_study_matches_against_the_module():
    figures = [{"figure": "satisfaction rate", "reading": "r", "subset": "s", "aware": 0.8504, "free": 0.7},
               {"figure": "phi1 satisfied (count)", "reading": "r", "subset": "s", "aware": "18/21",
                "free": None}]
    matches = {m["figure"]: m for m in paper_matches(figures)}
    assert matches["satisfaction rate (aware)"]["paper"] == paper_figures.SATISFACTION_RATE["aware"]
    assert [h["value"] for h in matches["satisfaction rate (aware)"]["reproduced_by"]] == [0.8504]
    assert matches["satisfaction rate (free)"]["reproduced_by"] == []
    assert [h["value"] for h in matches["phi1 satisfied (count) (aware)"]["reproduced_by"]] == ["18/21"]


def test_a_paper_count_sought_in_the_free_condition_is_named_as_the_aware_figure_it_is():
    """The paper printed 18/21 and 17/21 for the aware condition only: where the real study's free
    readings are searched for them, the match names the aware figure, never a free figure the paper
    does not have."""
    figures = [{"figure": "phi2 satisfied (count)", "reading": "r", "subset": "s", "aware": "14/14",
                "free": "17/21"}]
    matches = [m for m in paper_matches(figures) if m["figure"].startswith("phi2 satisfied")]
    assert [(m["figure"], [h["value"] for h in m["reproduced_by"]]) for m in matches] == [
        ("phi2 satisfied (count) (aware)", []),
        ("phi2 satisfied (count) (aware), sought in the free condition", ["17/21"])]
    assert all(m["paper"] == paper_figures.count_text("phi2") for m in matches)
