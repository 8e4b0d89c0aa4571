"""The directed road "U-V": driven from junction U to junction V, the state of the model.

A road id is written and read only here (`Road.parse`, `str(road)`); elsewhere a road id is
taken apart with `Road.parse(road_id)` and put together with `Road(u, v).id`.
Junction names are letters, digits and "_" (networks/town.py's `JUNCTION_NAME`, which imported
towns' names keep too: networks/sumo_import.py's `junction_names`), so the one "-" of an id
separates the two junctions unambiguously.
"""

from __future__ import annotations

from typing import NamedTuple

SEPARATOR = "-"


class Road(NamedTuple):
    """A directed road: `from_junction` is the junction it leaves, `to_junction` the one it enters
    (the vehicle on road U-V has just arrived at V from U)."""

    from_junction: str
    to_junction: str

    @classmethod
    def parse(cls, road_id: str) -> Road:
        """The road of an id "U-V"; ValueError for a string that is not one."""
        start, separator, end = road_id.partition(SEPARATOR)
        if not separator or not start or not end or SEPARATOR in end:
            raise ValueError(f"{road_id!r} is not a directed road id \"U-V\"")
        return cls(start, end)

    @classmethod
    def parse_or_none(cls, text: str) -> Road | None:
        """The road of an id "U-V", or None for any other string (a SUMO junction-internal edge
        such as ":A_5", or a start road's bare junction name)."""
        try:
            return cls.parse(text)
        except ValueError:
            return None

    @property
    def id(self) -> str:
        """The road's id "U-V", as towns, policies and tables name it."""
        return f"{self.from_junction}{SEPARATOR}{self.to_junction}"

    @property
    def reverse(self) -> Road:
        """The same road driven the other way (V-U)."""
        return Road(self.to_junction, self.from_junction)

    def __str__(self) -> str:
        return self.id

