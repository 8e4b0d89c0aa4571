"""The codebook covers every column of every dataset table, and nothing else."""

from __future__ import annotations

from trustroute.core.codebook import COLUMNS, codebook
from trustroute.core.dataset import TABLES


def test_every_schema_column_has_one_codebook_entry():
    assert set(COLUMNS) == set(TABLES)
    for table, (_, schema) in TABLES.items():
        assert list(COLUMNS[table]) == schema.names or set(COLUMNS[table]) == set(schema.names), table
    book = codebook()
    for table, (_, schema) in TABLES.items():
        assert [entry["column"] for entry in book[table]] == schema.names
        assert all(entry["meaning"] and entry["allowed"] for entry in book[table])
