"""The format docs (docs/formats/) list exactly the keys the loaders accept.

Each format doc has key tables whose first column names a key (`participants`, `[states]`,
`[beliefs.NAME].coeffs`, `types[i].weight`). A key's path is its section's table (a heading such as
"## `[study]`") followed by the key's own parts; placeholders (NAME, `[i]`) drop out. The loaders'
field tables (trustroute/core/fields.py) are the accepted keys: every documented key must be one of
them, and every one of them must be documented. The summary in docs/input_files.md ("Keys: strict
by default") lists each kind's keys again, and is held to the same loaders' keys.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from trustroute.core.fields import Field, keys
from trustroute.harness.study import config as study_config
from trustroute.networks import road_geometry, town
from trustroute.participants import driver_model, driver_population, population, questionnaires
from trustroute.policies.logic import spec

DOCS = Path(__file__).resolve().parents[1] / "docs" / "formats"

# doc -> {key path prefix: the field table of the keys under it}
ACCEPTED: dict[str, dict[str, tuple[Field, ...]]] = {
    "study_config.md": {"": study_config.FIELDS, "study": study_config.STUDY_FIELDS,
                        "population": population.FIELDS, "drivers": study_config.DRIVERS_FIELDS,
                        "live": study_config.LIVE_FIELDS},
    "spec.md": {"": spec.FIELDS, "beliefs": spec.BELIEF_FIELDS, "trust_states": spec.TRUST_STATE_FIELDS,
                "type_beliefs": spec.TYPE_BELIEF_FIELDS},
    "town.md": {"": town.FIELDS},
    "driver_model.md": {"": driver_model.FIELDS},
    "driver_population.md": {"": driver_population.FIELDS, "types": driver_population.TYPE_FIELDS},
}
KEY_CELL = re.compile(r"^\|\s*`([^`]+)`\s*\|")
SECTION = re.compile(r"^#+\s*`\[([A-Za-z_]+)\]`\s*$")
PLACEHOLDER = re.compile(r"^[A-Z]+$")


def key_path(cell: str, section: str) -> str:
    """`[beliefs.NAME].coeffs` -> beliefs.coeffs; `types[i].weight` -> types.weight; under the
    section `[study]`, `seed` -> study.seed."""
    text = cell.replace("[i]", "").replace("[", "").replace("]", "")
    parts = [part for part in text.split(".") if part and not PLACEHOLDER.match(part)]
    return ".".join([section, *parts] if section else parts)


def documented_keys(text: str) -> set[str]:
    """The key paths in the first column of the doc's tables (rows below a table's header)."""
    found: set[str] = set()
    section = ""
    in_table = False
    for line in text.splitlines():
        heading = SECTION.match(line)
        if heading:
            section = heading.group(1)
        elif line.startswith("#"):
            section = ""
        if not line.startswith("|"):
            in_table = False
            continue
        if re.match(r"^\|\s*-", line):
            in_table = True
            continue
        cell = KEY_CELL.match(line)
        if in_table and cell:
            found.add(key_path(cell.group(1), section))
    return found


def accepted_keys(tables: dict[str, tuple[Field, ...]]) -> set[str]:
    return {f"{prefix}.{key}" if prefix else key for prefix, fields in tables.items() for key in keys(fields)}


@pytest.mark.parametrize("doc", sorted(ACCEPTED))
def test_the_doc_lists_exactly_the_accepted_keys(doc):
    documented = documented_keys((DOCS / doc).read_text())
    accepted = accepted_keys(ACCEPTED[doc])
    assert sorted(documented - accepted) == [], f"{doc} documents keys the loader rejects"
    assert sorted(accepted - documented) == [], f"the loader accepts keys {doc} does not document"


@pytest.mark.parametrize("doc", sorted(ACCEPTED))
def test_the_doc_does_not_say_unknown_keys_are_ignored(doc):
    """Every loader rejects an unknown key (docs/input_files.md, the strict key policy)."""
    text = " ".join((DOCS / doc).read_text().split())
    assert not re.search(r"keys? (are|is) ignored", text, re.IGNORECASE)


def test_the_walker_reads_sections_placeholders_and_list_items():
    text = "\n".join([
        "| key | value |", "|---|---|", "| `name` | x |", "| `[beliefs.NAME].coeffs` | y |",
        "| &nbsp;M (plain) | z |", "", "## `[study]`", "", "| key | value |", "|---|---|",
        "| `seed` | s |", "| `types[i].weight` | w |", "## Other", "| `not_a_row` | header |",
    ])
    assert documented_keys(text) == {"name", "beliefs.coeffs", "study.seed", "study.types.weight"}



# docs/input_files.md, "Keys: strict by default": kind -> {table ("" the file's top level): its keys}
INPUT_FILES = DOCS.parent / "input_files.md"
KEY_LISTS: dict[str, dict[str, tuple[str, ...]]] = {
    "town": {"": keys(town.FIELDS), "geometry.<road>": road_geometry.GEOMETRY_KEYS},
    "driver model": {"": keys(driver_model.FIELDS), "trust_transition.<incident>": driver_model.HUMAN_ACTIONS,
                     "trust_transition.<incident>.<action>": keys(driver_model.PERFORMANCE_FIELDS)},
    "driver population": {"": keys(driver_population.FIELDS),
                          "types[i]": keys(driver_population.TYPE_FIELDS)},
    "spec": {"": keys(spec.FIELDS), "[beliefs.NAME]": keys(spec.BELIEF_FIELDS),
             "[trust_states].NAME": keys(spec.TRUST_STATE_FIELDS),
             "[type_beliefs].NAME": keys(spec.TYPE_BELIEF_FIELDS)},
    "study config": {"": keys(study_config.FIELDS), "[study]": study_config.STUDY_KEYS,
                     "[population]": keys(population.FIELDS), "[drivers]": keys(study_config.DRIVERS_FIELDS),
                     "[questionnaires]": questionnaires.PLACEMENTS, "[live]": keys(study_config.LIVE_FIELDS)},
}
KIND_ITEM = re.compile(r"^  - ([a-z ]+): (.*)$")


def key_lists(text: str) -> dict[str, dict[str, list[str]]]:
    """The lists of the doc's items `  - kind: `a`, `b`; inside `table` only `c`, `d`; ...` (an
    item wraps over lines indented deeper; a part's words in parentheses are not keys): kind ->
    {table: its keys, brackets dropped}."""
    items: dict[str, str] = {}
    kind = None
    for line in text.splitlines():
        item = KIND_ITEM.match(line)
        if item:
            kind = item.group(1)
            items[kind] = item.group(2)
        elif kind is not None and line.startswith("    "):
            items[kind] += " " + line.strip()
        else:
            kind = None
    found: dict[str, dict[str, list[str]]] = {}
    for kind, listed in items.items():
        found[kind] = {}
        for part in filter(str.strip, listed.split(";")):
            names = re.findall(r"`([^`]+)`", part.split(" (")[0])
            table, names = (names[0], names[1:]) if part.strip().startswith("inside") else ("", names)
            found[kind][table] = [name.strip("[]") for name in names]
    return found


def test_the_input_files_key_lists_are_the_loaders_keys():
    """docs/input_files.md lists every kind's keys: exactly the keys its loader accepts."""
    listed = key_lists(INPUT_FILES.read_text())
    for kind, tables in KEY_LISTS.items():
        assert kind in listed, f"docs/input_files.md lists no keys of the {kind}"
        assert set(listed[kind]) == set(tables), (kind, sorted(listed[kind]))
        for table, accepted in tables.items():
            assert sorted(listed[kind][table]) == sorted(accepted), (kind, table)
