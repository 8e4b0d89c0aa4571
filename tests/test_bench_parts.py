"""The parts benchmark writes episode tables of the dataset's own schemas: its synthetic episode is
built to them, so it cannot drift from what a study writes (a column made non-null later, say)."""

from __future__ import annotations

import numpy as np

from benchmarks import bench_parts
from trustroute.core.dataset import INCIDENTS_SCHEMA, KINEMATICS_SCHEMA, ROADS_SCHEMA


def test_the_benchmarks_episode_tables_have_the_dataset_schemas():
    tables = bench_parts._tables("p00000-phi1-free", np.random.default_rng(1))
    assert tables["roads"].schema.equals(ROADS_SCHEMA)
    assert tables["kinematics"].schema.equals(KINEMATICS_SCHEMA)
    assert tables["incidents"].schema.equals(INCIDENTS_SCHEMA)
    rows = (tables["roads"].num_rows, tables["kinematics"].num_rows, tables["incidents"].num_rows)
    assert rows == (11, 400, 4)
