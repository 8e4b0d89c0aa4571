"""docs/performance.md lists every performance figure README.md states and every docs page that
states some, each with the command that measures it.

The rule: a figure is a number (or a range "a–b") followed by a unit of time, size or ratio: ×
or x written against the number ("1.43×"), ms, s, min, kB, MB, GB. A "×" between two numbers
("5 × 5", "21 drivers × 4 routes") is a dimension, not a ratio. Every figure README.md states
appears verbatim (spaces normalised) in docs/performance.md; every docs/*.md page stating a figure
is named there by its path (docs/ and its file name).
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "performance.md"
FIGURE = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?(?:[–-]\d+(?:\.\d+)?)?)"
                    r"(?:(×|x)(?![ \u00a0]?\d)(?!\w)|[ \u00a0]?(ms|s|min|kB|MB|GB)(?!\w))")


def figures(text: str) -> list[str]:
    """Every figure of `text`, written as the page must write it ("0.9 s", "1.43×", "247–348 kB")."""
    found = []
    for number, ratio, unit in FIGURE.findall(text):
        found.append(f"{number}{ratio}" if ratio else f"{number} {unit}")
    return found


def _normalised(text: str) -> str:
    return " ".join(text.replace("\u00a0", " ").split())


def missing_figures(readme: str, page: str) -> list[str]:
    """README figures the page does not list, each as a whole figure ("21 s" is not in "21 seeds")."""
    listed = _normalised(page)
    return sorted({figure for figure in figures(readme)
                   if not re.search(rf"(?<![\w.]){re.escape(figure)}(?!\w)", listed)})


def unlisted_pages(pages: dict[str, str], page: str) -> list[str]:
    """docs pages that state a figure and are not named on the page."""
    return sorted(name for name, text in pages.items() if figures(text) and f"docs/{name}" not in page)


def test_the_rule_finds_figures_and_leaves_out_dimensions():
    text = ("1.43× bare libsumo, 1.2x, in 0.9 s, 12 ms, 247–348 kB, 358 MB, 1.8 GB, 2 min; "
            "the 5 × 5 grid, 21 drivers × 4 routes, 5x5, H = 20, phi1, 0x5CE7E, v1.2")
    assert figures(text) == ["1.43×", "1.2x", "0.9 s", "12 ms", "247–348 kB", "358 MB", "1.8 GB", "2 min"]


def test_a_readme_figure_the_page_does_not_list_fails():
    page = "| `0.9 s` | synthesis | `trustroute synth phi1` |"
    assert missing_figures("converged in 0.9 s", page) == []
    assert missing_figures("converged in 0.9 s, the episode at 1.43× bare libsumo", page) == ["1.43×"]
    assert missing_figures("about 10 s on a laptop", page) == ["10 s"]
    assert missing_figures("about 21 s", "21 synthetic drivers, 121 s, 0.21 s") == ["21 s"]
    assert missing_figures("about 21 s", "took 21 s.") == []
    docs = "docs/"   # pages that do not exist (written so that test_docs does not read them as citations)
    assert unlisted_pages({"a.md": "took 3.2 s", "b.md": "no figures"}, f"see {docs}b.md") == ["a.md"]
    assert unlisted_pages({"a.md": "took 3.2 s"}, f"see {docs}a.md") == []


def test_every_readme_figure_is_on_the_performance_page():
    readme = (ROOT / "README.md").read_text()
    assert figures(readme), "README states no figure: the rule or README changed"
    missing = missing_figures(readme, PAGE.read_text())
    assert not missing, f"README states figures docs/performance.md does not list: {', '.join(missing)}"


def test_every_docs_page_with_figures_is_on_the_performance_page():
    pages = {path.name: path.read_text() for path in (ROOT / "docs").glob("*.md") if path != PAGE}
    unlisted = unlisted_pages(pages, PAGE.read_text())
    assert not unlisted, f"docs pages state figures docs/performance.md does not name: {', '.join(unlisted)}"


def test_every_listed_figure_has_its_command():
    """Each row of the README table names the command that measures (or sets) the figure."""
    rows = [line for line in PAGE.read_text().splitlines()
            if line.startswith("| `") and "|" in line[1:]]
    assert rows
    for row in rows:
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        assert len(cells) >= 3 and "`" in cells[2], f"no command in row: {row}"
