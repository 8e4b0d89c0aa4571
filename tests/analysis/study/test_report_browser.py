"""The demo's report as a reader sees it: `report.html` opened in headless Chromium (Playwright,
the system's chromium). No interval on a probability leaves [0, 1], no risk difference leaves
[-1, 1], every odds ratio open above says why beside it, the first line names the belief source
that leads, and every plot shown has its vector version beside it.

Drives Debian's Chromium and never skips (tests/browser.py)."""

from __future__ import annotations

import math
import re

import playwright.sync_api as playwright
import pytest

from tests.browser import chromium_executable
from tests.cli import run_cli

INTERVAL = re.compile(r"\[\s*([^,\]]+),\s*([^\]]+)\]")
# columns holding a probability or an interval on one (headers as the report prints them)
PROBABILITY_COLUMNS = {"rate", "exact 95% CI", "Wilson 95% CI", "exact value [L, U]", "synthesized [L, U]",
                       "fallback"}
TABLES_JS = """() => [...document.querySelectorAll('table')].map(t => ({
    title: (t.previousElementSibling || {}).textContent || '',
    headers: [...t.querySelectorAll('thead th')].map(h => h.textContent.trim()),
    rows: [...t.querySelectorAll('tbody tr')].map(r => [...r.querySelectorAll('td')].map(
        c => c.textContent.trim()))}))"""


def _number(text: str) -> float:
    text = text.strip().replace("\u2212", "-")
    if text in ("inf", "+inf", "\u221e"):
        return math.inf
    if text in ("-inf", "-\u221e"):
        return -math.inf
    return float(text)


def _numbers(cell: str) -> list[float]:
    """The bounds of an interval in `cell` ("0.5 [0.2, 0.8]" or "[0.2, 0.8]") and the estimate or
    rate before it; nothing for a missing value."""
    if cell in ("", "-", "nan"):
        return []
    found = INTERVAL.search(cell)
    values = [_number(found.group(1)), _number(found.group(2))] if found else []
    head = INTERVAL.sub("", cell).strip()
    return values + ([_number(head)] if head else [])


def _is_probability(header: str) -> bool:
    return header in PROBABILITY_COLUMNS or header.startswith("rate (")


def _odds_ratio_cells(table: dict) -> list[tuple[str, str]]:
    """(odds ratio cell, its note) for every odds ratio of the table."""
    headers = table["headers"]
    if "conditional OR [exact CI]" in headers:
        at = headers.index("conditional OR [exact CI]")
        note = headers.index("odds ratio note") if "odds ratio note" in headers else None
        return [(row[at], row[note] if note is not None else "") for row in table["rows"]]
    if "estimate [95% CI]" in headers and "outcome" in headers:
        at, outcome, note = (headers.index(h) for h in ("estimate [95% CI]", "outcome", "note"))
        return [(row[at], row[note]) for row in table["rows"] if "odds ratio" in row[outcome]]
    return []


def check_report_page(tables: list[dict]) -> list[str]:
    """What a reader of the report would object to: one line per offending cell."""
    problems = []
    for table in tables:
        for row in table["rows"]:
            for header, cell in zip(table["headers"], row, strict=True):
                if _is_probability(header) and any(not 0.0 <= v <= 1.0 for v in _numbers(cell)):
                    problems.append(f"{table['title']}: {header} = {cell} leaves [0, 1]")
                if header.startswith("risk difference") and any(not -1.0 <= v <= 1.0 for v in _numbers(cell)):
                    problems.append(f"{table['title']}: {header} = {cell} leaves [-1, 1]")
        for cell, note in _odds_ratio_cells(table):
            if any(math.isinf(v) or math.isnan(v) for v in _numbers(cell)) and not note.strip():
                problems.append(f"{table['title']}: odds ratio {cell} is unbounded with no reason given")
    return problems


def test_the_checks_catch_what_they_look_for():
    """The page check itself fails on the rows it exists for."""
    rate = {"title": "t", "headers": ["rate", "exact 95% CI"], "rows": [["0.500", "[0.000, 1.48e44]"]]}
    odds = {"title": "t", "headers": ["outcome", "estimate [95% CI]", "note"],
            "rows": [["satisfied (odds ratio)", "13279.495 [0.000, inf]", ""]]}
    risk = {"title": "t", "headers": ["risk difference [95% CI]"], "rows": [["0.2 [-1.2, 0.5]"]]}
    assert len(check_report_page([rate, odds, risk])) == 3
    odds["rows"][0][2] = "quasi-separation: CI open above"
    fine = {"title": "t", "headers": ["rate", "trust 95% CI"], "rows": [["1.000", "[4.47, 5.44]"]]}
    assert check_report_page([odds, fine]) == []


@pytest.mark.slow
def test_the_demo_report_in_chromium_shows_no_impossible_interval(tmp_path, capsys):
    study = tmp_path / "demo"
    code, _, err = run_cli(capsys, "demo", "--engine", "model", "--out", str(study), "--quiet",
                           "--workers", "1")
    assert code == 0, err
    with playwright.sync_playwright() as driver:
        browser = driver.chromium.launch(executable_path=chromium_executable(), args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto((study / "report.html").resolve().as_uri())
            tables = page.evaluate(TABLES_JS)
            lead = page.evaluate("() => (document.querySelector('p.lead') || {}).textContent || ''")
            images = page.evaluate("() => [...document.images].map(i => [i.alt, i.naturalWidth])")
            page.screenshot(path=str(tmp_path / "report.png"), full_page=True)
        finally:
            browser.close()
    assert len(tables) >= 8 and sum(len(t["rows"]) for t in tables) > 30
    assert check_report_page(tables) == []
    odds = [cell for t in tables for cell, _ in _odds_ratio_cells(t)]
    assert any(math.isinf(max(_numbers(cell))) for cell in odds if cell != "-")   # the odds ratios were read
    assert lead.startswith("Leading belief source: 'true'"), lead
    assert images and all(width > 0 for _, width in images)
    plots = sorted((study / "plots").glob("*.png"))
    assert len(plots) == len(images) and all(p.with_suffix(".svg").is_file() for p in plots)
    assert (tmp_path / "report.png").stat().st_size > 100_000
