"""`trustroute analyze` and the report on a finished model-engine study."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from tests.cli import run_cli
from trustroute.analysis.statistics import rate_interval
from trustroute.analysis.study.display import TABLE_TITLES


@pytest.mark.slow
def test_analyze_json_and_self_contained_report(model_study, model_report):
    payload = model_report
    assert payload["belief_source"] == "true"
    assert payload["paths"] == {"report_markdown": str(model_study / "report.md"),
                                "report_html": str(model_study / "report.html"),
                                "plots": str(model_study / "plots")}
    cells = {(c["spec"], c["condition"]): c for c in payload["cells"]}
    assert set(cells) == {(s, c) for s in ("phi1", "phi2") for c in ("aware", "free")}
    for cell in cells.values():
        assert cell["n"] == 12
        assert (cell["ci_low"], cell["ci_high"]) == pytest.approx(rate_interval(cell["satisfied"], 12))
        assert (cell["wilson_low"], cell["wilson_high"]) == pytest.approx(
            rate_interval(cell["satisfied"], 12, method="wilson"))
        assert 1 <= cell["mean_trust"] <= 7
        assert cell["satisfaction_rate"] == pytest.approx(cell["satisfied"] / cell["n"])
        # the default leads with each driver's true filter; each AV's own filter is shown beside
        assert cell["satisfaction_rate_filter"] == pytest.approx(cell["logged_satisfaction_rate"])
        assert cell["exact_lower"] is not None
    assert cells[("phi1", "aware")]["synthesized_lower"] is not None
    paired = {p["spec"]: p for p in payload["paired"]}
    assert set(paired) == {"phi1", "phi2", "all specs"}
    for spec in ("phi1", "phi2"):
        p = paired[spec]
        assert p["pairs"] == 12 and 0 <= p["mcnemar_p"] <= 1 and 0 <= p["wilcoxon_p"] <= 1
        assert p["risk_difference"] == pytest.approx((p["only_a_satisfied"] - p["only_b_satisfied"]) / 12)
        assert p["rd_low"] <= p["risk_difference"] <= p["rd_high"]
        assert p["trust_diff_low"] <= p["trust_difference"] <= p["trust_diff_high"]
    # Both specs together: 12 participants, never 24 independent pairs.
    assert paired["all specs"]["pairs"] == 12 and paired["all specs"]["unit"].startswith("participant")
    models = {r["outcome"]: r for r in payload["repeated_measures"]}
    assert len(models) == 2 and all(r["participants"] <= 12 and r["episodes"] == 48 for r in models.values())
    episodes = pd.read_parquet(model_study / "episodes.parquet")
    roads = pd.read_parquet(model_study / "roads.parquet")
    met = roads[(roads["index"] > 0) & (roads["incident"].fillna("") != "")]
    takeovers = payload["takeovers"]
    assert sum(t["roads"] for t in takeovers) == len(met)
    assert sum(t["takeovers"] for t in takeovers) == int(met["takeover"].sum())
    for t in takeovers:
        assert (t["ci_low"], t["ci_high"]) == pytest.approx(rate_interval(t["takeovers"], t["roads"]))
    assert [o["position"] for o in payload["order"]] == [1, 2, 3, 4]
    assert all(o["n"] == 12 for o in payload["order"])
    assert sum(c["n"] for c in payload["carryover"]) == len(episodes)
    # 12 synthetic participants are not the paper's study: no paper table, a note instead.
    assert payload["paper_comparison"] == []
    assert "not comparable" in payload["paper_note"] and "12 participants" in payload["paper_note"]

    html = (model_study / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 5
    assert "http://" not in html and "https://" not in html and "<script" not in html
    markdown = (model_study / "report.md").read_text()
    for needle in ("beliefs: true", "beliefs: reported", "exact 95% CI", "Wilson 95% CI", "risk difference",
                   "conditional OR", "conditional logit", "mixed model", "Takeover rate per incident type",
                   "Latin square", "Carry-over", "not comparable", "synthesized [L, U]", "McNemar"):
        assert needle in markdown, needle
    assert re.search(r"\d\.\d\de[-+]\d\d", markdown) and "0.0000" not in markdown
    # a table whose figures do not depend on the belief source names none in its heading
    assert "## Takeover rate per incident type and condition\n" in markdown
    assert "## Order effects: by position in each participant's order (beliefs: true)\n" in markdown
    assert "<h2>Takeover rate per incident type and condition</h2>" in html
    for name in ("satisfaction", "trust", "routes", "takeovers", "participants"):
        assert (model_study / "plots" / f"{name}.png").stat().st_size > 1000
    # a synthetic study has no questionnaires and no manual driving: no section for them, not even empty
    for name in ("questionnaires", "questionnaire_tests", "manual"):
        assert TABLE_TITLES[name] not in markdown and TABLE_TITLES[name] not in html, name


def test_the_report_has_a_section_for_every_table_the_terminal_shows():
    """Each display table is in exactly one of the report's sections: a table the terminal and
    `--json` show is never left out of the report files."""
    from trustroute.analysis.study.report import ONCE_TABLES, OWN_SECTION_TABLES, PER_SOURCE_TABLES

    sections = [*PER_SOURCE_TABLES, *ONCE_TABLES, *OWN_SECTION_TABLES]
    assert sorted(sections) == sorted(TABLE_TITLES)


def test_paper_table_only_for_a_comparable_study():
    from trustroute.analysis.study.paper_comparison import is_paper_comparable
    from trustroute.core.packaged import PACKAGED_SPECS

    episodes = pd.DataFrame({"condition": ["aware", "free"]})
    specs = [str(PACKAGED_SPECS / "phi1.toml"), str(PACKAGED_SPECS / "phi2.toml")]
    assert is_paper_comparable({"config": {"participants": 21, "specs": specs, "town": None}}, episodes)[0]
    ok, note = is_paper_comparable({"config": {"participants": 1000, "specs": specs}}, episodes)
    assert not ok and "1000 participants" in note
    strict = [str(PACKAGED_SPECS / "phi1_strict.toml"), specs[1]]
    ok, note = is_paper_comparable({"config": {"participants": 21, "specs": strict}}, episodes)
    assert not ok and "phi1" in note


@pytest.mark.slow
def test_analyze_reported_source_text(model_study, capsys):
    code, out, _ = run_cli(capsys, "analyze", str(model_study), "--belief-source", "reported", "--no-report")
    assert code == 0
    assert "satisfaction on beliefs from: reported" in out


def test_analyze_not_a_study_exit_2(tmp_path, capsys):
    code, _, err = run_cli(capsys, "analyze", str(tmp_path))
    assert code == 2 and "not a finished study directory" in err


def test_the_docs_and_notes_name_the_intervals_the_code_computes():
    """The cells' satisfaction interval is exact and Wilson (cells.py), not a bootstrap; the all-specs
    difference is the mean over specs, not a count of specs; a bootstrap bound says how approximate
    it is."""
    from pathlib import Path

    from trustroute.analysis.study import analysis
    from trustroute.analysis.study.report import NOTES

    study_doc = (Path(__file__).resolve().parents[3] / "docs" / "study.md").read_text()
    bullet = " ".join(study_doc.split("- **Analysis** (`analysis/study/`):")[1].split("\n- ")[0].split())
    assert "satisfaction rate with its exact (Clopper–Pearson) and Wilson intervals" in bullet, bullet
    assert "bootstrap CI" not in bullet
    assert "number of specs" not in " ".join((analysis.__doc__ or "").split())
    assert any("third decimal is not reliable" in note for note in NOTES)
