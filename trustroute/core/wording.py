"""Counts in messages, in the singular for one ("1 file excluded", "3 files excluded")."""

from __future__ import annotations


def counted(count: int, noun: str, plural: str | None = None) -> str:
    """`count` and `noun`, the noun's plural (`plural`, or `noun` + "s") unless count is 1."""
    return f"{count} {noun if count == 1 else plural or noun + 's'}"
