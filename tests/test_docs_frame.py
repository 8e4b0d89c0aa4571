"""docs/live_studies.md's table of a frame's fields is the schema's: the fields of `Frame`
(harness/live/protocol.py) in their order, each row its field's description there, so neither can
change without the other."""

from __future__ import annotations

from pathlib import Path
from typing import get_args

from pydantic import BaseModel, Field

from trustroute.harness.live.protocol import SEEN_PERSON, SEEN_VEHICLE, Frame, SeenPerson, SeenVehicle

DOC = Path(__file__).resolve().parents[1] / "docs" / "live_studies.md"
HEADER = "| frame field | what |"


def documented_rows(text: str) -> list[tuple[str, str]]:
    """(field, description) of each row of the doc's frame table."""
    lines = text.splitlines()
    assert lines.count(HEADER) == 1, f"docs/live_studies.md has no single table headed {HEADER!r}"
    rows = []
    for line in lines[lines.index(HEADER) + 2:]:
        if not line.startswith("|"):
            break
        name, what = (cell.strip() for cell in line.strip().strip("|").split("|", 1))
        rows.append((name.strip("`"), what))
    return rows


def schema_rows(model: type[BaseModel]) -> list[tuple[str, str]]:
    rows = [(name, field.description or "") for name, field in model.model_fields.items()]
    for name, what in rows:
        assert what and "|" not in what, f"{model.__name__}.{name}: a description without '|' is due"
    return rows


def table(rows: list[tuple[str, str]]) -> str:
    return "\n".join(f"| `{name}` | {what} |" for name, what in rows)


def test_the_docs_frame_table_is_the_schemas():
    documented, schema = documented_rows(DOC.read_text()), schema_rows(Frame)
    assert documented == schema, (
        f"docs/live_studies.md \"Protocol\": the rows under {HEADER!r} are to read\n{table(schema)}")


def test_a_field_added_to_the_schema_only_is_told():
    class Wider(Frame):
        fuel: float = Field(description="litres left")

    assert documented_rows(DOC.read_text()) != schema_rows(Wider)


def test_the_seen_items_are_named_as_the_types_hold_them():
    """A vehicle's and a person's items, as the descriptions name them, are as many as their types
    hold (a `str` where a kind or a shape is named)."""
    for names, kind in ((SEEN_VEHICLE, SeenVehicle), (SEEN_PERSON, SeenPerson)):
        items = get_args(kind)
        assert len(items) == len(names)
        assert [name for name, item in zip(names, items, strict=True) if item is str] == [
            name for name in names if name in ("kind", "shape")]
