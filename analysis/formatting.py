"""Display formatting of analysis results, shared by the terminal tables, the report and the CLI.

Missing values (None, NaN, pd.NA) read "-" everywhere; numbers get a fixed number of decimals,
intervals read "[low, high]", p-values are in scientific notation, and tables are rendered as
GitHub-flavoured Markdown or as aligned plain-text columns; terminal tables fit TERMINAL_WIDTH
columns (`terminal_table`: long cells wrapped, columns split into blocks that repeat the row's key
columns) unless shown wide.
"""

from __future__ import annotations

import math
import sys
import textwrap
from collections.abc import Sequence
from typing import TYPE_CHECKING, SupportsFloat

import numpy as np

from trustroute.core.wording import interval

if TYPE_CHECKING:
    import pandas as pd

MISSING = "-"
TERMINAL_WIDTH = 120
CELL_WIDTH = 48  # a longer cell (a note) wraps onto continuation lines


def is_pandas_na(value: object) -> bool:
    """Whether `value` is pd.NA; pandas is not imported for it (the CLI formats values of commands
    that never load pandas, and none of those can hold pd.NA)."""
    pandas = sys.modules.get("pandas")
    return pandas is not None and value is pandas.NA


def finite_or_none(value: SupportsFloat | None) -> float | None:
    """A float, or None for a missing value (None, NaN, or pd.NA: e.g. the mean of a nullable
    column with no values, such as final_trust of real participants)."""
    if value is None or is_pandas_na(value):
        return None
    value = float(value)
    return None if math.isnan(value) else value


def number_text(value: object, digits: int = 3) -> str:
    """A float with `digits` decimals ("inf" when infinite), another value as str, "-" if missing."""
    if value is None or (isinstance(value, float) and math.isnan(value)) or is_pandas_na(value):
        return MISSING
    if isinstance(value, (float, np.floating)):
        return "inf" if math.isinf(value) else f"{value:.{digits}f}"
    return str(value)


def interval_text(low: object, high: object, digits: int = 3) -> str:
    """"[low, high]", or "-" when either end is missing."""
    if number_text(low) == MISSING or number_text(high) == MISSING:
        return MISSING
    return f"[{number_text(low, digits)}, {number_text(high, digits)}]"


def interval_column(frame: pd.DataFrame, low: str, high: str, digits: int = 3) -> list[str]:
    """The column pair (low, high) of a table as formatted intervals."""
    return [interval_text(a, b, digits) for a, b in zip(frame[low], frame[high], strict=True)]


def bounds_text(lower: SupportsFloat | None, upper: SupportsFloat | None, digits: int = 3) -> str:
    """A certified [L, U] as "[lower, upper]" rounded outward, L down and U up, as every command
    prints one (trustroute/core/wording.py `interval`), so that it holds the certified interval;
    "-" when either end is missing."""
    low, high = finite_or_none(lower), finite_or_none(upper)
    return MISSING if low is None or high is None else interval(low, high, digits)


def bounds_column(frame: pd.DataFrame, lower: str, upper: str, digits: int = 3) -> list[str]:
    """The certified bounds (lower, upper) of a table as intervals rounded outward (`bounds_text`)."""
    return [bounds_text(a, b, digits) for a, b in zip(frame[lower], frame[upper], strict=True)]


def estimate_column(frame: pd.DataFrame, value: str, low: str, high: str, digits: int = 3) -> list[str]:
    """'estimate [low, high]' per row; '-' where the estimate is missing (or the column absent)."""
    missing = [None] * len(frame)
    return [
        f"{number_text(v, digits)} {interval_text(lo, hi, digits)}" if number_text(v) != MISSING else MISSING
        for v, lo, hi in zip(frame.get(value, missing), frame.get(low, missing),
                             frame.get(high, missing), strict=True)
    ]


def format_p(p: float | None) -> str:
    """A p-value in scientific notation with three significant digits ("3.05e-07"); "-" if missing."""
    if p is None or (isinstance(p, float) and math.isnan(p)):
        return MISSING
    return f"{p:.2e}"


def markdown_table(frame: pd.DataFrame) -> str:
    """A pandas table as a GitHub-flavoured Markdown table (pipes in cells escaped)."""

    def cell(value: object) -> str:
        return str(value).replace("|", "\\|").replace("\n", " ")

    header = "| " + " | ".join(cell(c) for c in frame.columns) + " |"
    rule = "|" + "---|" * len(frame.columns)
    body = ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def aligned_columns(header: Sequence[str], rows: Sequence[Sequence[object]]) -> list[str]:
    """Plain-text lines of a table: left-aligned columns two spaces apart, a dashed rule under the
    header, no trailing spaces."""
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows, strict=True)]
    pattern = "  ".join(f"{{:<{w}}}" for w in widths)
    lines = [pattern.format(*header), pattern.format(*("-" * w for w in widths)),
             *(pattern.format(*row) for row in rows)]
    return [line.rstrip() for line in lines]


def _wrapped_rows(rows: Sequence[Sequence[object]], cell_width: int) -> list[list[list[str]]]:
    """Each row as its lines: cells longer than `cell_width` continue on lines of their own below."""
    out: list[list[list[str]]] = []
    for row in rows:
        parts = [textwrap.wrap(str(v), cell_width) or [""] if len(str(v)) > cell_width else [str(v)]
                 for v in row]
        depth = max(len(p) for p in parts)
        out.append([[p[k] if k < len(p) else "" for p in parts] for k in range(depth)])
    return out


def terminal_table(header: Sequence[str], rows: Sequence[Sequence[object]],
                   width: int | None = TERMINAL_WIDTH, keys: int = 1) -> list[str]:
    """`aligned_columns` fitted to `width` characters: long cells wrapped, then the columns split
    into blocks (a blank line between them), each block repeating the first `keys` columns so its
    rows stay identifiable. `width` None: one block, nothing wrapped (--wide). A table that fits
    `width` as it is stays as it is: a cell is wrapped only to make room."""
    whole = aligned_columns(header, rows)
    if width is None or max(len(line) for line in whole) <= width:
        return whole
    wrapped = _wrapped_rows(rows, CELL_WIDTH)
    header = [str(h) for h in header]
    widths = [max(len(str(x)) for x in col)
              for col in zip(header, *(line for row in wrapped for line in row), strict=True)]
    keys = max(0, min(keys, len(header) - 1))
    key_width = sum(widths[:keys]) + 2 * keys
    blocks: list[list[int]] = []
    current: list[int] = []
    used = key_width
    for i in range(keys, len(header)):
        if current and used + widths[i] > width:
            blocks.append(current)
            current, used = [], key_width
        current.append(i)
        used += widths[i] + 2
    blocks.append(current)
    lines: list[str] = []
    for block in blocks:
        chosen = [*range(keys), *block]
        if lines:
            lines.append("")
        # a row's continuation lines hold the wrapped cells of one block: in the others they would
        # only be blank lines inside the table
        shown = [[line[i] for i in chosen] for row in wrapped for k, line in enumerate(row)
                 if k == 0 or any(line[i] for i in chosen)]
        lines += aligned_columns([header[i] for i in chosen], shown)
    return lines


def wrapped_text(text: str, width: int | None = TERMINAL_WIDTH, indent: str = "") -> list[str]:
    """A sentence for the terminal: lines of at most `width` characters, continuation lines
    indented by `indent` (None: one line; a line that fits stays as it is)."""
    if width is None or len(text) <= width:
        return [text]
    return textwrap.wrap(text, width, subsequent_indent=indent)
