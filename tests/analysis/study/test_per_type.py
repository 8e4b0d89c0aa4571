"""Episodes tables without a driver type: earlier studies still read, and have no per-type tables; the
per-type tables' "all" rows are the main tables' rows."""

from __future__ import annotations

from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.analysis.study.made_episodes import made_episodes
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


def _rows(frame, columns) -> list[dict]:
    """The rows as comparable records (NaN and None both missing)."""
    return frame[list(columns)].astype(object).where(frame[list(columns)].notna(), None).to_dict("records")


@pytest.mark.parametrize("types", [("builder", "wary"), ("builder",)])
def test_the_all_rows_are_the_main_tables_rows_every_interval_included(types):
    """Per type "all" is every participant: its cells and paired rows are the main tables' own, bootstrap
    intervals included, whichever table is computed first; with one type, that type's rows are too."""
    from trustroute.analysis.study.analysis import ANALYSIS_SEED
    from trustroute.analysis.study.cells import cell_table
    from trustroute.analysis.study.paired import all_pairs_table, condition_pairs, per_participant_table
    from trustroute.analysis.study.per_type import PER_TYPE_CELL_COLUMNS, per_type_tables

    episodes = made_episodes(types=types)
    specs, conditions = ["phi1", "phi2"], ["aware", "robust", "free"]
    per_type, per_type_paired = per_type_tables(episodes, specs, conditions, "true", ANALYSIS_SEED, 400)
    wide = per_participant_table(episodes, "satisfied_true", tuple(conditions))
    paired = all_pairs_table(wide, condition_pairs(conditions), specs, ANALYSIS_SEED, 400)
    cells = cell_table(episodes, specs, conditions, "true", {}, ANALYSIS_SEED, 400)
    assert paired["trust_diff_low"].notna().all() and paired["rd_low"].notna().any()
    for name in ("all", *(types if len(types) == 1 else ())):
        mine = per_type_paired[per_type_paired["driver_type"] == name]
        assert _rows(mine, paired.columns) == _rows(paired, paired.columns)
        mine_cells = per_type[per_type["driver_type"] == name]
        assert _rows(mine_cells, PER_TYPE_CELL_COLUMNS) == _rows(cells, PER_TYPE_CELL_COLUMNS)
    again = per_type_tables(episodes, specs, conditions, "true", ANALYSIS_SEED, 400)[1]
    assert _rows(again, again.columns) == _rows(per_type_paired, per_type_paired.columns)


def test_a_cell_whose_trust_has_no_spread_says_its_interval_is_the_point():
    """The cells' "trust 95% CI" is the percentile bootstrap's; a cell whose episodes all report one
    mean has nothing to resample, and the table says so rather than show [6.00, 6.00] as an interval."""
    from trustroute.analysis.study.analysis import ANALYSIS_SEED
    from trustroute.analysis.study.cells import cell_table
    from trustroute.analysis.study.display import trust_columns

    episodes = made_episodes()
    flat = (episodes["spec"] == "phi1") & (episodes["condition"] == "aware")
    episodes.loc[flat, "mean_reported_trust"] = 6.0
    specs, conditions = ["phi1", "phi2"], ["aware", "robust", "free"]
    cells = cell_table(episodes, specs, conditions, "true", {}, ANALYSIS_SEED, 400)
    keys = zip(cells["spec"], cells["condition"], strict=True)
    methods = dict(zip(keys, cells["trust_ci_method"], strict=True))
    assert methods.pop(("phi1", "aware")) == "degenerate" and set(methods.values()) == {"percentile"}
    shown = list(trust_columns(cells)["trust 95% CI"])
    assert shown[0] == "[6.00, 6.00] (degenerate)" and not any("(" in text for text in shown[1:]), shown
