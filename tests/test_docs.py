"""Documentation cited by the code exists: every docs/ file named anywhere, and every section cited."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [p for pattern in ("*.py", "*.toml", "*.md") for p in ROOT.rglob(pattern)
           if not {".venv", "build", ".home", ".git"} & set(p.relative_to(ROOT).parts)]
CITATION = re.compile(r"docs/([\w/.-]+\.md)((?:,? ?\"[^\"]+\"(?: and)?)*)")


def headings(path: Path) -> set[str]:
    return {line.lstrip("#").strip() for line in path.read_text().splitlines() if line.startswith("#")}


def test_every_cited_doc_and_section_exists():
    cited = 0
    for source in SOURCES:
        for match in CITATION.finditer(source.read_text(errors="replace")):
            target = ROOT / "docs" / match.group(1)
            assert target.is_file(), f"{source.relative_to(ROOT)} cites missing docs/{match.group(1)}"
            for section in re.findall(r"\"([^\"]+)\"", match.group(2)):
                section = " ".join(section.split())   # a citation may wrap across lines
                # A section is cited by its heading or the heading's first words ("Belief sources").
                assert any(h == section or h.startswith(section + " ") for h in headings(target)), (
                    f"{source.relative_to(ROOT)} cites section {section!r} absent from docs/{match.group(1)}")
            cited += 1
    assert cited >= 20


def test_no_citation_of_a_design_file_outside_the_repository():
    for source in SOURCES:
        if source.name == "test_docs.py":
            continue
        assert "DESIGN.md" not in source.read_text(errors="replace"), source.relative_to(ROOT)


def test_index_links_every_doc():
    index = (ROOT / "docs" / "README.md").read_text()
    for doc in (ROOT / "docs").rglob("*.md"):
        if doc.name != "README.md":
            assert f"({doc.relative_to(ROOT / 'docs')})" in index, doc
