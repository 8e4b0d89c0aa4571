"""A finished study copied with one of its tables changed: the bad study tables of the dataset's,
the analyses' and the fits' tests (the tables keep their schema, only their values are wrong)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

Edit = Callable[[pa.Table], pa.Table]


def study_copy(study: Path, target: Path, file_name: str | None = None, edit: Edit | None = None) -> Path:
    """`study` copied to `target`, with `edit` applied to its table `file_name`."""
    shutil.copytree(study, target)
    if file_name is not None and edit is not None:
        edit_table(target / file_name, edit)
    return target


def edit_table(path: Path, edit: Edit) -> None:
    pq.write_table(edit(pq.read_table(path)), path)


def set_values(column: str, value: object, rows: slice | list[int] | None = None) -> Edit:
    """Set `column` to `value` in `rows` (every row when None)."""

    def edit(table: pa.Table) -> pa.Table:
        values = table.column(column).to_pylist()
        chosen = range(len(values)) if rows is None else (
            range(len(values))[rows] if isinstance(rows, slice) else rows)
        for i in chosen:
            values[i] = value
        index = table.schema.get_field_index(column)
        field = table.schema.field(index)
        return table.set_column(index, field, pa.array(values, type=field.type))

    return edit


def duplicate_row(row: int) -> Edit:
    """The table with its row `row` appended once more."""
    return lambda table: pa.concat_tables([table, table.slice(row, 1)])
