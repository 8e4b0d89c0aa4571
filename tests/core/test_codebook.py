"""The codebook covers every column of every dataset table, and nothing else."""

from __future__ import annotations

from trustroute.core.codebook import COLUMNS, EXPORTED_TIMES, UTC, codebook
from trustroute.core.dataset import TABLES


def test_every_schema_column_has_one_codebook_entry():
    assert set(COLUMNS) == set(TABLES)
    for table, (_, schema) in TABLES.items():
        assert list(COLUMNS[table]) == schema.names or set(COLUMNS[table]) == set(schema.names), table
    book = codebook()
    for table, (_, schema) in TABLES.items():
        assert [entry["column"] for entry in book[table]] == schema.names
        assert all(entry["meaning"] and entry["allowed"] for entry in book[table])


def test_every_wall_clock_column_is_exported_as_seconds_with_an_entry():
    utc = {table: {column for column, (unit, _, _) in entries.items() if unit == UTC}
           for table, entries in COLUMNS.items()}
    assert {table: set(columns) for table, columns in EXPORTED_TIMES.items()} == {
        table: columns for table, columns in utc.items() if columns}
    exported = codebook(exported=True)
    for table, columns in EXPORTED_TIMES.items():
        entries = {entry["column"]: entry for entry in exported[table]}
        assert not set(columns) & set(entries)
        for seconds in columns.values():
            assert (entries[seconds]["type"], entries[seconds]["unit"]) == ("double", "s")
            assert "first recorded wall-clock time" in entries[seconds]["meaning"]
    assert all(entry["unit"] != UTC for entries in exported.values() for entry in entries)


def test_a_packages_codebook_describes_its_codes_not_the_studys_numbers():
    study, exported = codebook(), codebook(exported=True)
    for table in TABLES:
        ours = {entry["column"]: entry for entry in exported[table]}
        theirs = {entry["column"]: entry for entry in study[table]}
        if "participant" in ours:
            code = ours["participant"]
            assert "0-based" not in code["meaning"] and "pseudonym" in code["meaning"]
            assert code["allowed"].startswith("codes of one width") and "100-999" in code["allowed"]
            assert theirs["participant"]["allowed"] == "integers >= 0"
        if "episode_id" in ours:
            assert ours["episode_id"]["allowed"].startswith("p<participant code, 5 digits (code 114:")
            assert ours["episode_id"]["meaning"] == theirs["episode_id"]["meaning"]   # each table's own
            assert "5 digits" in theirs["episode_id"]["allowed"]
