"""The real-study tables beside the dataset's: file names, Arrow schemas and their reader.

Written by the CARLA-log importer (analysis/carla_study/log_import.py) and read by the real-study
analysis (analysis/carla_study/analysis.py); its own module so that the two do not import each other
(docs/real_study.md, "The study directory").
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pyarrow as pa

from trustroute.core import dataset

REAL_EPISODES_FILE = "real_episodes.parquet"
REAL_ROADS_FILE = "real_roads.parquet"
TICKS_FILE = "ticks.parquet"
REAL_EPISODES_SCHEMA = dataset.required_schema(
    episode_id=pa.string(),
    trial=pa.int64(),
    source_file=pa.string(),
    ticks=pa.int64(),
    manual_ticks=pa.int64(),
    trust_changes=pa.int64(),
    final_reported_trust=pa.int64(),
    log_end=pa.string(),
)
REAL_ROADS_SCHEMA = dataset.required_schema(
    episode_id=pa.string(),
    index=pa.int64(),
    authors_state=pa.string(),
    logged_belief=dataset.BELIEF,
    arrived=pa.bool_(),
    tick_first=pa.int64(),
    tick_last=pa.int64(),
    ticks=pa.int64(),
    manual_ticks=pa.int64(),
    trust_changes=pa.int64(),
)
TICKS_SCHEMA = dataset.required_schema(
    episode_id=pa.string(),
    tick_first=pa.int64(),
    tick_last=pa.int64(),
    rows=pa.int64(),
    road_index=pa.int64(),
    carla_road=pa.int64(),
    trust=pa.int64(),
    autopilot=pa.bool_(),
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
