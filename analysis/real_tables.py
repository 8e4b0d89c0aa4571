"""The real-study tables beside the dataset's: file names, Arrow schemas and their reader.

Written by the CARLA-log importer (analysis/carla_import.py) and read by the real-study analysis
(analysis/real_study.py); its own module so that the two do not import each other
(docs/real_study.md, "The study directory").
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pyarrow as pa

from trustroute.analysis import dataset

REAL_EPISODES_FILE = "real_episodes.parquet"
REAL_ROADS_FILE = "real_roads.parquet"
TICKS_FILE = "ticks.parquet"
REAL_EPISODES_SCHEMA = pa.schema(
    [
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("trial", pa.int64(), nullable=False),
        pa.field("source_file", pa.string(), nullable=False),
        pa.field("ticks", pa.int64(), nullable=False),
        pa.field("manual_ticks", pa.int64(), nullable=False),
        pa.field("trust_changes", pa.int64(), nullable=False),
        pa.field("final_reported_trust", pa.int64(), nullable=False),
        pa.field("log_end", pa.string(), nullable=False),
    ]
)
REAL_ROADS_SCHEMA = pa.schema(
    [
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("index", pa.int64(), nullable=False),
        pa.field("authors_state", pa.string(), nullable=False),
        pa.field("logged_belief", pa.list_(pa.float64()), nullable=False),
        pa.field("arrived", pa.bool_(), nullable=False),
        pa.field("tick_first", pa.int64(), nullable=False),
        pa.field("tick_last", pa.int64(), nullable=False),
        pa.field("ticks", pa.int64(), nullable=False),
        pa.field("manual_ticks", pa.int64(), nullable=False),
        pa.field("trust_changes", pa.int64(), nullable=False),
    ]
)
TICKS_SCHEMA = pa.schema(
    [
        pa.field("episode_id", pa.string(), nullable=False),
        pa.field("tick_first", pa.int64(), nullable=False),
        pa.field("tick_last", pa.int64(), nullable=False),
        pa.field("rows", pa.int64(), nullable=False),
        pa.field("road_index", pa.int64(), nullable=False),
        pa.field("carla_road", pa.int64(), nullable=False),
        pa.field("trust", pa.int64(), nullable=False),
        pa.field("autopilot", pa.bool_(), nullable=False),
    ]
)
REAL_TABLES = {
    "real_episodes": (REAL_EPISODES_FILE, REAL_EPISODES_SCHEMA),
    "real_roads": (REAL_ROADS_FILE, REAL_ROADS_SCHEMA),
    "ticks": (TICKS_FILE, TICKS_SCHEMA),
}


def read_real_table(study_dir: Path, name: str) -> pd.DataFrame:
    """real_episodes, real_roads or ticks of an imported study, checked against its schema."""
    file_name, schema = REAL_TABLES[name]
    return dataset.frame_from_table(dataset.read_table(Path(study_dir) / file_name, schema))
