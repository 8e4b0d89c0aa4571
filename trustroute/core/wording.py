"""Counts in messages, in the singular for one ("1 file excluded", "3 files excluded"), certified
bounds as text rounded outward, and a refused value as a message shows it."""

from __future__ import annotations

from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal


def counted(count: int, noun: str, plural: str | None = None) -> str:
    """`count` and `noun`, the noun's plural (`plural`, or `noun` + "s") unless count is 1."""
    return f"{count} {noun if count == 1 else plural or noun + 's'}"


def shown_value(value: object, limit: int = 40) -> str:
    """A refused value as a message shows it: a string as Python writes it, quoted, so that the
    string "5" never reads as the number 5 a message asks for; any other value as its text (numpy's
    3 as 3, numpy's "5" as '5'); on one line, since a message is one (a 2-D array's rows joined);
    cut to `limit` characters, "..." marking the cut."""
    text = repr(str(value)) if isinstance(value, str) else str(value)
    text = " ".join(line.strip() for line in text.splitlines())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def outward(lower: float, upper: float, digits: int) -> tuple[str, str]:
    """A certified [lower, upper] as text of `digits` decimals rounded outward, lower down and upper
    up, so the printed interval holds the certified one: a lower bound of 0.99999996 reads 0.999999
    at six decimals, never 1.000000, which would claim more than was certified."""
    return lower_text(lower, digits), upper_text(upper, digits)


def lower_text(lower: float, digits: int = 6) -> str:
    """A certified lower bound alone (a worst type's value, "certified >= ..."), rounded down."""
    return str(Decimal(lower).quantize(Decimal(1).scaleb(-digits), rounding=ROUND_FLOOR))


def upper_text(upper: float, digits: int = 6) -> str:
    """A certified upper bound alone, rounded up."""
    return str(Decimal(upper).quantize(Decimal(1).scaleb(-digits), rounding=ROUND_CEILING))


def interval(lower: float, upper: float, digits: int = 6) -> str:
    """A certified interval as "[lower, upper]", rounded outward (`outward`)."""
    low, high = outward(lower, upper, digits)
    return f"[{low}, {high}]"
