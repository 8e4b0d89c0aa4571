"""Documentation cited by the code exists: every docs/ file named anywhere, and every section cited."""

from __future__ import annotations

import functools
import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SKIPPED = {".venv", "build", ".home", ".git"}   # not the project's sources (the environment's 2.7 GB)


@functools.cache
def sources() -> list[Path]:
    """The project's .py, .toml and .md files, found without walking the skipped folders."""
    found = []
    for folder, subfolders, files in os.walk(ROOT):
        subfolders[:] = sorted(d for d in subfolders if d not in SKIPPED)
        found += [Path(folder, name) for name in sorted(files) if name.endswith((".py", ".toml", ".md"))]
    return found


# A section follows its page after a comma or a space (docs/synthesis.md, "Work limit"); a quote
# right after ".md" closes a string literal in code, whatever quoted text comes next.
CITATION = re.compile(r"docs/([\w/.-]+\.md)((?:(?:, ?| )\"[^\"]+\"(?: and)?)*)")


def headings(path: Path) -> set[str]:
    return {line.lstrip("#").strip() for line in path.read_text().splitlines() if line.startswith("#")}


def test_every_cited_doc_and_section_exists():
    cited = 0
    for source in sources():
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
    for source in sources():
        if source.name == "test_docs.py":
            continue
        assert "DESIGN.md" not in source.read_text(errors="replace"), source.relative_to(ROOT)


def test_index_links_every_doc():
    index = (ROOT / "docs" / "README.md").read_text()
    for doc in (ROOT / "docs").rglob("*.md"):
        if doc.name != "README.md":
            assert f"({doc.relative_to(ROOT / 'docs')})" in index, doc
