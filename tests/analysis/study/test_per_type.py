"""Episodes tables without a driver type: earlier studies still read, and have no per-type tables."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from trustroute.analysis.study.analysis import study_analysis
from trustroute.core import dataset
from trustroute.core.errors import InputError

REAL_STUDY = Path(__file__).resolve().parents[3] / "analysis" / "data" / "real_study" / "study"


def test_a_study_without_drivers_has_no_per_type_tables(model_study):
    analysis = study_analysis(model_study, "filter", resamples=50)
    assert analysis.episodes["driver_type"].isna().all()
    assert analysis.per_type.empty and analysis.per_type_paired.empty


def test_an_episodes_file_written_before_driver_type_reads_with_nulls(model_study, tmp_path):
    table = pq.read_table(model_study / dataset.EPISODES_FILE)
    # a file written before driver_type also lacks every column added after it
    later = dataset.ADDED_COLUMNS["episodes"]
    older = table.drop_columns(list(later[later.index("driver_type"):]))
    pq.write_table(older, tmp_path / dataset.EPISODES_FILE)
    episodes = dataset.read_episodes(tmp_path)
    assert list(episodes.columns) == dataset.EPISODES_SCHEMA.names
    assert episodes["driver_type"].isna().all() and len(episodes) == table.num_rows
    # the committed real study predates the column
    assert "driver_type" not in pq.read_schema(REAL_STUDY / dataset.EPISODES_FILE).names
    assert dataset.read_episodes(REAL_STUDY)["driver_type"].isna().all()
    # a column missing elsewhere is still an error
    broken = table.drop_columns(["seed"])
    pq.write_table(broken, tmp_path / dataset.EPISODES_FILE)
    with pytest.raises(InputError, match="schema"):
        dataset.read_episodes(tmp_path)
    # so is a driver_type of the wrong type
    wrong = older.append_column("driver_type", pa.array([1] * table.num_rows, pa.int64()))
    pq.write_table(wrong, tmp_path / dataset.EPISODES_FILE)
    with pytest.raises(InputError):
        dataset.read_episodes(tmp_path)
