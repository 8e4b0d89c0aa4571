"""`trustroute analyze` and the report on a finished model-engine study."""

from __future__ import annotations

import json

import pytest

from tests.cli import run_cli


@pytest.mark.slow
def test_analyze_json_and_self_contained_report(model_study, capsys):
    code, out, err = run_cli(capsys, "analyze", str(model_study), "--json", "--report")
    assert code == 0, err
    payload = json.loads(out)
    assert payload["paths"] == {"report_markdown": str(model_study / "report.md"),
                                "report_html": str(model_study / "report.html")}
    cells = {(c["spec"], c["condition"]): c for c in payload["cells"]}
    assert set(cells) == {(s, c) for s in ("phi1", "phi2") for c in ("aware", "free")}
    for cell in cells.values():
        assert cell["n"] == 12
        assert cell["ci_low"] <= cell["satisfaction_rate"] <= cell["ci_high"]
        assert 1 <= cell["mean_trust"] <= 7
        assert cell["satisfaction_rate"] == pytest.approx(cell["satisfied"] / cell["n"])
        assert cell["satisfaction_rate"] == pytest.approx(cell["logged_satisfaction_rate"])  # filter source
        assert cell["exact_lower"] is not None
    assert cells[("phi1", "aware")]["synthesized_lower"] is not None
    paired = {p["spec"]: p for p in payload["paired"]}
    assert set(paired) == {"phi1", "phi2", "all"}
    for p in paired.values():
        assert 0 <= p["mcnemar_p"] <= 1 and 0 <= p["wilcoxon_p"] <= 1
    assert paired["all"]["pairs"] == 24
    figures = {r["figure"]: r for r in payload["paper_comparison"]}
    assert figures["satisfaction aware vs free"]["paper"] == "0.85 vs 0.775"
    assert figures["participants satisfying phi1 (aware)"]["paper"] == "18/21"

    html = (model_study / "report.html").read_text()
    assert html.count("data:image/png;base64,") == 3
    assert "http://" not in html and "https://" not in html and "<script" not in html
    markdown = (model_study / "report.md").read_text()
    for needle in (
        "beliefs: filter",
        "beliefs: reported",
        "0.85 vs 0.775",
        "4.6018 vs 4.3933",
        "18/21",
        "17/21",
        "synthesized [L, U]",
        "McNemar",
    ):
        assert needle in markdown
    for name in ("satisfaction", "trust", "routes"):
        assert (model_study / "plots" / f"{name}.png").stat().st_size > 1000


@pytest.mark.slow
def test_analyze_reported_source_text(model_study, capsys):
    code, out, _ = run_cli(capsys, "analyze", str(model_study), "--belief-source", "reported", "--no-report")
    assert code == 0
    assert "satisfaction on beliefs from: reported" in out


def test_analyze_not_a_study_exit_2(tmp_path, capsys):
    code, _, err = run_cli(capsys, "analyze", str(tmp_path))
    assert code == 2 and "not a finished study directory" in err
