"""The logs of one SUMO or model-engine episode (`EpisodeRecord`) and the SUMO episode's per-step
log while it runs (`StepLog`)."""

from __future__ import annotations

from array import array
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from trustroute.core.dataset import (
    INCIDENTS_SCHEMA,
    KINEMATICS_SCHEMA,
    ROADS_SCHEMA,
    frame_from_table,
    table_from_columns,
    table_from_frame,
)

STEP_FIELDS = ("time", "x", "y", "speed", "lane", "mode")   # what the loop logs per step, in order


_SCHEMAS = {"roads": ROADS_SCHEMA, "kinematics": KINEMATICS_SCHEMA, "incidents": INCIDENTS_SCHEMA}


class EpisodeRecord:
    """The logs of one episode (the caller writes them to Parquet). `incidents` (SUMO engine only):
    one row per road with an incident or a takeover, with the SUMO ids of its objects.

    Each table is given as an Arrow table of its dataset schema (trustroute.core.dataset), or
    as a DataFrame; `roads`, `kinematics` and `incidents` are DataFrames built on first use, and
    `tables()` hands the logs back as Arrow tables without going through pandas when they were
    given as Arrow (the SUMO engine's case: the cheap path for writers, a study writes Arrow).
    """

    def __init__(self, summary: dict, roads, kinematics, incidents=None) -> None:
        self.summary = summary
        self._sources = {"roads": roads, "kinematics": kinematics,
                         "incidents": incidents if incidents is not None else INCIDENTS_SCHEMA.empty_table()}
        self._frames: dict[str, pd.DataFrame] = {}

    def _frame(self, name: str) -> pd.DataFrame:
        frame = self._frames.get(name)
        if frame is None:
            source = self._sources[name]
            frame = source if isinstance(source, pd.DataFrame) else frame_from_table(source)
            self._frames[name] = frame
        return frame

    @property
    def roads(self) -> pd.DataFrame:
        return self._frame("roads")

    def last_road(self) -> dict[str, Any]:
        """The roads table's last row as {column: Python value} (None where null), read from the
        Arrow table when the roads are not in pandas yet: a gym episode's end reads its last road
        only, and a table's conversion to pandas costs milliseconds whatever its length."""
        source = self._sources["roads"]
        if "roads" not in self._frames and isinstance(source, pa.Table):
            return source.slice(source.num_rows - 1).to_pylist()[0]
        row = self.roads.iloc[-1]
        return {name: None if pd.api.types.is_scalar(value) and pd.isna(value) else value
                for name, value in row.items()}

    @property
    def kinematics(self) -> pd.DataFrame:
        return self._frame("kinematics")

    @property
    def incidents(self) -> pd.DataFrame:
        return self._frame("incidents")

    def tables(self) -> dict[str, pa.Table]:
        """{"roads", "kinematics", "incidents"} as Arrow tables."""
        out = {}
        for name, source in self._sources.items():
            if isinstance(source, pa.Table):
                out[name] = source
            else:
                out[name] = table_from_frame(source, _SCHEMAS[name])
        return out


class StepLog:
    """The per-step log (STEP_FIELDS) as columns while the loop runs: time, x, y and speed in one
    float64 array, lane and mode in lists. The kinematics table is then a few buffer copies, not a
    conversion of one Python object per cell."""

    def __init__(self) -> None:
        self.floats = array("d")          # time, x, y, speed of every step, in that order
        self.lanes: list[str] = []
        self.modes: list[str] = []

    def table(self, episode_id: str) -> pa.Table:
        floats = np.frombuffer(self.floats, dtype=np.float64).reshape(-1, 4).T
        rows = len(self.lanes)
        columns = {"episode_id": pa.repeat(pa.scalar(episode_id, pa.string()), rows),
                   **{name: pa.array(floats[i]) for i, name in enumerate(STEP_FIELDS[:4])},
                   "lane": self.lanes, "mode": self.modes}
        return table_from_columns(columns, KINEMATICS_SCHEMA, nan_as_null=False)
