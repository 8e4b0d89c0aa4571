"""One of the authors' CARLA logs (a trust_level_record CSV) read into a checked tick table.

A log has one row per CARLA tick: the tick index (the unnamed first column the authors' pandas
wrote; absent, the rows are ticks 0, 1, ...), `trust_level` (the displayed trust, 1-7),
`location` "(x, y, road_id, lane_id)" of the lane-centre waypoint, `if_autopilot` (True/False) and
`trust_belief`, the 7-tuple belief the AV logged. Every cell is checked before any of it is used
(docs/real_study.md, "Mapping decisions"): the ticks are integers that increase from row to row,
x and y are finite, road and lane ids integers, the trust a level 1..7, the belief a probability
vector (trustroute.core.validation `first_non_belief`). A bad cell is an InputError naming the
file, the line an editor shows the row on (`csv_place`) and the column.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from trustroute.core.errors import InputError
from trustroute.core.validation import csv_place, first_non_belief

LOG_COLUMNS = ("trust_level", "location", "if_autopilot", "trust_belief")
TRUST_LEVELS = (1, 7)  # the displayed scale, lowest and highest
BELIEF_WIDTH = 7  # one probability per trust level
LOCATION_FORM = '"(x, y, road_id, lane_id)"'
UNCHANGED = "pass the authors' CSV unchanged"


class _BadCell(Exception):
    """A bad cell found by a check of `read_log`, by its data row; `read_log` places it in the file."""

    def __init__(self, row: int, column: str, problem: str, fix: str = UNCHANGED) -> None:
        super().__init__(row, column, problem, fix)
        self.row, self.column, self.problem, self.fix = row, column, problem, fix


def _cell(raw: pd.DataFrame, column: str, row: int) -> str:
    """The cell as the file has it, quoted (a number read as a float shows as written)."""
    return repr(str(raw[column].iloc[row]))


def _integers(values: np.ndarray) -> np.ndarray:
    """True where a float value is a whole number (NaN and inf are not)."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(values) & (values == np.round(values))


def _numbers(cells: pd.Series) -> np.ndarray:
    """Each cell as a float (NaN where it is not a number)."""
    return pd.to_numeric(cells.astype(str).str.strip(), errors="coerce").to_numpy(dtype=float)


def _tuples(raw: pd.DataFrame, column: str, width: int, form: str) -> np.ndarray:
    """The "(a, b, ...)" cells of `column` as floats [n, width]; InputError at the first cell that
    is not `width` numbers."""
    text = raw[column].astype(str).str.strip().str.strip("()")
    counts = (text.str.count(",") + 1).to_numpy()
    if (counts != width).any():
        row = int(np.flatnonzero(counts != width)[0])
        raise _BadCell(row, column, f"{_cell(raw, column, row)} has {counts[row]} entries, not "
                        f"{width}", f"{column} is {form}")
    parts = text.str.split(",", expand=True)
    values = np.column_stack([_numbers(parts[i]) for i in range(width)])
    missing = np.isnan(values).any(axis=1)
    if missing.any():
        row = int(np.flatnonzero(missing)[0])
        raise _BadCell(row, column, f"{_cell(raw, column, row)} is not {width} numbers",
                        f"{column} is {form}")
    return values


def _ticks(raw: pd.DataFrame) -> np.ndarray:
    """The tick index of each row: the unnamed first column, else 0, 1, ...; integers increasing
    from row to row (a repeated or earlier tick is no log of one drive)."""
    column = raw.columns[0]
    if not column.startswith("Unnamed"):
        return np.arange(len(raw), dtype=np.int64)
    ticks = _numbers(raw[column])
    whole = _integers(ticks) & (ticks >= 0)
    if not whole.all():
        row = int(np.flatnonzero(~whole)[0])
        raise _BadCell(row, "tick (the first column)",
                        f"{_cell(raw, column, row)} is not a tick index (a whole number >= 0)")
    later = np.diff(ticks) > 0
    if not later.all():
        row = int(np.flatnonzero(~later)[0]) + 1
        raise _BadCell(row, "tick (the first column)", f"tick {int(ticks[row])} does not follow "
                        f"tick {int(ticks[row - 1])} of the row before",
                        "pass the ticks in the order logged, once each")
    return ticks.astype(np.int64)


def _location(raw: pd.DataFrame) -> np.ndarray:
    location = _tuples(raw, "location", 4, LOCATION_FORM)
    bad = ~(np.isfinite(location[:, :2]).all(axis=1) & _integers(location[:, 2:]).all(axis=1))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise _BadCell(row, "location", f"{_cell(raw, 'location', row)} is not finite x, y and "
                        "whole road and lane ids", f"location is {LOCATION_FORM}")
    return location


def _belief(raw: pd.DataFrame) -> np.ndarray:
    belief = _tuples(raw, "trust_belief", BELIEF_WIDTH, f"a {BELIEF_WIDTH}-tuple of probabilities")
    wrong = first_non_belief(belief)
    if wrong is not None:
        row, problem = wrong
        raise _BadCell(row, "trust_belief", f"not a probability vector: {problem}")
    return belief


def _trust(raw: pd.DataFrame) -> np.ndarray:
    trust = _numbers(raw["trust_level"])
    low, high = TRUST_LEVELS
    bad = ~(_integers(trust) & (trust >= low) & (trust <= high))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise _BadCell(row, "trust_level", f"{_cell(raw, 'trust_level', row)} is not a level "
                        f"{low}..{high}")
    return trust.astype(np.int64)


def read_log(path: Path, relative: str) -> pd.DataFrame:
    """The tick table: tick, trust, x, y, carla_road, carla_lane, autopilot, belief [n, 7]."""
    try:
        raw = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(relative, "", f"cannot read the CSV ({exc})", UNCHANGED) from None
    missing = [c for c in LOG_COLUMNS if c not in raw.columns]
    if missing:
        raise InputError(relative, "header", f"missing column(s) {', '.join(missing)}",
                         f"a trust_level_record file has columns {', '.join(LOG_COLUMNS)}")
    if raw.empty:
        raise InputError(relative, "rows", "no ticks", "pass a non-empty log")
    try:
        return _tick_table(raw)
    except _BadCell as bad:
        raise InputError(relative, csv_place(path, bad.row, bad.column), bad.problem, bad.fix) from None


def _tick_table(raw: pd.DataFrame) -> pd.DataFrame:
    """`raw`'s cells checked and converted (read_log); _BadCell at the first bad one."""
    tick = _ticks(raw)
    location = _location(raw)
    belief = _belief(raw)
    trust = _trust(raw)
    autopilot = raw["if_autopilot"].astype(str).str.strip().map({"True": True, "False": False})
    if autopilot.isna().any():
        row = int(np.flatnonzero(autopilot.isna().to_numpy())[0])
        raise _BadCell(row, "if_autopilot", f"{_cell(raw, 'if_autopilot', row)} is not True/False")
    return pd.DataFrame(
        {
            "tick": tick,
            "trust": trust,
            "x": location[:, 0],
            "y": location[:, 1],
            "carla_road": location[:, 2].astype(np.int64),
            "carla_lane": location[:, 3].astype(np.int64),
            "autopilot": autopilot.to_numpy(dtype=bool),
        }
    ).assign(belief=list(belief))
