"""The report of a live study with questionnaires and takeovers: its Markdown and HTML files show the
questionnaire scores, their paired tests and the manual-driving table with the figures of
`analyze --json`, rounded and marked as the terminal shows them."""

from __future__ import annotations

import json
import re
from html.parser import HTMLParser

import pytest
from fastapi.testclient import TestClient

from tests.cli import run_cli
from tests.harness.live.conftest import TINY
from tests.harness.live.test_live_manual import play_in
from trustroute.analysis.formatting import MISSING
from trustroute.analysis.study.analysis import MULTIPLICITY
from trustroute.analysis.study.display import APPROXIMATE_MARK, TABLE_TITLES
from trustroute.harness.live.app import live_app
from trustroute.harness.live.scripted import ScriptedParticipant
from trustroute.harness.live.server import LiveStudy, ServerOptions
from trustroute.harness.study.config import load_study_config

pytestmark = [pytest.mark.slow, pytest.mark.wallclock]
PARTICIPANTS = 3
QUESTIONNAIRES = """
[questionnaires]
after_each_trial = ["jian"]
"""


class SpreadAnswers(ScriptedParticipant):
    """A scripted participant whose answers differ between items, trials and participants (the
    scripted participant answers every item at the scale's middle, whose scores have no spread, no
    alpha and no Wilcoxon p to show)."""

    def answer_questionnaire(self, questionnaire: dict) -> dict:
        scale = questionnaire["scale"]
        points = int((scale["max"] - scale["min"]) / scale["step"]) + 1
        return {"type": "answers", "questionnaire": questionnaire["name"],
                "answers": {item["id"]: scale["min"] + scale["step"] * (
                    (3 * self.participant + 2 * index + len(self.episodes)) % points)
                    for index, item in enumerate(questionnaire["items"])}}


@pytest.fixture(scope="module")
def live_study_dir(tmp_path_factory):
    """Three participants of φ1 under aware and free, in lockstep (the episodes of `trustroute
    study` on the same seeds, takeovers included), the Jian questionnaire after each trial."""
    root = tmp_path_factory.mktemp("live-report")
    path = root / "live.toml"
    path.write_text(TINY.format(participants=PARTICIPANTS, specs='["phi1"]')
                    .replace('conditions = ["free"]', 'conditions = ["aware", "free"]') + QUESTIONNAIRES)
    config = load_study_config(path)
    study = LiveStudy(config, root / "study", ServerOptions(pace=1e4, warm_up=False)).open()
    try:
        with TestClient(live_app(study)) as client:
            for participant in range(PARTICIPANTS):
                assert play_in(client, study, SpreadAnswers(config, participant, lockstep=True)).finished
    finally:
        study.close()
    return root / "study"


def markdown_tables(text: str) -> dict[str, list[list[str]]]:
    """{section heading: the rows of its first table, the header first} of a Markdown report."""
    tables = {}
    for section in text.split("\n## ")[1:]:
        heading, *lines = section.split("\n")
        rows = [[cell.strip() for cell in line.strip()[1:-1].split(" | ")] for line in lines
                if line.startswith("| ")]
        if rows:
            tables[heading] = rows
    return tables


class HtmlTables(HTMLParser):
    """{h2 heading: the rows of the first table after it, the header first} of an HTML report."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.heading, self.text, self.row, self.rows = "", "", None, None

    def handle_starttag(self, tag, attrs):
        if tag in ("h2", "td", "th"):
            self.text = ""
        elif tag == "table" and self.heading not in self.tables:
            self.rows = self.tables.setdefault(self.heading, [])
        elif tag == "tr" and self.rows is not None:
            self.row = []

    def handle_endtag(self, tag):
        if tag == "h2":
            self.heading = self.text.strip()
        elif tag in ("td", "th") and self.row is not None:
            self.row.append(self.text.strip())
        elif tag == "tr" and self.rows is not None and self.row is not None:
            self.rows.append(self.row)
            self.row = None
        elif tag == "table":
            self.rows = None

    def handle_data(self, data):
        self.text += data


def figure(value: float | None, digits: int = 2) -> str:
    return MISSING if value is None else f"{value:.{digits}f}"


def p_text(value: float | None, method: str) -> str:
    mark = APPROXIMATE_MARK if method == "approximate" and value is not None else ""
    return mark + (MISSING if value is None else f"{value:.2e}")


def expected_rows(payload: dict) -> dict[str, list[list[str]]]:
    """The three tables' rows from the figures of `--json`, as the terminal rounds and marks them."""
    return {
        "questionnaires": [
            [r["questionnaire"], r["condition"], str(r["responses"]), str(r["participants"]),
             figure(r["mean_score"]), figure(r["sd_score"]), figure(r["cronbach_alpha"])]
            for r in payload["questionnaires"]],
        "questionnaire_tests": [
            [r["questionnaire"], f"{r['a']} vs {r['b']}", str(r["pairs"]), figure(r["median_difference"]),
             *(p_text(r[column], r["wilcoxon_method"]) for column in ("wilcoxon_p", "wilcoxon_p_holm"))]
            for r in payload["questionnaire_tests"]],
        "manual": [
            [r["incident"], r["condition"], str(r["takeovers"]), figure(r["reaction_s"]), str(r["by_wheel"]),
             figure(r["lateral_sd_m"]), figure(r["min_ttc_s"]), figure(r["max_deceleration"]),
             figure(r["oncoming_s"], 1), str(r["road_departures"]), str(r["collisions"])]
            for r in payload["manual_driving"]],
    }


def test_the_report_files_show_the_questionnaire_and_manual_driving_tables_of_json(live_study_dir, capsys):
    code, out, err = run_cli(capsys, "analyze", str(live_study_dir), "--json", "--report")
    assert code == 0, err
    payload = json.loads(out)
    expected = expected_rows(payload)
    # the study has what the tables show: scores with spread, a paired test, takeovers
    assert len(expected["questionnaires"]) == 2 and len(expected["questionnaire_tests"]) == 1
    assert payload["questionnaire_tests"][0]["wilcoxon_p"] is not None and expected["manual"]
    markdown = markdown_tables((live_study_dir / "report.md").read_text())
    parser = HtmlTables()
    parser.feed((live_study_dir / "report.html").read_text())
    code, terminal, err = run_cli(capsys, "analyze", str(live_study_dir), "--wide", "--no-report")
    assert code == 0, err
    for name, rows in expected.items():
        # the questionnaires' figures do not depend on the belief source: no source in the title
        title = TABLE_TITLES[name]
        for shown in (markdown[title], parser.tables[title]):
            assert shown[1:] == rows, (name, shown)
        assert markdown[title][0] == parser.tables[title][0], name   # the same columns
        assert f"\n{title}\n" in terminal, name
        for row in rows:   # the terminal's row, cell for cell
            assert re.search(r"\s+".join(re.escape(cell) for cell in row), terminal), (name, row)
    report = (live_study_dir / "report.md").read_text()
    assert f"Multiplicity: {MULTIPLICITY}." in report and "per questionnaire" in MULTIPLICITY
    # a table ends at a blank line: a note or a heading after it is not read as one more row
    lines = report.split("\n")
    ends = [after for line, after in zip(lines, lines[1:], strict=False) if line.startswith("|")]
    assert all(after.startswith("|") or after == "" for after in ends), ends
